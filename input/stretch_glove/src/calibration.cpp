#include "proprio/stretch_glove/calibration.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::stretch_glove {

namespace {

std::string toml_string(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    if (static_cast<unsigned char>(ch) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(ch));
      out += buf;
      continue;
    }
    if (ch == '"' || ch == '\\') out += '\\';
    out += ch;
  }
  return out + "\"";
}

// Nine significant digits read back as the same float.
std::string float_text(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", static_cast<double>(v));
  std::string s = buf;
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

std::optional<Finger> finger_of(HandJoint j) {
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(f));
    for (std::size_t k = 0; k < fj.count; ++k) {
      if (fj.joints[k] == j) return static_cast<Finger>(f);
    }
  }
  return std::nullopt;
}

constexpr std::array<std::string_view, kCalibrationRegionCount> kRegionNames = {"thumb",  "index",  "middle",
                                                                                 "ring",   "little", "dorsum"};

}  // namespace

// --- the calibration ---------------------------------------------------------------

void MinMaxCalibration::normalize(std::span<const float> cells_pf, std::span<float> out) const noexcept {
  const std::size_t n = std::min({cells_pf.size(), out.size(), min_pf.size(), max_pf.size()});
  for (std::size_t i = 0; i < n; ++i) {
    const float c = cells_pf[i];
    if (std::isnan(c)) {
      out[i] = 0.0f;
      continue;
    }
    // Exactly this order in single precision; the Python side mirrors it.
    const float x = 2.0f * (c - min_pf[i]) / (max_pf[i] - min_pf[i]) - 1.0f;
    out[i] = std::clamp(x, -kNormalizedClamp, kNormalizedClamp);
  }
}

std::vector<float> MinMaxCalibration::normalize(std::span<const float> cells_pf) const {
  std::vector<float> out(cells_pf.size(), 0.0f);
  normalize(cells_pf, out);
  return out;
}

Status MinMaxCalibration::validate() const {
  if (min_pf.empty()) return make_error(Errc::invalid_argument, "the calibration has no cells");
  if (min_pf.size() != max_pf.size()) {
    return make_error(Errc::invalid_argument, "the calibration has " + std::to_string(min_pf.size()) +
                                                  " minima but " + std::to_string(max_pf.size()) + " maxima");
  }
  for (std::size_t i = 0; i < min_pf.size(); ++i) {
    if (!std::isfinite(min_pf[i]) || !std::isfinite(max_pf[i])) {
      return make_error(Errc::invalid_argument, "cell " + std::to_string(i) + " of the calibration has a " +
                                                    "non-finite min or max; calibrate again");
    }
    if (!(min_pf[i] < max_pf[i])) {
      return make_error(Errc::invalid_argument,
                        "cell " + std::to_string(i) + " of the calibration has min " + float_text(min_pf[i]) +
                            " pF >= max " + float_text(max_pf[i]) +
                            " pF; that cell never changed during calibration: explore more, or check the cell");
    }
  }
  return {};
}

Status MinMaxCalibration::check_layout(const StretchGloveLayout& layout) const {
  if (cell_count() != layout.cell_count()) {
    return make_error(Errc::invalid_argument, "the calibration has " + std::to_string(cell_count()) +
                                                  " cells but layout '" + layout.name + "' has " +
                                                  std::to_string(layout.cell_count()) +
                                                  "; calibrate again with this glove");
  }
  if (!layout_name.empty() && !layout.name.empty() && layout_name != layout.name) {
    return make_error(Errc::invalid_argument, "the calibration belongs to layout '" + layout_name +
                                                  "', not '" + layout.name + "'; calibrate again with this glove");
  }
  return {};
}

std::string MinMaxCalibration::to_toml() const {
  std::ostringstream s;
  s << "# Min-max calibration of a stretch-sensing glove: x = 2 (c - min) / (max - min) - 1,\n"
       "# clamped to [-2, 2]. Format: input/stretch_glove/include/proprio/stretch_glove/calibration.hpp.\n";
  s << "layout = " << toml_string(layout_name) << "\n";
  s << "cell_count = " << cell_count() << "\n";
  s << "median_frames = " << median_frames << "\n";
  s << "frames = " << frames << "\n";
  s << "source = " << toml_string(source) << "\n";
  s << "created = " << toml_string(created) << "\n";
  auto array = [&](const char* key, const std::vector<float>& v) {
    s << key << " = [";
    for (std::size_t i = 0; i < v.size(); ++i) s << (i % 8 == 0 ? "\n  " : " ") << float_text(v[i]) << ",";
    s << "\n]\n";
  };
  array("min_pf", min_pf);
  array("max_pf", max_pf);
  return s.str();
}

Status MinMaxCalibration::save(const std::filesystem::path& path) const {
  if (auto st = validate(); !st) return st.error().with_context("not saving calibration '" + path.string() + "'");
  return write_file_atomic(path, to_toml(), "calibration file");
}

Result<MinMaxCalibration> MinMaxCalibration::parse(std::string_view toml_text, const std::string& source_name) {
  auto cfg = Config::parse(toml_text, source_name);
  if (!cfg) return cfg.error().with_context("calibration file is corrupted");
  if (auto k = cfg->check_keys("calibration file", {"layout", "cell_count", "median_frames", "frames", "source",
                                                     "created", "min_pf", "max_pf"});
      !k) {
    return k.error();
  }
  MinMaxCalibration c;
  auto layout = cfg->get_string_or("layout", "");
  if (!layout) return layout.error();
  c.layout_name = *layout;
  auto count = cfg->get_int("cell_count");
  if (!count) return count.error().with_context("calibration file " + source_name + " has no valid cell count");
  auto median = cfg->get_int_or("median_frames", 20, 1, 100000);
  if (!median) return median.error();
  c.median_frames = static_cast<int>(*median);
  auto frames = cfg->get_int_or("frames", 0, 0, std::int64_t{1} << 50);
  if (!frames) return frames.error();
  c.frames = static_cast<std::size_t>(*frames);
  auto src = cfg->get_string_or("source", "");
  if (!src) return src.error();
  c.source = *src;
  auto created = cfg->get_string_or("created", "");
  if (!created) return created.error();
  c.created = *created;

  for (const char* key : {"min_pf", "max_pf"}) {
    auto v = cfg->get_doubles(key);
    if (!v) return v.error();
    if (static_cast<std::int64_t>(v->size()) != *count) {
      return make_error(Errc::invalid_argument, cfg->where(key) + ": '" + key + "' has " +
                                                    std::to_string(v->size()) + " values but cell_count is " +
                                                    std::to_string(*count) + "; the file is corrupted or "
                                                    "truncated: calibrate again");
    }
    auto& dst = std::string_view(key) == "min_pf" ? c.min_pf : c.max_pf;
    for (double x : *v) dst.push_back(static_cast<float>(x));
  }
  for (std::size_t i = 0; i < c.min_pf.size(); ++i) {
    if (!(c.min_pf[i] < c.max_pf[i]) || !std::isfinite(c.min_pf[i]) || !std::isfinite(c.max_pf[i])) {
      return make_error(Errc::invalid_argument,
                        cfg->where("max_pf") + ": cell " + std::to_string(i) + " has min_pf " +
                            float_text(c.min_pf[i]) + " >= max_pf " + float_text(c.max_pf[i]) +
                            " (or one is not finite in single precision); every max must exceed its min: "
                            "calibrate again");
    }
  }
  if (auto st = c.validate(); !st) return st.error().with_context(source_name);
  return c;
}

Result<MinMaxCalibration> MinMaxCalibration::load(const std::filesystem::path& path) {
  auto text = read_input_file(path, "calibration file", 16 * kMiB);
  if (!text) {
    if (text.error().code != Errc::not_found) return text.error();
    return make_error(Errc::not_found, text.error().message + "; " "make one with 'proprio calibrate glove' first");
  }
  return parse(*text, path.string());
}

// --- the calibrator -------------------------------------------------------------------

Status MinMaxCalibratorOptions::validate() const {
  if (median_frames < 1 || median_frames > 10000) {
    return make_error(Errc::invalid_argument, "calibrator option median_frames = " + std::to_string(median_frames) +
                                                  " must be 1-10000 frames");
  }
  for (double v : {typical_range_joint, typical_range_abduction, typical_range_perpendicular, typical_range_dorsum}) {
    if (!(v > 0.0) || !std::isfinite(v)) {
      return make_error(Errc::invalid_argument, "calibrator typical ranges must be fractions of C0 above 0");
    }
  }
  if (!(good_coverage > 0.0 && good_coverage <= 1.0)) {
    return make_error(Errc::invalid_argument, "calibrator option good_coverage must be in (0, 1]");
  }
  return {};
}

std::string MinMaxCalibratorOptions::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "median over %d frames; typical ranges (x C0) joint %.2f, abduction %.2f, perpendicular %.2f, "
                "dorsum %.2f; good coverage %.0f%%",
                median_frames, typical_range_joint, typical_range_abduction, typical_range_perpendicular,
                typical_range_dorsum, good_coverage * 100.0);
  return buf;
}

std::string_view to_string(CalibrationRegion r) noexcept {
  const auto i = static_cast<std::size_t>(r);
  return i < kRegionNames.size() ? kRegionNames[i] : std::string_view("invalid_region");
}

Result<MinMaxCalibrator> MinMaxCalibrator::create(const StretchGloveLayout& layout, MinMaxCalibratorOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  if (layout.cells.empty()) return make_error(Errc::invalid_argument, "the layout has no cells to calibrate");
  MinMaxCalibrator c;
  c.options_ = options;
  c.layout_name_ = layout.name;
  for (const auto& cell : layout.cells) {
    c.cell_names_.push_back(cell.name);
    double typical = options.typical_range_dorsum;
    switch (cell.category) {
      case StretchCellCategory::joint: typical = options.typical_range_joint; break;
      case StretchCellCategory::abduction: typical = options.typical_range_abduction; break;
      case StretchCellCategory::perpendicular: typical = options.typical_range_perpendicular; break;
      case StretchCellCategory::dorsum: typical = options.typical_range_dorsum; break;
    }
    c.typical_pf_.push_back(typical * cell.rest_capacitance_pf);
    const auto f = finger_of(cell.segment);
    c.region_.push_back(f ? static_cast<CalibrationRegion>(*f) : CalibrationRegion::dorsum);
  }
  const std::size_t n = layout.cells.size();
  c.history_.assign(n * static_cast<std::size_t>(options.median_frames), 0.0f);
  c.history_next_.assign(n, 0);
  c.history_count_.assign(n, 0);
  c.min_pf_.assign(n, 0.0f);
  c.max_pf_.assign(n, 0.0f);
  c.median_count_.assign(n, 0);
  c.scratch_.assign(static_cast<std::size_t>(options.median_frames), 0.0f);
  return c;
}

void MinMaxCalibrator::reset() {
  std::fill(history_next_.begin(), history_next_.end(), 0);
  std::fill(history_count_.begin(), history_count_.end(), 0);
  std::fill(median_count_.begin(), median_count_.end(), 0);
  frames_ = 0;
}

void MinMaxCalibrator::add_cell(std::size_t cell, float value) {
  if (!std::isfinite(value)) return;
  const auto F = static_cast<std::size_t>(options_.median_frames);
  float* h = history_.data() + cell * F;
  h[history_next_[cell]] = value;
  history_next_[cell] = static_cast<int>((static_cast<std::size_t>(history_next_[cell]) + 1) % F);
  if (static_cast<std::size_t>(history_count_[cell]) < F) ++history_count_[cell];
  // Extremes come only from full windows, so one spike (or the first
  // frames after donning) cannot set them.
  if (static_cast<std::size_t>(history_count_[cell]) < F) return;
  std::copy(h, h + F, scratch_.begin());
  std::sort(scratch_.begin(), scratch_.end());
  const float median = F % 2 ? scratch_[F / 2] : 0.5f * (scratch_[F / 2 - 1] + scratch_[F / 2]);
  if (median_count_[cell]++ == 0) {
    min_pf_[cell] = max_pf_[cell] = median;
  } else {
    min_pf_[cell] = std::min(min_pf_[cell], median);
    max_pf_[cell] = std::max(max_pf_[cell], median);
  }
}

void MinMaxCalibrator::add(const CellFrame& frame) {
  ++frames_;
  const std::size_t n = std::min(frame.cells_pf.size(), min_pf_.size());
  for (std::size_t i = 0; i < n; ++i) {
    if (i < frame.status.size() && frame.status[i] == CellStatus::valid) add_cell(i, frame.cells_pf[i]);
  }
}

void MinMaxCalibrator::add(std::span<const float> cells_pf) {
  ++frames_;
  const std::size_t n = std::min(cells_pf.size(), min_pf_.size());
  for (std::size_t i = 0; i < n; ++i) add_cell(i, cells_pf[i]);
}

CalibrationProgress MinMaxCalibrator::progress() const {
  CalibrationProgress p;
  p.frames = frames_;
  p.good_coverage = options_.good_coverage;
  const std::size_t n = min_pf_.size();
  p.range_pf.assign(n, 0.0);
  p.coverage.assign(n, 0.0);
  std::array<std::size_t, kCalibrationRegionCount> per_region{};
  for (std::size_t i = 0; i < n; ++i) {
    p.medians = std::max(p.medians, median_count_[i]);
    if (median_count_[i] > 0) p.range_pf[i] = static_cast<double>(max_pf_[i]) - static_cast<double>(min_pf_[i]);
    p.coverage[i] = std::min(1.0, p.range_pf[i] / typical_pf_[i]);
    const auto r = static_cast<std::size_t>(region_[i]);
    p.region_coverage[r] += p.coverage[i];
    ++per_region[r];
    p.overall += p.coverage[i];
  }
  for (std::size_t r = 0; r < kCalibrationRegionCount; ++r) {
    p.region_coverage[r] = per_region[r] ? p.region_coverage[r] / static_cast<double>(per_region[r]) : 1.0;
  }
  if (n) p.overall /= static_cast<double>(n);
  return p;
}

std::string CalibrationProgress::advice() const {
  std::vector<std::size_t> low;
  for (std::size_t r = 0; r < kCalibrationRegionCount; ++r) {
    if (region_coverage[r] < good_coverage) low.push_back(r);
  }
  char pct[32];
  std::snprintf(pct, sizeof pct, "%.0f %%", overall * 100.0);
  if (low.empty()) return std::string("every region is covered (overall ") + pct + "); calibration can finish";
  std::string names, values;
  for (std::size_t k = 0; k < low.size(); ++k) {
    const std::string_view sep = k == 0 ? "" : (k + 1 == low.size() ? " and " : ", ");
    const auto region = static_cast<CalibrationRegion>(low[k]);
    names += std::string(sep) + (region == CalibrationRegion::dorsum ? "the whole hand (fist, spread)"
                                                                     : "the " + std::string(to_string(region)));
    char v[16];
    std::snprintf(v, sizeof v, "%s%.0f %%", k ? ", " : "", region_coverage[low[k]] * 100.0);
    values += v;
  }
  const bool fingers = low.size() > 1 || static_cast<CalibrationRegion>(low[0]) != CalibrationRegion::dorsum;
  return "move " + names + (fingers ? " more through their full range" : " more") + " (coverage " + values +
         "; overall " + pct + ")";
}

Result<MinMaxCalibration> MinMaxCalibrator::finish(std::string source, std::string created) const {
  MinMaxCalibration c;
  c.layout_name = layout_name_;
  c.median_frames = options_.median_frames;
  c.frames = frames_;
  c.source = std::move(source);
  c.created = std::move(created);
  std::string flat;
  std::size_t flat_count = 0;
  for (std::size_t i = 0; i < min_pf_.size(); ++i) {
    if (median_count_[i] == 0 || !(min_pf_[i] < max_pf_[i])) {
      if (flat_count++ < 8) flat += (flat.empty() ? "" : ", ") + cell_names_[i];
    }
  }
  if (flat_count > 0) {
    if (flat_count > 8) flat += " and " + std::to_string(flat_count - 8) + " more";
    return make_error(Errc::unavailable,
                      std::to_string(flat_count) + " cell(s) have no range yet after " + std::to_string(frames_) +
                          " frames (" + flat + "); keep exploring extreme poses (at least " +
                          std::to_string(options_.median_frames) + " frames per pose), or check those cells");
  }
  c.min_pf = min_pf_;
  c.max_pf = max_pf_;
  return c;
}

// --- input grid ---------------------------------------------------------------------------

InputGrid::InputGrid(const StretchGloveLayout& layout) : index_(layout.input_grid_index()) {}

void InputGrid::fill(std::span<const float> normalized, std::span<float> grid) const noexcept {
  std::fill(grid.begin(), grid.end(), 0.0f);
  const std::size_t n = std::min(normalized.size(), index_.size());
  for (std::size_t i = 0; i < n; ++i) {
    const auto slot = static_cast<std::size_t>(index_[i]);
    if (slot < grid.size()) grid[slot] = normalized[i];
  }
}

}  // namespace proprio::stretch_glove
