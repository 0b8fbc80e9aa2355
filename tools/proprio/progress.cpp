#include "progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace proprio::cli {

namespace {
constexpr auto kQuietFor = std::chrono::milliseconds(1000);
constexpr auto kRedrawEvery = std::chrono::milliseconds(100);
}  // namespace

ProgressBar::ProgressBar(std::string label, double total, std::string unit)
    : label_(std::move(label)), unit_(std::move(unit)), total_(std::max(total, 1e-12)),
      start_(std::chrono::steady_clock::now()), last_draw_(start_), tty_(::isatty(STDERR_FILENO) != 0) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(double done) {
  const auto now = std::chrono::steady_clock::now();
  if (!tty_ || now - start_ < kQuietFor || now - last_draw_ < kRedrawEvery) return;
  last_draw_ = now;
  draw(done, false);
}

void ProgressBar::finish() {
  if (finished_) return;
  finished_ = true;
  if (shown_ || std::chrono::steady_clock::now() - start_ >= kQuietFor) draw(total_, true);
}

void ProgressBar::draw(double done, bool final_line) {
  shown_ = true;
  const double fraction = std::clamp(done / total_, 0.0, 1.0);
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(fraction * kWidth);
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.append(static_cast<std::size_t>(kWidth - filled), '-');
  const double eta = fraction > 0 ? elapsed * (1.0 - fraction) / fraction : 0.0;
  if (tty_) {
    std::fprintf(stderr, "\r%s [%s] %3.0f%% %.1f/%.1f %s, %.1fs elapsed, ETA %.1fs%s", label_.c_str(), bar.c_str(),
                 100.0 * fraction, done, total_, unit_.c_str(), elapsed, eta, final_line ? "\n" : "   ");
  } else if (final_line) {
    std::fprintf(stderr, "%s: %.1f %s in %.1fs\n", label_.c_str(), done, unit_.c_str(), elapsed);
  }
  std::fflush(stderr);
}

}  // namespace proprio::cli
