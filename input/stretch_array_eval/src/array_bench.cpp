#include "proprio/stretch_array_eval/array_bench.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "proprio/elastic_sheet/flat_scenarios.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "sheet_timeline.hpp"

namespace proprio::stretch_array_eval {

namespace es = elastic_sheet;
namespace sa = stretch_array;
namespace sas = stretch_array_sim;

ErrorStats ErrorStats::of(std::vector<double> v) {
  ErrorStats s;
  s.samples = v.size();
  if (v.empty()) return s;
  s.mean = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
  double ss = 0.0;
  for (double x : v) ss += (x - s.mean) * (x - s.mean);
  s.std = std::sqrt(ss / static_cast<double>(v.size()));
  std::sort(v.begin(), v.end());
  s.p95 = v[std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(0.95 * static_cast<double>(v.size()))) - 1)];
  s.max = v.back();
  return s;
}

Status BenchArrayOptions::validate() const {
  if (!(uniaxial_max_stretch > 1.0 && uniaxial_max_stretch <= 3.0)) {
    return make_error(Errc::invalid_argument, "the uniaxial stretch must be above 1 and at most 3");
  }
  if (uniaxial_positions < 3) return make_error(Errc::invalid_argument, "the stage needs at least 3 positions");
  if (!(string_pull_seconds > 0.0 && string_pull_seconds <= 3600.0) || !(frame_rate_hz > 0.0 && frame_rate_hz <= 1000.0)) {
    return make_error(Errc::invalid_argument, "string-pull seconds and frame rate out of range");
  }
  return board.validate();
}

namespace {

// The board's reading of one whole frame through the wire (1 fF), less the
// host's rest calibration, solved by least squares: each cell's pF.
class HostReadout {
 public:
  static Result<HostReadout> create(const sa::StripArrayLayout& layout, sas::BoardSimulator board) {
    auto readout = sa::make_array_readout(layout);
    if (!readout) return readout.error();
    auto calibration = board.calibrate_at_rest(0.0, 8);
    if (!calibration) return calibration.error().with_context("the rest calibration");
    return HostReadout(std::move(board), std::move(*readout), std::move(calibration->parasitic_pf));
  }
  Result<std::vector<double>> cells_pf(const sas::BoardFrame& frame, double t_s) {
    rows_.resize(frame.rows_pf.size());
    for (std::size_t r = 0; r < rows_.size(); ++r) {
      const auto wire = devices::quantise_capacitance(static_cast<std::uint16_t>(r), frame.rows_pf[r]);
      rows_[r] = wire.status == devices::StretchMeasurementStatus::ok
                     ? devices::stretch_count_to_pf(wire.value) - parasitic_pf_[r]
                     : std::nan("");
    }
    if (auto st = readout_.solve(rows_, static_cast<TimeNs>(t_s * 1e9), frame_); !st) return st.error();
    return std::vector<double>(frame_.cells_pf.begin(), frame_.cells_pf.end());
  }
  sas::BoardSimulator& board() { return board_; }

 private:
  HostReadout(sas::BoardSimulator board, sa::MatrixReadout readout, std::vector<double> parasitic)
      : board_(std::move(board)), readout_(std::move(readout)), parasitic_pf_(std::move(parasitic)) {
    frame_ = readout_.make_frame();
  }
  sas::BoardSimulator board_;
  sa::MatrixReadout readout_;
  std::vector<double> parasitic_pf_;
  std::vector<double> rows_;
  sa::CellFrame frame_;
};

Result<HostReadout> host_for(const sas::ArraySheet& sheet, const sas::BoardOptions& options) {
  auto board = sas::BoardSimulator::create(sheet, options);
  if (!board) return board.error();
  return HostReadout::create(sheet.layout(), std::move(*board));
}

nlohmann::ordered_json stats_json(const ErrorStats& s) {
  return {{"samples", s.samples}, {"mean", s.mean}, {"std", s.std}, {"p95", s.p95}, {"max", s.max}};
}

}  // namespace

Result<UniaxialResult> bench_uniaxial(const BenchArrayOptions& o) {
  if (auto st = o.validate(); !st) return st.error();
  // A 15 mm wide strip of sheet, 100 mm between the clamps, with the 15 x 50
  // mm cell in its middle: the clamps' edge effects (the sheet cannot narrow
  // at a clamp) die out within about a width, so the cell is in uniaxial
  // tension as on the thesis's linear stage.
  constexpr double kCellLength = 0.050, kMargin = 0.025;
  es::UniaxialOptions rig_options;
  rig_options.length_m = kCellLength + 2 * kMargin;
  auto rig = es::UniaxialStretchRig::create(rig_options);
  if (!rig) return rig.error();
  sa::StripArrayLayout layout;
  layout.name = "uniaxial_15x50";
  layout.top_strips = {{"T0", rig_options.width_m / 2, rig_options.width_m}};
  layout.bottom_strips = {{"B0", rig_options.length_m / 2, kCellLength}};
  layout.cells = {{"T0-B0", 0, 0, {}}};
  if (auto st = layout.validate(); !st) return st.error();
  sa::SheetMesh mesh = rig->mesh();
  std::vector<std::uint32_t> cell_start, cell_end;  // vertices on the cell's two ends
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    double y = 0.0;
    for (auto v : mesh.triangles[t]) y += mesh.vertices_m[v].y() / 3.0;
    mesh.cell_of_triangle[t] = y > kMargin && y < kMargin + kCellLength ? 0 : -1;
  }
  for (std::size_t v = 0; v < mesh.vertices_m.size(); ++v) {
    if (std::abs(mesh.vertices_m[v].y() - kMargin) < 1e-9) cell_start.push_back(static_cast<std::uint32_t>(v));
    if (std::abs(mesh.vertices_m[v].y() - kMargin - kCellLength) < 1e-9) cell_end.push_back(static_cast<std::uint32_t>(v));
  }
  if (cell_start.empty() || cell_end.empty()) {
    return make_error(Errc::invalid_argument, "the uniaxial rig's grid has no vertex rows on the cell's ends");
  }
  auto sheet = sas::ArraySheet::create(layout, mesh);
  if (!sheet) return sheet.error().with_context("the uniaxial cell");
  auto host = host_for(*sheet, o.board);
  if (!host) return host.error();
  auto ideal = host_for(*sheet, sas::BoardOptions::ideal());
  if (!ideal) return ideal.error();

  auto mean_y = [](const std::vector<Eigen::Vector3d>& x, const std::vector<std::uint32_t>& vs) {
    double y = 0.0;
    for (auto v : vs) y += x[v].y() / static_cast<double>(vs.size());
    return y;
  };
  std::vector<double> stage;
  const int up = o.uniaxial_positions / 2;
  for (int i = 0; i <= up; ++i) stage.push_back(1.0 + (o.uniaxial_max_stretch - 1.0) * i / up);
  for (int i = up - 1; i >= 0; --i) stage.push_back(stage[static_cast<std::size_t>(i)]);
  UniaxialResult r;
  r.max_stretch = o.uniaxial_max_stretch;
  r.stage_positions = stage.size();
  std::vector<double> errors, errors_ideal;
  double c0 = 0.0, c0_ideal = 0.0;
  for (std::size_t i = 0; i < stage.size(); ++i) {
    auto solved = rig->set_stretch(stage[i]);
    if (!solved) return solved.error();
    if (!solved->converged) {
      return make_error(Errc::unavailable, fmt::format("the uniaxial rig did not converge at stretch {:.3f}", stage[i]));
    }
    const auto& x = rig->vertices_m();
    // The truth: the cell's own length over its rest length.
    const double lambda = (mean_y(x, cell_end) - mean_y(x, cell_start)) / kCellLength;
    auto state = sheet->evaluate(x);
    if (!state) return state.error();
    const double t = static_cast<double>(i);  // a stage position per second
    for (auto* h : {&*host, &*ideal}) {
      auto frame = h->board().measure_static(t, *state);
      if (!frame) return frame.error();
      auto cells = h->cells_pf(*frame, t);
      if (!cells) return cells.error();
      double& base = h == &*host ? c0 : c0_ideal;
      if (i == 0) base = (*cells)[0];
      if (!(base > 0.0)) return make_error(Errc::unavailable, "the uniaxial cell reads no capacitance at rest");
      // Eq. 4.2: l / l0 = C / C0.
      const double estimate = (*cells)[0] / base;
      if (i > 0) (h == &*host ? errors : errors_ideal).push_back(std::abs(estimate - lambda) / lambda);
    }
    if (stage[i] == o.uniaxial_max_stretch) r.width_ratio_at_max = rig->mid_width_m() / rig_options.width_m;
  }
  r.relative_length_error = ErrorStats::of(errors);
  r.relative_length_error_ideal = ErrorStats::of(errors_ideal);
  return r;
}

Result<StringPullResult> bench_string_pull(const BenchArrayOptions& o) {
  if (auto st = o.validate(); !st) return st.error();
  const sa::StripArrayLayout layout = sa::StripArrayLayout::prototype_92();
  auto mesh = sa::build_sheet_mesh(layout);
  if (!mesh) return mesh.error();
  es::StringPullOptions pull_options;
  pull_options.seed = o.seed;
  auto rig = es::StringPullRig::create(*mesh, pull_options);
  if (!rig) return rig.error();
  auto sheet = sas::ArraySheet::create(layout, *mesh);
  if (!sheet) return sheet.error();
  sas::BoardOptions board_options = o.board;
  board_options.timing.row_rate_hz = o.frame_rate_hz * static_cast<double>(layout.measurement_plan(true).size());
  auto host = host_for(*sheet, board_options);
  if (!host) return host.error();
  sas::BoardOptions ideal_options = sas::BoardOptions::ideal();
  ideal_options.timing.row_rate_hz = board_options.timing.row_rate_hz;
  auto ideal = host_for(*sheet, ideal_options);
  if (!ideal) return ideal.error();

  const double frame_s = 1.0 / o.frame_rate_hz;
  SheetTimeline timeline(
      [&](double t_s) -> Result<std::vector<Eigen::Vector3d>> {
        auto step = rig->step(t_s);
        if (!step) return step.error();
        return std::vector<Eigen::Vector3d>(rig->vertices_m().begin(), rig->vertices_m().end());
      },
      *sheet, frame_s / 2);
  if (auto st = timeline.start(); !st) return st.error();
  const sas::StateProvider provider = [&timeline](double t) { return timeline.state_at(t); };

  StringPullResult r;
  r.layout = layout.name;
  r.cells = layout.cell_count();
  const auto frames = static_cast<std::size_t>(std::floor(o.string_pull_seconds * o.frame_rate_hz));
  std::vector<double> c0, c0_ideal, errors, errors_ideal, errors_stretched;
  for (std::size_t k = 0; k < frames; ++k) {
    const double t0 = static_cast<double>(k) * frame_s, t_end = t0 + frame_s;
    std::vector<double> measured[2];
    int which = 0;
    for (auto* h : {&*host, &*ideal}) {
      auto frame = h->board().measure_frame(t0, provider);
      if (!frame) return frame.error();
      auto cells = h->cells_pf(*frame, t_end);
      if (!cells) return cells.error();
      measured[which++] = std::move(*cells);
    }
    auto x = timeline.vertices_at(t_end);
    if (!x) return x.error();
    auto truth = sheet->eq48_ratio(*x);
    if (!truth) return truth.error();
    if (k == 0) {  // the strings start slack: C0
      c0 = measured[0];
      c0_ideal = measured[1];
      continue;
    }
    for (std::size_t c = 0; c < r.cells; ++c) {
      const double want = (*truth)[c];
      r.max_area_ratio = std::max(r.max_area_ratio, std::sqrt(want));
      const double e = std::abs(measured[0][c] / c0[c] - want) / want;
      errors.push_back(e);
      errors_ideal.push_back(std::abs(measured[1][c] / c0_ideal[c] - want) / want);
      if (want > 1.05) errors_stretched.push_back(e);
    }
    ++r.frames;
  }
  r.relative_error = ErrorStats::of(errors);
  r.relative_error_ideal = ErrorStats::of(errors_ideal);
  r.relative_error_stretched = ErrorStats::of(errors_stretched);
  return r;
}

std::string BenchArrayReport::json() const {
  nlohmann::ordered_json j;
  j["simulated"] = "simulated accuracy is not real-world accuracy";
  if (uniaxial) {
    j["uniaxial"] = {{"ran", true},
                     {"max_stretch", uniaxial->max_stretch},
                     {"stage_positions", uniaxial->stage_positions},
                     {"relative_length_error", stats_json(uniaxial->relative_length_error)},
                     {"relative_length_error_ideal_board", stats_json(uniaxial->relative_length_error_ideal)},
                     {"width_ratio_at_max", uniaxial->width_ratio_at_max},
                     {"target_mean", 0.0085},
                     {"thesis_mean", 0.0096}};
  } else {
    j["uniaxial"] = {{"ran", false}};
  }
  if (string_pull) {
    j["string_pull"] = {{"ran", true},
                        {"layout", string_pull->layout},
                        {"frames", string_pull->frames},
                        {"cells", string_pull->cells},
                        {"max_area_ratio", string_pull->max_area_ratio},
                        {"relative_error", stats_json(string_pull->relative_error)},
                        {"relative_error_ideal_board", stats_json(string_pull->relative_error_ideal)},
                        {"relative_error_stretched_cells", stats_json(string_pull->relative_error_stretched)},
                        {"target_mean", 0.05},
                        {"thesis_mean", 0.077}};
  } else {
    j["string_pull"] = {{"ran", false}};
  }
  return j.dump(2);
}

std::string BenchArrayReport::describe() const {
  std::string s = "Stretch array bench (simulated; simulated accuracy is not real-world accuracy)\n";
  if (uniaxial) {
    const auto& u = *uniaxial;
    s += fmt::format("  uniaxial 15 x 50 mm cell, stage to {:.2f}x, {} positions: relative length error mean {:.4f} "
                     "(p95 {:.4f}, max {:.4f}; target <= 0.0085, thesis 0.0096); ideal board {:.4f}; width at max "
                     "stretch {:.3f} of rest\n",
                     u.max_stretch, u.stage_positions, u.relative_length_error.mean, u.relative_length_error.p95,
                     u.relative_length_error.max, u.relative_length_error_ideal.mean, u.width_ratio_at_max);
  } else {
    s += "  uniaxial: not run\n";
  }
  if (string_pull) {
    const auto& p = *string_pull;
    s += fmt::format("  string-pulled {} sheet, {} frames x {} cells (largest area ratio {:.2f}): C/C0 vs eq. 4.8 "
                     "relative error mean {:.2f} % (p95 {:.2f} %, max {:.2f} %; target <= 5 %, thesis 7.7 %); "
                     "stretched cells only {:.2f} %; ideal board {:.2f} %\n",
                     p.layout, p.frames, p.cells, p.max_area_ratio, 100 * p.relative_error.mean,
                     100 * p.relative_error.p95, 100 * p.relative_error.max, 100 * p.relative_error_stretched.mean,
                     100 * p.relative_error_ideal.mean);
  } else {
    s += "  string-pull: not run\n";
  }
  return s;
}

}  // namespace proprio::stretch_array_eval
