#include "proprio/stretch_array_eval/array_bench.hpp"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <random>
#include <cmath>
#include <numeric>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "proprio/elastic_sheet/flat_scenarios.hpp"
#include "proprio/stretch_array_eval/array_dataset.hpp"
#include "proprio/stretch_array_recon/array_reconstructor.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/capacitance.hpp"
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

Status DatasetBenchOptions::validate() const {
  if (dataset.empty()) return make_error(Errc::invalid_argument, "no dataset (--dataset)");
  if (models.empty()) return make_error(Errc::invalid_argument, "no models (--models: train array's --out, or an .onnx)");
  return {};
}

namespace {

Result<sa::StripArrayLayout> dataset_layout(const ArrayDataset& d, const std::string& layout_file) {
  if (!layout_file.empty()) return sa::StripArrayLayout::load(layout_file);
  if (d.shape.layout == "prototype_92") return sa::StripArrayLayout::prototype_92();
  if (d.shape.layout == "biceps_144") return sa::StripArrayLayout::biceps_144();
  return make_error(Errc::invalid_argument, "the dataset's layout '" + d.shape.layout +
                                                "' is not a shipped one; pass the layout file (--layout)");
}

// (kind, model file) pairs: train array's OUT/<kind>/model.onnx, or one file.
Result<std::vector<std::pair<std::string, std::filesystem::path>>> model_files(const std::string& where) {
  std::vector<std::pair<std::string, std::filesystem::path>> out;
  const std::filesystem::path p(where);
  if (p.extension() == ".onnx") {
    out.emplace_back(p.parent_path().filename().string(), p);
    return out;
  }
  for (const char* kind : {"dnn", "svm", "lr"}) {
    if (std::filesystem::is_regular_file(p / kind / "model.onnx")) out.emplace_back(kind, p / kind / "model.onnx");
  }
  if (out.empty()) {
    return make_error(Errc::not_found, "no model in '" + where + "': expected <kind>/model.onnx (proprio train array "
                                                                  "--out) or an .onnx file");
  }
  return out;
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

Result<std::vector<ModelSessionResult>> bench_dataset(const DatasetBenchOptions& o, std::optional<SpeedResult>* speed) {
  namespace sar = stretch_array_recon;
  if (auto st = o.validate(); !st) return st.error();
  auto d = load_array_dataset(o.dataset);
  if (!d) return d.error();
  auto layout = dataset_layout(*d, o.layout_file);
  if (!layout) return layout.error();
  const std::size_t C = d->shape.cell_names.size(), M = d->shape.marker_names.size(), V = d->shape.mesh_vertex_count;
  if (layout->cell_count() != C) {
    return make_error(Errc::invalid_argument, fmt::format("the layout has {} cells, the dataset {}", layout->cell_count(), C));
  }
  auto mesh = sar::build_recon_mesh(*layout);
  if (!mesh) return mesh.error();
  auto markers = sar::select_marker_vertices(*mesh);
  if (!markers) return markers.error();
  if (markers->size() != M || mesh->vertex_count() != V) {
    return make_error(Errc::invalid_argument,
                      fmt::format("the dataset has {} markers and {} mesh vertices, this build's reconstruction mesh {} "
                                  "and {}: the dataset was made with other mesh options",
                                  M, V, markers->size(), mesh->vertex_count()));
  }
  auto models = model_files(o.models);
  if (!models) return models.error();

  std::vector<ModelSessionResult> results;
  std::vector<double> first_regressor_ms, first_arap_ms;
  for (const auto& [kind, file] : *models) {
    for (const auto& session : d->sessions) {
      if (session.split != "test") continue;
      auto regressor = sar::MarkerRegressor::load(file, C, M);
      if (!regressor) return regressor.error();
      sar::ArrayReconstructorOptions recon_options;
      recon_options.rest_cylinder_radius_m = d->shape.rest_radius_m;
      auto recon = sar::ArrayReconstructor::create(*mesh, *markers, std::move(*regressor), recon_options);
      if (!recon) return recon.error();
      ModelSessionResult r;
      r.model_kind = kind;
      r.session = session.name;
      r.donning = session.donning;
      r.frames = session.frames;
      std::vector<double> marker_mm, labelled_mm, vertex_mm, regressor_ms, arap_ms;
      Eigen::VectorXd cells(static_cast<Eigen::Index>(C));
      sar::ReconstructedFrame frame;
      for (std::size_t f = session.first_frame; f < session.first_frame + session.frames; ++f) {
        for (std::size_t c = 0; c < C; ++c) cells[static_cast<Eigen::Index>(c)] = d->cells.values[f * C + c];
        if (f == session.first_frame) {
          if (auto st = recon->align_session_from_cells(cells); !st) return st.error();
        }
        if (auto st = recon->reconstruct(cells, frame); !st) return st.error().with_context(session.name);
        for (std::size_t m = 0; m < M; ++m) {
          const std::size_t at = (f * M + m) * 3;
          const Eigen::Vector3d p = frame.markers_m.row(static_cast<Eigen::Index>(m)).transpose();
          const Eigen::Vector3d truth(d->markers_truth.values[at], d->markers_truth.values[at + 1],
                                      d->markers_truth.values[at + 2]);
          const Eigen::Vector3d labelled(d->markers.values[at], d->markers.values[at + 1], d->markers.values[at + 2]);
          marker_mm.push_back(1e3 * (p - truth).norm());
          labelled_mm.push_back(1e3 * (p - labelled).norm());
        }
        for (std::size_t v = 0; v < V; ++v) {
          const std::size_t at = (f * V + v) * 3;
          const Eigen::Vector3d truth(d->vertices_truth.values[at], d->vertices_truth.values[at + 1],
                                      d->vertices_truth.values[at + 2]);
          vertex_mm.push_back(1e3 * (frame.vertices_m.row(static_cast<Eigen::Index>(v)).transpose() - truth).norm());
        }
        regressor_ms.push_back(1e3 * frame.regressor_s);
        arap_ms.push_back(1e3 * frame.arap_s);
      }
      if (first_regressor_ms.empty()) first_regressor_ms = regressor_ms, first_arap_ms = arap_ms;
      r.marker_error_mm = ErrorStats::of(std::move(marker_mm));
      r.marker_error_labelled_mm = ErrorStats::of(std::move(labelled_mm));
      r.vertex_error_mm = ErrorStats::of(std::move(vertex_mm));
      r.regressor_ms = ErrorStats::of(std::move(regressor_ms));
      r.arap_ms = ErrorStats::of(std::move(arap_ms));
      results.push_back(std::move(r));
    }
  }
  if (results.empty()) return make_error(Errc::invalid_argument, "the dataset has no test session (split = test)");

  if (speed) {
    // The read-out's solve of a whole plan, timed on rows of the rest sheet
    // with a little noise, as many frames as the model was timed on.
    auto readout = sa::make_array_readout(*layout);
    if (!readout) return readout.error();
    const Eigen::MatrixXd Mx = layout->measurement_matrix(true);
    Eigen::VectorXd c0(static_cast<Eigen::Index>(C));
    for (std::size_t c = 0; c < C; ++c) {
      c0[static_cast<Eigen::Index>(c)] = sa::plate_capacitance_f(layout->sheet.relative_permittivity,
                                                                  layout->rest_area_m2(c),
                                                                  layout->sheet.dielectric_thickness_m) * 1e12;
    }
    const Eigen::VectorXd rows0 = Mx * c0;
    std::mt19937_64 rng(1);
    std::normal_distribution<double> noise(0.0, 0.002);
    sa::CellFrame cell_frame = readout->make_frame();
    std::vector<double> rows(static_cast<std::size_t>(rows0.size())), solve_ms, total_ms;
    for (std::size_t f = 0; f < first_regressor_ms.size(); ++f) {
      for (std::size_t r = 0; r < rows.size(); ++r) rows[r] = rows0[static_cast<Eigen::Index>(r)] + noise(rng);
      const auto t0 = std::chrono::steady_clock::now();
      if (auto st = readout->solve(rows, static_cast<TimeNs>(f), cell_frame); !st) return st.error();
      solve_ms.push_back(ms_since(t0));
      total_ms.push_back(solve_ms.back() + first_regressor_ms[f] + first_arap_ms[f]);
    }
    SpeedResult sp;
    sp.layout = layout->name;
    sp.cells = C;
    sp.rows = rows.size();
    sp.vertices = V;
    sp.markers = M;
    sp.model = (*models)[0].second.string();
    sp.solve_ms = ErrorStats::of(solve_ms);
    sp.regressor_ms = ErrorStats::of(first_regressor_ms);
    sp.arap_ms = ErrorStats::of(first_arap_ms);
    sp.total_ms = ErrorStats::of(total_ms);
    *speed = sp;
  }
  return results;
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
  if (!dataset.empty()) {
    auto& rows = j["dataset"] = nlohmann::ordered_json::array();
    for (const auto& r : dataset) {
      rows.push_back({{"ran", true},
                      {"dataset", dataset_name},
                      {"model", r.model_kind},
                      {"session", r.session},
                      {"donning", r.donning},
                      {"frames", r.frames},
                      {"marker_error_mm", stats_json(r.marker_error_mm)},
                      {"marker_error_vs_labelled_mm", stats_json(r.marker_error_labelled_mm)},
                      {"vertex_error_mm", stats_json(r.vertex_error_mm)},
                      {"regressor_ms", stats_json(r.regressor_ms)},
                      {"arap_ms", stats_json(r.arap_ms)}});
    }
  } else {
    j["dataset"] = {{"ran", false}};
  }
  if (speed) {
    j["speed"] = {{"ran", true},
                  {"layout", speed->layout},
                  {"cells", speed->cells},
                  {"rows", speed->rows},
                  {"vertices", speed->vertices},
                  {"markers", speed->markers},
                  {"model", speed->model},
                  {"solve_ms", stats_json(speed->solve_ms)},
                  {"regressor_ms", stats_json(speed->regressor_ms)},
                  {"arap_ms", stats_json(speed->arap_ms)},
                  {"total_ms", stats_json(speed->total_ms)},
                  {"target_ms", 5.0}};
  } else {
    j["speed"] = {{"ran", false}};
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
  if (!dataset.empty()) {
    s += fmt::format("  {} test sessions: error in mm, mean / std / max (thesis Table 4.1 reports against its mocap)\n",
                     dataset_name);
    for (const auto& r : dataset) {
      s += fmt::format("    {:4} {:24} {:5} frames  markers vs truth {:.2f} / {:.2f} / {:.2f}, vs labelled {:.2f}; "
                       "dense vertices {:.2f} / {:.2f} / {:.2f}\n",
                       r.model_kind, r.session, r.frames, r.marker_error_mm.mean, r.marker_error_mm.std,
                       r.marker_error_mm.max, r.marker_error_labelled_mm.mean, r.vertex_error_mm.mean,
                       r.vertex_error_mm.std, r.vertex_error_mm.max);
    }
  } else {
    s += "  dataset: not run (--dataset and --models)\n";
  }
  if (speed) {
    s += fmt::format("  speed, {} ({} cells, {} rows, {} vertices, {} markers), one core, per frame: solve {:.3f} ms, "
                     "regressor {:.2f} ms, ARAP {:.2f} ms, total mean {:.2f} ms, p95 {:.2f}, max {:.2f} "
                     "(target <= 5 ms); model {}\n",
                     speed->layout, speed->cells, speed->rows, speed->vertices, speed->markers, speed->solve_ms.mean,
                     speed->regressor_ms.mean, speed->arap_ms.mean, speed->total_ms.mean, speed->total_ms.p95,
                     speed->total_ms.max, speed->model);
  } else {
    s += "  speed: not run (needs --dataset and --models)\n";
  }
  return s;
}

}  // namespace proprio::stretch_array_eval
