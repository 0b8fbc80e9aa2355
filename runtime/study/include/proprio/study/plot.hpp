#pragma once
// Psychometric plots as standalone SVG: data points with area proportional to
// their trial count, the fitted curve, and the threshold with its confidence
// interval; several conditions can share one plot (one colour each).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/study/psychometric.hpp"

namespace proprio::study {

struct PsychometricCurve {
  std::string label;                       // legend entry, e.g. the condition
  std::vector<StimulusLevel> data;
  std::optional<PsychometricFit> fit;      // drawn as a smooth curve
  std::optional<double> threshold;         // a vertical marker at the criterion
  std::optional<ConfidenceInterval> threshold_ci;  // a horizontal bar at the criterion
};

struct PsychometricPlot {
  std::string title;
  std::string x_label = "stimulus level";
  std::string y_label = "proportion correct";
  double criterion = 0.75;                 // the proportion the threshold belongs to
  std::vector<PsychometricCurve> curves;
};

// The SVG document as text.
std::string psychometric_svg(const PsychometricPlot& plot);
Status write_psychometric_svg(const std::filesystem::path& path, const PsychometricPlot& plot);

}  // namespace proprio::study
