#pragma once
// Line plots as standalone SVG files: one panel per group of series sharing a
// y unit, time on x. Enough for a newcomer to see what a recording contains.
#include <filesystem>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio::cli {

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;
};

struct PlotPanel {
  std::string title;
  std::string y_label;
  std::vector<PlotSeries> series;
};

Status write_svg_plot(const std::filesystem::path& path, const std::string& title, const std::string& x_label,
                      const std::vector<PlotPanel>& panels);

}  // namespace proprio::cli
