#include "proprio/study/plot.hpp"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <limits>

#include "proprio/core/file_io.hpp"

namespace proprio::study {
namespace {

constexpr double kWidth = 720, kHeight = 480;
constexpr double kLeft = 70, kRight = 170, kTop = 40, kBottom = 60;  // margins; the legend sits on the right
constexpr const char* kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
                                    "#7f7f7f"};

std::string escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// Round tick spacing (1, 2 or 5 times a power of ten) for about `target` ticks.
double tick_step(double span, int target) {
  const double raw = span / target;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * power >= raw) return m * power;
  }
  return 10.0 * power;
}

}  // namespace

std::string psychometric_svg(const PsychometricPlot& plot) {
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = -x_lo;
  int max_n = 1;
  for (const PsychometricCurve& c : plot.curves) {
    for (const StimulusLevel& s : c.data) {
      if (s.trials <= 0 || !std::isfinite(s.level)) continue;
      x_lo = std::min(x_lo, s.level);
      x_hi = std::max(x_hi, s.level);
      max_n = std::max(max_n, s.trials);
    }
    if (c.threshold && std::isfinite(*c.threshold)) {
      x_lo = std::min(x_lo, *c.threshold);
      x_hi = std::max(x_hi, *c.threshold);
    }
  }
  if (!std::isfinite(x_lo)) {
    x_lo = 0.0;
    x_hi = 1.0;
  }
  if (x_hi - x_lo < 1e-12) {
    x_lo -= 0.5;
    x_hi += 0.5;
  }
  const double pad = 0.08 * (x_hi - x_lo);
  x_lo -= pad;
  x_hi += pad;
  const double plot_w = kWidth - kLeft - kRight, plot_h = kHeight - kTop - kBottom;
  auto px = [&](double x) { return kLeft + (x - x_lo) / (x_hi - x_lo) * plot_w; };
  auto py = [&](double y) { return kTop + (1.0 - y) * plot_h; };

  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
      "font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
      kWidth, kHeight);
  svg += fmt::format("<text x=\"{}\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">{}</text>\n",
                     kLeft + plot_w / 2, escape(plot.title));
  // Axes, ticks and grid.
  svg += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>\n", kLeft,
                     kTop, plot_w, plot_h);
  const double xs = tick_step(x_hi - x_lo, 6);
  for (double t = std::ceil(x_lo / xs) * xs; t <= x_hi + 1e-9 * xs; t += xs) {
    const double v = std::abs(t) < 1e-9 * xs ? 0.0 : t;
    svg += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1}\" x2=\"{0:.1f}\" y2=\"{2}\" stroke=\"#ddd\"/>"
                       "<text x=\"{0:.1f}\" y=\"{3}\" text-anchor=\"middle\">{4:g}</text>\n",
                       px(v), kTop, kTop + plot_h, kTop + plot_h + 16, v);
  }
  for (int i = 0; i <= 10; i += 2) {
    const double y = i / 10.0;
    svg += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#ddd\"/>"
                       "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5:.1f}</text>\n",
                       kLeft, py(y), kLeft + plot_w, kLeft - 6, py(y) + 4, y);
  }
  svg += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#888\" "
                     "stroke-dasharray=\"4 3\"/>\n",
                     kLeft, py(plot.criterion), kLeft + plot_w);
  svg += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", kLeft + plot_w / 2, kHeight - 18,
                     escape(plot.x_label));
  svg += fmt::format("<text x=\"18\" y=\"{0}\" text-anchor=\"middle\" transform=\"rotate(-90 18 {0})\">{1}</text>\n",
                     kTop + plot_h / 2, escape(plot.y_label));

  const double max_radius = 9.0;
  for (std::size_t ci = 0; ci < plot.curves.size(); ++ci) {
    const PsychometricCurve& c = plot.curves[ci];
    const char* colour = kPalette[ci % std::size(kPalette)];
    if (c.fit) {
      std::string path;
      constexpr int kSteps = 200;
      for (int i = 0; i <= kSteps; ++i) {
        const double x = x_lo + (x_hi - x_lo) * i / kSteps;
        const double y = psi(c.fit->model, c.fit->params, x);
        if (!std::isfinite(y)) continue;
        path += fmt::format("{}{:.1f},{:.1f} ", path.empty() ? "M" : "L", px(x), py(y));
      }
      svg += fmt::format("<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\"/>\n", path, colour);
    }
    for (const StimulusLevel& s : c.data) {
      if (s.trials <= 0 || !std::isfinite(s.level)) continue;
      // Area proportional to n: radius grows with sqrt(n).
      const double r = std::max(2.0, max_radius * std::sqrt(static_cast<double>(s.trials) / max_n));
      svg += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"{:.1f}\" fill=\"{}\" fill-opacity=\"0.55\" "
                         "stroke=\"{}\"><title>level {:g}: {} of {}</title></circle>\n",
                         px(s.level), py(static_cast<double>(s.correct) / s.trials), r, colour, colour, s.level,
                         s.correct, s.trials);
    }
    if (c.threshold_ci && std::isfinite(c.threshold_ci->lower) && std::isfinite(c.threshold_ci->upper)) {
      const double y = py(plot.criterion);
      const double a = px(std::clamp(c.threshold_ci->lower, x_lo, x_hi));
      const double b = px(std::clamp(c.threshold_ci->upper, x_lo, x_hi));
      svg += fmt::format("<path d=\"M{0:.1f},{2:.1f} L{1:.1f},{2:.1f} M{0:.1f},{3:.1f} L{0:.1f},{4:.1f} M{1:.1f},"
                         "{3:.1f} L{1:.1f},{4:.1f}\" stroke=\"{5}\" stroke-width=\"2\"/>\n",
                         a, b, y, y - 5, y + 5, colour);
    }
    if (c.threshold && std::isfinite(*c.threshold)) {
      const double x = px(*c.threshold);
      svg += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" stroke=\"{3}\" "
                         "stroke-dasharray=\"2 2\"/>\n",
                         x, py(plot.criterion), kTop + plot_h, colour);
    }
    // Legend entry.
    const double ly = kTop + 14 + 34.0 * static_cast<double>(ci);
    const double lx = kLeft + plot_w + 14;
    svg += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"5\" fill=\"{}\"/><text x=\"{}\" y=\"{}\">{}</text>\n", lx,
                       ly - 4, colour, lx + 10, ly, escape(c.label));
    if (c.threshold && std::isfinite(*c.threshold)) {
      std::string note = fmt::format("thr {:.4g}", *c.threshold);
      if (c.threshold_ci) note += fmt::format(" [{:.3g}, {:.3g}]", c.threshold_ci->lower, c.threshold_ci->upper);
      svg += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"10\">{}</text>\n", lx + 10, ly + 13, escape(note));
    }
  }
  svg += "</svg>\n";
  return svg;
}

Status write_psychometric_svg(const std::filesystem::path& path, const PsychometricPlot& plot) {
  return write_file_atomic(path, psychometric_svg(plot), "plot");
}

}  // namespace proprio::study
