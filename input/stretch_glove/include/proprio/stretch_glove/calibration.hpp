#pragma once
// Per-user min-max calibration of the stretch-sensing glove (Glauser 2019,
// Sec. 5.3.3): after putting the glove on, the user freely explores extreme
// poses for under a minute; each cell's readings, median-filtered over 20
// frames so a spike cannot set an extreme, give its min and max, which then
// map its readings to about [-1, 1]:
//
//   x = 2 (c - min) / (max - min) - 1, clamped to [-2, 2]
//
// computed in single precision exactly in that order (the Python training
// code does the same with float32 numpy arrays: 2 * (c - mn) / (mx - mn) - 1,
// then clip). The clamp keeps a reading far outside the calibrated range (a
// slipped glove, a spike) from driving the network anywhere it never saw. A
// NaN reading (an invalid cell) normalises to 0, the middle of its range.
//
// The normalised cells then go into the network's 2 x 5 x 5 input grid
// (InputGrid, stretch_glove_layout.hpp's input_grid_index()).
//
// File format (TOML, written by save(), read by load()):
//   layout = "<layout name>"         # the glove layout it belongs to
//   cell_count = 44
//   median_frames = 20               # median filter length used
//   frames = 3600                    # frames the calibrator saw
//   source = "..."                   # free text: who/what made it
//   created = "..."                  # free text, e.g. a date; may be empty
//   min_pf = [ ... cell_count numbers ... ]
//   max_pf = [ ... ]                 # every max_pf[i] > min_pf[i]
#include <array>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_glove/readout.hpp"

namespace proprio::stretch_glove {

inline constexpr float kNormalizedClamp = 2.0f;

struct MinMaxCalibration {
  std::string layout_name;
  std::vector<float> min_pf;
  std::vector<float> max_pf;
  int median_frames = 20;
  std::size_t frames = 0;
  std::string source;
  std::string created;

  std::size_t cell_count() const noexcept { return min_pf.size(); }
  // out[i] = clamp(2 (cells[i] - min) / (max - min) - 1, -2, 2); NaN -> 0.
  // out may alias cells. Both have cell_count() entries.
  void normalize(std::span<const float> cells_pf, std::span<float> out) const noexcept;
  std::vector<float> normalize(std::span<const float> cells_pf) const;

  // Sizes agree, every value finite, min < max for every cell.
  Status validate() const;
  // Belongs to this layout: same cell count (and name, when both have one).
  Status check_layout(const StretchGloveLayout& layout) const;

  std::string to_toml() const;
  Status save(const std::filesystem::path& path) const;
  static Result<MinMaxCalibration> load(const std::filesystem::path& path);
  static Result<MinMaxCalibration> parse(std::string_view toml_text, const std::string& source_name);
};

struct MinMaxCalibratorOptions {
  int median_frames = 20;  // thesis: a median filter over 20 frames
  // Range a cell of each category spans in a good enough exploration, as a
  // fraction of its rest capacitance; coverage = range / this (at most 1).
  // About 60 % of the median cell's range in the simulated glove's 60 s
  // exploration (1.5, 0.86, 0.46, 0.38; docs/stretch-glove-layout.md), so a
  // full exploration scores near 100 %.
  double typical_range_joint = 0.9;
  double typical_range_abduction = 0.45;
  double typical_range_perpendicular = 0.25;
  double typical_range_dorsum = 0.2;
  // Below this coverage a region is reported as "move it more".
  double good_coverage = 0.7;

  Status validate() const;
  std::string describe() const;
};

// Regions the coverage report groups cells into.
enum class CalibrationRegion : std::uint8_t { thumb = 0, index, middle, ring, little, dorsum };
inline constexpr std::size_t kCalibrationRegionCount = 6;
std::string_view to_string(CalibrationRegion r) noexcept;

struct CalibrationProgress {
  std::size_t frames = 0;          // frames seen
  std::size_t medians = 0;         // median values taken (frames once the filter is full)
  std::vector<double> range_pf;    // per cell: max - min of its medians (0 before any)
  std::vector<double> coverage;    // per cell: range / typical range, in [0, 1]
  std::array<double, kCalibrationRegionCount> region_coverage{};  // mean over the region's cells
  double overall = 0.0;            // mean over all cells
  double good_coverage = 0.7;

  // What to tell the user, e.g. "move the ring and little fingers more
  // (coverage 42 %, 55 %)", or that every region is covered.
  std::string advice() const;
};

class MinMaxCalibrator {
 public:
  static Result<MinMaxCalibrator> create(const StretchGloveLayout& layout, MinMaxCalibratorOptions options = {});

  // Cells not valid in the frame are skipped (their filters wait).
  void add(const CellFrame& frame);
  // All cells valid.
  void add(std::span<const float> cells_pf);

  CalibrationProgress progress() const;
  // Errc::unavailable (naming the cells) when a cell has no range yet:
  // explore more, or that cell is broken.
  Result<MinMaxCalibration> finish(std::string source = {}, std::string created = {}) const;
  void reset();
  const MinMaxCalibratorOptions& options() const noexcept { return options_; }

 private:
  MinMaxCalibrator() = default;
  void add_cell(std::size_t cell, float value);

  MinMaxCalibratorOptions options_;
  std::string layout_name_;
  std::vector<std::string> cell_names_;
  std::vector<double> typical_pf_;
  std::vector<CalibrationRegion> region_;
  std::vector<float> history_;          // cells x median_frames ring buffers
  std::vector<int> history_next_, history_count_;
  std::vector<float> min_pf_, max_pf_;
  std::vector<std::size_t> median_count_;
  std::vector<float> scratch_;
  std::size_t frames_ = 0;
};

// Writes normalised cells into the network input: kStretchInputSize floats,
// NCHW (1 x 2 x 5 x 5), cell i at layout.input_grid_index()[i], empty slots 0.
class InputGrid {
 public:
  explicit InputGrid(const StretchGloveLayout& layout);
  // normalized: cell_count() floats; grid: kStretchInputSize floats.
  void fill(std::span<const float> normalized, std::span<float> grid) const noexcept;
  std::size_t cell_count() const noexcept { return index_.size(); }
  const std::vector<int>& index() const noexcept { return index_; }

 private:
  std::vector<int> index_;
};

}  // namespace proprio::stretch_glove
