#include "proprio/stretch_board/stretch_array_reader.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>

#include "proprio/stretch_array/capacitance.hpp"

namespace proprio::devices {

namespace {

Error bad_layout(const stretch_array::StripArrayLayout& layout, const std::string& what) {
  return make_error(Errc::invalid_argument, "stretch board: layout '" + layout.name + "' " + what);
}

}  // namespace

Result<StretchArrayPlan> stretch_array_plan(const stretch_array::StripArrayLayout& layout, bool single_strips) {
  if (auto st = layout.validate(); !st) return st.error();
  const std::size_t n = layout.top_strips.size(), k = layout.bottom_strips.size();
  if (n > kStretchMaxStrips || k > kStretchMaxStrips) {
    return bad_layout(layout, "has " + std::to_string(n) + " top and " + std::to_string(k) +
                                  " bottom strips; the board's protocol carries 1 to " +
                                  std::to_string(kStretchMaxStrips) + " per layer");
  }
  const std::size_t rows = stretch_row_count(n, k, single_strips);
  if (rows > kStretchMaxCombinations) {
    return bad_layout(layout, "needs " + std::to_string(rows) + " rows (" + std::to_string(n) + " x " +
                                  std::to_string(k) + " pairs + " + std::to_string(n + k) +
                                  " single strips), but the board's 10-bit combination field holds " +
                                  std::to_string(kStretchMaxCombinations) +
                                  "; use fewer strips, or pairs only if M^I alone reads it");
  }
  StretchArrayPlan plan;
  plan.top_strips = static_cast<std::uint8_t>(n);
  plan.bottom_strips = static_cast<std::uint8_t>(k);
  plan.single_strips = single_strips;
  return plan;
}

Result<StretchEmulatorOptions> stretch_array_emulator_options(const stretch_array::StripArrayLayout& layout,
                                                              StretchEmulatorOptions base, bool single_strips) {
  auto plan = stretch_array_plan(layout, single_strips);
  if (!plan) return plan.error();
  base.top_strips = plan->top_strips;
  base.bottom_strips = plan->bottom_strips;
  base.single_strips = plan->single_strips;
  if (auto st = base.validate(); !st) return st.error();
  return base;
}

StretchCapacitanceProvider stretch_array_provider(const stretch_array::StripArrayLayout& layout,
                                                  StretchArrayCells cells, std::vector<double> row_parasitic_pf) {
  // Shared state: std::function copies its target, and the scratch vector must not be reallocated per call.
  struct State {
    Eigen::MatrixXd M;
    StretchArrayCells cells;
    std::vector<double> parasitic_pf;
    std::vector<double> cells_pf;
    TimeNs cached_t = 0;
    bool cached = false;
  };
  auto state = std::make_shared<State>();
  state->M = layout.measurement_matrix(true);
  state->cells = std::move(cells);
  state->parasitic_pf = std::move(row_parasitic_pf);
  state->cells_pf.assign(layout.cell_count(), 0.0);
  return [state](std::size_t combination, TimeNs t_ns) -> double {
    State& s = *state;
    if (combination >= static_cast<std::size_t>(s.M.rows()) || !s.cells) return std::nan("");
    if (!s.cached || s.cached_t != t_ns) {
      s.cells(t_ns, s.cells_pf);
      s.cached_t = t_ns;
      s.cached = true;
    }
    double pf = combination < s.parasitic_pf.size() ? s.parasitic_pf[combination] : 0.0;
    const auto r = static_cast<Eigen::Index>(combination);
    for (Eigen::Index c = 0; c < s.M.cols(); ++c) {
      if (s.M(r, c) != 0.0) pf += s.cells_pf[static_cast<std::size_t>(c)];
    }
    return pf;
  };
}

// --- calibration ------------------------------------------------------------------

void StretchRowMeans::add(std::span<const StretchSample> samples) noexcept {
  for (const StretchSample& s : samples) {
    if (s.status != StretchMeasurementStatus::ok || s.combination >= sum_pf_.size()) {
      ++skipped_;
      continue;
    }
    sum_pf_[s.combination] += s.capacitance_pf;
    ++count_[s.combination];
  }
}

Result<std::vector<double>> StretchRowMeans::means(std::size_t min_samples) const {
  std::vector<double> out(sum_pf_.size(), 0.0);
  std::string short_rows;
  std::size_t missing = 0;
  for (std::size_t r = 0; r < sum_pf_.size(); ++r) {
    if (count_[r] < std::max<std::size_t>(min_samples, 1)) {
      if (++missing <= 8) short_rows += (short_rows.empty() ? "" : ", ") + std::to_string(r);
      continue;
    }
    out[r] = sum_pf_[r] / static_cast<double>(count_[r]);
  }
  if (missing > 0) {
    return make_error(Errc::invalid_argument, "stretch board calibration: " + std::to_string(missing) + " of " +
                                                  std::to_string(sum_pf_.size()) + " rows have fewer than " +
                                                  std::to_string(min_samples) + " good measurements (rows " +
                                                  short_rows + (missing > 8 ? ", ..." : "") +
                                                  "); record longer, or check those rows' leads");
  }
  return out;
}

std::vector<double> array_rest_capacitances_pf(const stretch_array::StripArrayLayout& layout) {
  std::vector<double> rest_pf;
  rest_pf.reserve(layout.cell_count());
  for (std::size_t c = 0; c < layout.cell_count(); ++c) {
    rest_pf.push_back(1e12 * stretch_array::plate_capacitance_f(layout.sheet.relative_permittivity,
                                                                layout.rest_area_m2(c),
                                                                layout.sheet.dielectric_thickness_m));
  }
  return rest_pf;
}

Result<std::vector<double>> row_parasitics_at_rest(const stretch_array::StripArrayLayout& layout,
                                                   std::span<const double> row_means_pf) {
  const Eigen::MatrixXd M = layout.measurement_matrix(true);
  if (row_means_pf.size() != static_cast<std::size_t>(M.rows())) {
    return bad_layout(layout, "has " + std::to_string(M.rows()) + " rows, but the calibration has " +
                                  std::to_string(row_means_pf.size()) + " row means");
  }
  const std::vector<double> rest = array_rest_capacitances_pf(layout);
  const Eigen::VectorXd c0 = Eigen::Map<const Eigen::VectorXd>(rest.data(), static_cast<Eigen::Index>(rest.size()));
  const Eigen::VectorXd modelled = M * c0;
  std::vector<double> out(row_means_pf.size());
  for (std::size_t r = 0; r < out.size(); ++r) {
    if (!std::isfinite(row_means_pf[r])) {
      return bad_layout(layout, "calibration row " + std::to_string(r) + " is not finite");
    }
    out[r] = row_means_pf[r] - modelled(static_cast<Eigen::Index>(r));
  }
  return out;
}

// --- reader ------------------------------------------------------------------------

Status StretchArrayReaderOptions::validate(std::size_t rows) const {
  if (auto st = readout.validate(); !st) return st;
  if (!(negative_tolerance_pf >= 0.0 && negative_tolerance_pf <= 1.0)) {
    char buf[160];
    std::snprintf(buf, sizeof buf,
                  "stretch array reader: negative_tolerance_pf = %g is not usable: use 0 to 1 pF (a few fF is "
                  "the wire's step plus calibration noise)",
                  negative_tolerance_pf);
    return make_error(Errc::invalid_argument, buf);
  }
  if (!row_parasitic_pf.empty() && row_parasitic_pf.size() != rows) {
    return make_error(Errc::invalid_argument, "stretch array reader: row_parasitic_pf has " +
                                                  std::to_string(row_parasitic_pf.size()) +
                                                  " values; the layout's plan has " + std::to_string(rows) +
                                                  " rows (pairs, then single strips): give one per row, or none");
  }
  for (std::size_t r = 0; r < row_parasitic_pf.size(); ++r) {
    const double p = row_parasitic_pf[r];
    // Larger than the wire's full scale cannot be a stray capacitance the board could measure around.
    if (!std::isfinite(p) || std::fabs(p) > kStretchWireFullScalePf) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "stretch array reader: row_parasitic_pf[%zu] = %g pF is not usable: it must be finite and within "
                    "+-%.3f pF (the wire's full scale)",
                    r, p, kStretchWireFullScalePf);
      return make_error(Errc::invalid_argument, buf);
    }
  }
  return {};
}

std::string StretchArrayReaderOptions::describe() const {
  std::string s = readout.describe();
  s += row_parasitic_pf.empty()
           ? "; no per-row parasitic subtraction"
           : "; per-row parasitics subtracted (" + std::to_string(row_parasitic_pf.size()) + " rows)";
  s += require_single_strips ? "; requires single-strip rows" : "; single-strip rows optional";
  return s;
}

Result<StretchArrayReader> StretchArrayReader::create(const stretch_array::StripArrayLayout& layout,
                                                      StretchArrayReaderOptions options) {
  auto plan = stretch_array_plan(layout, true);
  if (!plan) return plan.error();
  if (auto st = options.validate(plan->rows()); !st) return st.error();
  auto readout = stretch_array::make_array_readout(layout, options.readout);
  if (!readout) return readout.error();
  return StretchArrayReader(*plan, std::move(*readout), std::move(options));
}

StretchArrayReader::StretchArrayReader(StretchArrayPlan plan, stretch_array::MatrixReadout readout,
                                       StretchArrayReaderOptions options)
    : plan_(plan), readout_(std::move(readout)), options_(std::move(options)), stream_(StretchStreamOptions{}) {
  stream_ = StretchStreamDecoder(stream_options());
}

StretchStreamOptions StretchArrayReader::stream_options() const {
  StretchStreamOptions o;
  o.expected_top_strips = plan_.top_strips;
  o.expected_bottom_strips = plan_.bottom_strips;
  o.require_single_strips = options_.require_single_strips;
  return o;
}

void StretchArrayReader::reset() {
  readout_.reset();
  have_epoch_ = false;
}

bool StretchArrayReader::add(std::span<const StretchSample> samples, stretch_array::CellFrame& out) {
  const std::size_t rows = readout_.measurement_count();
  for (const StretchSample& s : samples) {
    if (have_epoch_ && s.epoch != epoch_) {
      // A restarted board: what was recorded belongs to the old run (and maybe another plan).
      readout_.reset();
      ++stats_.epochs;
    }
    have_epoch_ = true;
    epoch_ = s.epoch;
    if (s.combination >= rows) {
      ++stats_.out_of_plan;
      continue;
    }
    double pf = s.capacitance_pf;
    if (s.status != StretchMeasurementStatus::ok) {
      ++stats_.flagged;
      pf = std::nan("");  // the read-out leaves the row out until it is measured again
    } else if (!options_.row_parasitic_pf.empty()) {
      pf -= options_.row_parasitic_pf[s.combination];
      if (pf < 0.0 && pf >= -options_.negative_tolerance_pf) {
        pf = 0.0;
        ++stats_.clamped;
      } else if (pf < 0.0) {
        ++stats_.below_parasitic;  // negative: the read-out leaves the row out
      }
    }
    const TimeNs t = s.time_ns != 0 ? s.time_ns : static_cast<TimeNs>(s.device_time_us) * 1000;
    readout_.record(s.combination, pf, t);
    ++stats_.measurements;
  }
  if (!readout_.solve_due(out)) return false;
  ++stats_.frames;
  return true;
}

StretchArrayReader::PushResult StretchArrayReader::push_report(std::span<const std::uint8_t> report, TimeNs receive_ns,
                                                               stretch_array::CellFrame& out) {
  PushResult r;
  std::array<StretchSample, kStretchMeasurementsPerReport> samples;
  r.report = stream_.push(report, samples, receive_ns);
  if (r.report.verdict == StretchReportVerdict::accepted) {
    r.frame = add(std::span<const StretchSample>(samples.data(), r.report.sample_count), out);
  }
  return r;
}

}  // namespace proprio::devices
