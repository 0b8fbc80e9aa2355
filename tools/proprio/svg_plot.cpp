#include "svg_plot.hpp"

#include "proprio/core/file_io.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace proprio::cli {

namespace {

constexpr double kWidth = 960, kPanelHeight = 220, kLeft = 70, kRight = 180, kTop = 40, kGap = 50;
constexpr const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"};

// Tick spacing of 1, 2 or 5 times a power of ten giving about five ticks.
double nice_step(double span) {
  const double raw = span / 5.0;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0}) {
    if (m * p >= raw) return m * p;
  }
  return 10.0 * p;
}

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", std::abs(v) < 1e-12 ? 0.0 : v);
  return buf;
}

std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '<') out += "&lt;";
    else if (c == '>') out += "&gt;";
    else if (c == '&') out += "&amp;";
    else out += c;
  }
  return out;
}

}  // namespace

Status write_svg_plot(const std::filesystem::path& path, const std::string& title, const std::string& x_label,
                      const std::vector<PlotPanel>& panels) {
  const double height = kTop + static_cast<double>(panels.size()) * (kPanelHeight + kGap) + 20;
  std::ostringstream svg;
  svg << "<svg xmlns='http://www.w3.org/2000/svg' width='" << kWidth << "' height='" << height
      << "' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n"
      << "<text x='" << kWidth / 2 << "' y='22' text-anchor='middle' font-size='15'>" << escape(title) << "</text>\n";
  const double plot_w = kWidth - kLeft - kRight;
  for (std::size_t pi = 0; pi < panels.size(); ++pi) {
    const PlotPanel& panel = panels[pi];
    const double top = kTop + static_cast<double>(pi) * (kPanelHeight + kGap);
    double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    for (const auto& s : panel.series) {
      for (double v : s.x) x0 = std::min(x0, v), x1 = std::max(x1, v);
      for (double v : s.y) y0 = std::min(y0, v), y1 = std::max(y1, v);
    }
    if (!(x1 > x0)) x0 = 0, x1 = 1;
    if (!(y1 > y0)) y0 -= 1, y1 += 1;
    const double ystep = nice_step(y1 - y0), xstep = nice_step(x1 - x0);
    y0 = std::floor(y0 / ystep) * ystep;
    y1 = std::ceil(y1 / ystep) * ystep;
    auto X = [&](double v) { return kLeft + (v - x0) / (x1 - x0) * plot_w; };
    auto Y = [&](double v) { return top + kPanelHeight - (v - y0) / (y1 - y0) * kPanelHeight; };

    svg << "<text x='" << kLeft << "' y='" << top - 8 << "' font-weight='bold'>" << escape(panel.title) << "</text>\n";
    for (double v = y0; v <= y1 + 1e-9 * ystep; v += ystep) {
      svg << "<line x1='" << kLeft << "' x2='" << kLeft + plot_w << "' y1='" << Y(v) << "' y2='" << Y(v)
          << "' stroke='#ddd'/><text x='" << kLeft - 6 << "' y='" << Y(v) + 4 << "' text-anchor='end'>" << fmt(v)
          << "</text>\n";
    }
    for (double v = std::ceil(x0 / xstep) * xstep; v <= x1 + 1e-9 * xstep; v += xstep) {
      svg << "<line x1='" << X(v) << "' x2='" << X(v) << "' y1='" << top << "' y2='" << top + kPanelHeight
          << "' stroke='#eee'/><text x='" << X(v) << "' y='" << top + kPanelHeight + 15 << "' text-anchor='middle'>"
          << fmt(v) << "</text>\n";
    }
    svg << "<rect x='" << kLeft << "' y='" << top << "' width='" << plot_w << "' height='" << kPanelHeight
        << "' fill='none' stroke='#444'/>\n";
    svg << "<text transform='translate(" << 16 << "," << top + kPanelHeight / 2 << ") rotate(-90)' text-anchor='middle'>"
        << escape(panel.y_label) << "</text>\n";
    if (pi + 1 == panels.size()) {
      svg << "<text x='" << kLeft + plot_w / 2 << "' y='" << top + kPanelHeight + 32 << "' text-anchor='middle'>"
          << escape(x_label) << "</text>\n";
    }
    for (std::size_t si = 0; si < panel.series.size(); ++si) {
      const auto& s = panel.series[si];
      const char* colour = kColours[si % std::size(kColours)];
      svg << "<polyline fill='none' stroke='" << colour << "' stroke-width='1.3' points='";
      // Thin to about 2000 points: more cannot be seen and bloats the file.
      const std::size_t n = std::min(s.x.size(), s.y.size());
      const std::size_t stride = std::max<std::size_t>(1, n / 2000);
      for (std::size_t i = 0; i < n; i += stride) svg << X(s.x[i]) << ',' << Y(s.y[i]) << ' ';
      svg << "'/>\n<text x='" << kLeft + plot_w + 10 << "' y='" << top + 14 + 16 * static_cast<double>(si)
          << "' fill='" << colour << "'>" << escape(s.label) << "</text>\n";
    }
  }
  svg << "</svg>\n";
  return write_file_atomic(path, svg.str(), "plot");
}

}  // namespace proprio::cli
