#include "proprio/stretch_array_eval/sim_array.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numeric>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "proprio/core/log.hpp"
#include "proprio/elastic_sheet/elastic_sheet.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"
#include "proprio/stretch_array_eval/array_dataset.hpp"
#include "proprio/stretch_array_recon/marker_labelling.hpp"
#include "proprio/stretch_array_recon/recon_mesh.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "sheet_timeline.hpp"

namespace proprio::stretch_array_eval {

namespace es = elastic_sheet;
namespace sa = stretch_array;
namespace sas = stretch_array_sim;
namespace sar = stretch_array_recon;

namespace {

struct SessionPlan {
  std::string name, split;
  int donning = 0;
  double minutes = 0.0;
  std::uint64_t seed = 0;
};

// What every session shares, built once.
struct Shared {
  sa::StripArrayLayout layout;
  sa::SheetMesh sheet_mesh;
  sar::ReconMesh recon;
  std::vector<std::uint32_t> marker_vertices;
  std::vector<es::MaterialPoint> recon_points;  // per recon vertex, on the simulated sheet
  es::BodyKind body = es::BodyKind::wrist;
};

std::uint64_t mix(std::uint64_t seed, std::uint64_t salt) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (salt + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

Result<Shared> build_shared(const SimArrayOptions& o) {
  Shared s;
  auto body = es::parse_body_kind(o.motion);
  if (!body) return body.error();
  s.body = *body;
  auto layout = layout_for_motion(o.layout_file, o.motion);
  if (!layout) return layout.error();
  s.layout = std::move(*layout);
  auto mesh = sa::build_sheet_mesh(s.layout);
  if (!mesh) return mesh.error().with_context("the simulated sheet");
  s.sheet_mesh = std::move(*mesh);
  auto recon = sar::build_recon_mesh(s.layout);
  if (!recon) return recon.error().with_context("the reconstruction mesh");
  s.recon = std::move(*recon);
  auto markers = sar::select_marker_vertices(s.recon);
  if (!markers) return markers.error();
  s.marker_vertices = std::move(*markers);
  // Both meshes span the strips plus the same margin; a boundary vertex may
  // sit a rounding error outside the simulated sheet, so it is looked up a
  // micrometre towards the sheet's middle.
  Eigen::Vector2d lo = s.recon.sheet_xy_m[0], hi = lo;
  for (const auto& p : s.recon.sheet_xy_m) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Eigen::Vector2d mid = 0.5 * (lo + hi);
  for (const auto& p : s.recon.sheet_xy_m) {
    const Eigen::Vector2d d = mid - p;
    const Eigen::Vector2d q = d.norm() > 0 ? Eigen::Vector2d(p + 1e-6 * d.normalized()) : p;
    auto point = es::locate_material_point(s.sheet_mesh, q);
    if (!point) return point.error().with_context("a reconstruction vertex outside the simulated sheet");
    s.recon_points.push_back(*point);
  }
  return s;
}

// The optical system at the frame rate: occlusion given in time becomes the
// simulator's per-frame chain.
sas::MocapOptions frame_rate_mocap(const SimArrayOptions& o) {
  sas::MocapOptions m = o.mocap;
  if (m.p_lose > 0.0) {
    // share = p L / (1 + p L) for the two-state chain with mean run L frames.
    m.mean_occluded_frames = std::max(1.0, o.mean_occlusion_s * o.frame_rate_hz);
    m.p_lose = o.occluded_share / ((1.0 - o.occluded_share) * m.mean_occluded_frames);
  }
  return m;
}

struct SessionResult {
  ArrayDatasetSession data;
  SimArraySessionReport report;
};

Result<SessionResult> simulate_session(const SimArrayOptions& o, const Shared& sh, const SessionPlan& plan,
                                       std::atomic<double>& minutes_done) {
  const auto wall_start = std::chrono::steady_clock::now();
  std::shared_ptr<const es::BodyProxy> body = es::make_body(sh.body, mix(plan.seed, 1));
  auto sheet_options = es::ElasticSheetOptions::from_layout(sh.layout);
  if (plan.donning > 0) sheet_options.placement = sheet_options.placement.redonned(mix(plan.seed, 2));
  auto sheet = es::ElasticSheet::create(sh.sheet_mesh, body, sheet_options);
  if (!sheet) return sheet.error().with_context("donning the sheet");
  auto array = sas::ArraySheet::create(sh.layout, sh.sheet_mesh);
  if (!array) return array.error();
  sas::BoardOptions board_options = o.board;
  board_options.seed = mix(plan.seed, 3);
  auto board = sas::BoardSimulator::create(*array, board_options);
  if (!board) return board.error();
  // The host's calibration: the sheet flat on the table before it is put on
  // (BoardSimulator::calibrate_at_rest), then the donning's own offsets.
  auto calibration = board->calibrate_at_rest(0.0, 8);
  if (!calibration) return calibration.error().with_context("the rest calibration");
  board->set_donning(static_cast<std::uint32_t>(plan.donning));
  auto readout = sa::make_array_readout(sh.layout);
  if (!readout) return readout.error();
  auto mocap_options = frame_rate_mocap(o);
  mocap_options.seed = mix(plan.seed, 4);
  auto mocap = sas::MocapSimulator::create(sh.marker_vertices.size(), mocap_options);
  if (!mocap) return mocap.error();

  const double frame_s = 1.0 / o.frame_rate_hz;
  // Still for rest_s, then the motion.
  auto body_time = [&o](double t_s) { return std::max(0.0, t_s - o.rest_s); };
  SheetTimeline timeline(
      [&](double t_s) -> Result<std::vector<Eigen::Vector3d>> {
        auto step = sheet->step(body_time(t_s));
        if (!step) return step.error().with_context(fmt::format("the sheet at t = {:.3f} s", t_s));
        return std::vector<Eigen::Vector3d>(sheet->vertices_m().begin(), sheet->vertices_m().end());
      },
      *array, frame_s / o.mechanics_steps_per_frame);
  if (auto st = timeline.start(); !st) return st.error();
  const std::size_t C = sh.layout.cell_count(), M = sh.marker_vertices.size(), V = sh.recon.vertex_count();
  const auto frames = static_cast<std::size_t>(std::floor((o.rest_s + 60.0 * plan.minutes) * o.frame_rate_hz));
  const auto rest_frames = std::max<std::size_t>(1, static_cast<std::size_t>(std::floor(o.rest_s * o.frame_rate_hz)));

  std::vector<float> cells_pf;  // frames x C
  std::vector<float> vertices;  // frames x V x 3
  std::vector<float> pose;
  std::vector<sa::MocapFrame> mocap_frames;
  cells_pf.reserve(frames * C);
  vertices.reserve(frames * V * 3);
  sa::CellFrame cell_frame = readout->make_frame();
  std::vector<double> rows;
  const sas::StateProvider provider = [&timeline](double t) { return timeline.state_at(t); };
  for (std::size_t k = 0; k < frames; ++k) {
    const double t0 = static_cast<double>(k) * frame_s, t_end = t0 + frame_s;
    auto measured = board->measure_frame(t0, provider);
    if (!measured) return measured.error().with_context(fmt::format("frame {}", k));
    rows.resize(measured->rows_pf.size());
    for (std::size_t r = 0; r < rows.size(); ++r) {
      // What the wire carries (1 fF, the board's full scale), then the host's subtraction.
      const auto wire = devices::quantise_capacitance(static_cast<std::uint16_t>(r), measured->rows_pf[r]);
      rows[r] = wire.status == devices::StretchMeasurementStatus::ok
                    ? devices::stretch_count_to_pf(wire.value) - calibration->parasitic_pf[r]
                    : std::nan("");
    }
    if (auto st = readout->solve(rows, static_cast<TimeNs>(t_end * 1e9), cell_frame); !st) return st.error();
    cells_pf.insert(cells_pf.end(), cell_frame.cells_pf.begin(), cell_frame.cells_pf.end());

    auto x = timeline.vertices_at(t_end);
    if (!x) return x.error();
    std::vector<Eigen::Vector3d> truth(V);
    for (std::size_t v = 0; v < V; ++v) {
      truth[v] = es::material_point_position_m(sh.sheet_mesh, *x, sh.recon_points[v]);
      vertices.insert(vertices.end(), {static_cast<float>(truth[v].x()), static_cast<float>(truth[v].y()),
                                       static_cast<float>(truth[v].z())});
    }
    std::vector<Eigen::Vector3d> marker_truth(M);
    for (std::size_t m = 0; m < M; ++m) marker_truth[m] = truth[sh.marker_vertices[m]];
    auto observed = mocap->step(t_end, marker_truth);
    if (!observed) return observed.error();
    mocap_frames.push_back(std::move(*observed));
    pose.push_back(static_cast<float>(body->pose_value(body_time(t_end))));
    minutes_done.fetch_add(frame_s / 60.0);
  }

  // The user's three clicks: markers spread over the sheet, visible in frame 0.
  const auto& seen0 = mocap->truth().marker_of_observation.at(0);
  std::vector<sar::InitialMatch> initial;
  for (std::size_t want : {std::size_t{0}, M / 2, M - 1, M / 4, 3 * M / 4, std::size_t{1}}) {
    if (initial.size() == 3) break;
    for (std::size_t i = 0; i < seen0.size(); ++i) {
      const bool taken = std::any_of(initial.begin(), initial.end(), [&](const auto& m) { return m.marker == want; });
      if (!taken && seen0[i] == static_cast<std::int32_t>(want)) {
        initial.push_back({mocap_frames[0].observations[i].label, want});
      }
    }
  }
  if (initial.size() < 3) return make_error(Errc::unavailable, plan.name + ": fewer than three markers visible at the start");
  const Eigen::MatrixX3d rest = sar::rest_shape(sh.recon, body->rest_radius_m());
  auto labelled = sar::label_markers(rest, sh.recon.triangles, sh.marker_vertices, mocap_frames, initial);
  if (!labelled) return labelled.error().with_context(plan.name + ": labelling the markers");

  // C0: the read-out's mean over the rest frames, per cell.
  std::vector<double> c0(C, 0.0);
  for (std::size_t k = 0; k < rest_frames && k < frames; ++k) {
    for (std::size_t c = 0; c < C; ++c) c0[c] += cells_pf[k * C + c] / static_cast<double>(rest_frames);
  }
  for (std::size_t c = 0; c < C; ++c) {
    if (!(c0[c] > 0.0)) {
      return make_error(Errc::unavailable, fmt::format("{}: cell {} reads {} pF at rest; it cannot be normalised",
                                                         plan.name, sh.layout.cells[c].name, c0[c]));
    }
  }

  SessionResult out;
  auto& d = out.data;
  d.name = plan.name;
  d.motion = o.motion;
  d.donning = plan.donning;
  d.split = plan.split;
  for (std::size_t k = 0; k < frames; ++k) {
    if (!labelled->complete[k]) {
      ++d.frames_dropped;
      continue;
    }
    for (std::size_t c = 0; c < C; ++c) d.cells.push_back(static_cast<float>(cells_pf[k * C + c] / c0[c]));
    const auto& lm = labelled->markers_m[k];
    for (std::size_t m = 0; m < M; ++m) {
      for (int a = 0; a < 3; ++a) d.markers.push_back(static_cast<float>(lm(static_cast<Eigen::Index>(m), a)));
      for (int a = 0; a < 3; ++a) d.markers_truth.push_back(vertices[(k * V + sh.marker_vertices[m]) * 3 + a]);
    }
    d.vertices_truth.insert(d.vertices_truth.end(), vertices.begin() + static_cast<std::ptrdiff_t>(k * V * 3),
                            vertices.begin() + static_cast<std::ptrdiff_t>((k + 1) * V * 3));
    d.pose.push_back(pose[k]);
  }
  auto& r = out.report;
  // Which markers the labelling most often left without a track: what to
  // look at when many frames are dropped.
  std::vector<std::size_t> missing(M, 0);
  for (std::size_t k = 0; k < frames; ++k) {
    for (std::size_t m = 0; m < M; ++m) missing[m] += std::isnan(labelled->markers_m[k](static_cast<Eigen::Index>(m), 0));
  }
  std::vector<std::size_t> order(M);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](auto a, auto b) { return missing[a] > missing[b]; });
  for (std::size_t i = 0; i < std::min<std::size_t>(3, M) && missing[order[i]] > 0; ++i) {
    r.most_missing += fmt::format("{}m{} {:.0f} %", i ? ", " : "", order[i],
                                  100.0 * static_cast<double>(missing[order[i]]) / static_cast<double>(frames));
  }
  r.name = plan.name;
  r.frames = d.frames();
  r.frames_dropped = d.frames_dropped;
  r.labels_seen = labelled->labels_seen;
  r.labels_outlier = labelled->labels_outlier;
  r.max_area_stretch = std::sqrt(timeline.max_cell_ratio());
  r.damaged_cells = static_cast<std::size_t>(std::count_if(board->damaged_cells().begin(), board->damaged_cells().end(),
                                                           [](auto v) { return v != 0; }));
  r.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  return out;
}

}  // namespace

Result<sa::StripArrayLayout> layout_for_motion(const std::string& layout_file, const std::string& motion) {
  sa::StripArrayLayout layout;
  if (layout_file.empty()) {
    layout = motion == "biceps" ? sa::StripArrayLayout::biceps_144() : sa::StripArrayLayout::prototype_92();
  } else {
    auto loaded = sa::StripArrayLayout::load(layout_file);
    if (!loaded) return loaded.error();
    layout = std::move(*loaded);
  }
  if (auto st = sa::require_readable(layout); !st) return st.error();
  return layout;
}

Status SimArrayOptions::validate() const {
  if (auto body = es::parse_body_kind(motion); !body) return body.error();
  if (train_sessions < 0 || test_sessions < 0 || train_sessions + test_sessions + (redonned_test ? 1 : 0) == 0) {
    return make_error(Errc::invalid_argument, "sim-array needs at least one session");
  }
  if (!(train_minutes > 0.0) || !(test_minutes > 0.0) || !(frame_rate_hz > 0.0) || !(rest_s > 0.0) ||
      !std::isfinite(train_minutes + test_minutes + frame_rate_hz + rest_s)) {
    return make_error(Errc::invalid_argument, "minutes, frame rate and rest time must be positive and finite");
  }
  if (mechanics_steps_per_frame < 1 || mechanics_steps_per_frame > 64) {
    return make_error(Errc::invalid_argument, "mechanics steps per frame must be 1-64");
  }
  if (!(occluded_share >= 0.0 && occluded_share < 0.5) || !(mean_occlusion_s > 0.0 && mean_occlusion_s < 60.0)) {
    return make_error(Errc::invalid_argument, "the occluded share must be in [0, 0.5) and occlusions last (0, 60) s");
  }
  if (out.empty()) return make_error(Errc::invalid_argument, "no output folder (--out)");
  if (auto st = board.validate(); !st) return st;
  return mocap.validate();
}

double SimArrayOptions::total_simulated_minutes() const {
  const double rest_min = rest_s / 60.0;
  return train_sessions * (train_minutes + rest_min) + test_sessions * (test_minutes + rest_min) +
         (redonned_test ? test_minutes + rest_min : 0.0);
}

std::string SimArrayOptions::describe() const {
  return fmt::format("sim-array: {} on {}, {} training session(s) of {} min, {} test session(s) of {} min{}, "
                     "{} Hz, {} mechanics steps per frame, {} s at rest first, seed {}\n{}\nmocap at the frame rate, "
                     "each marker out of sight {:.1f} % of the time for {} s on average; {}",
                     motion, layout_file.empty() ? "the default layout" : layout_file, train_sessions, train_minutes,
                     test_sessions, test_minutes, redonned_test ? " plus one re-donned" : "", frame_rate_hz,
                     mechanics_steps_per_frame, rest_s, seed, board.describe(), 100 * occluded_share, mean_occlusion_s,
                     frame_rate_mocap(*this).describe());
}

std::string SimArrayReport::describe() const {
  std::string s = fmt::format("{} frames kept, {} dropped by the labelling, {} sessions in {:.1f} s on {} threads",
                              frames, frames_dropped, sessions.size(), elapsed_s, threads);
  for (const auto& r : sessions) {
    s += fmt::format("\n  {}: {} frames ({} dropped), {} mocap labels ({} outliers), largest cell area stretch {:.2f}, "
                     "{} over-stretched cells, {:.1f} s{}{}",
                     r.name, r.frames, r.frames_dropped, r.labels_seen, r.labels_outlier, r.max_area_stretch,
                     r.damaged_cells, r.elapsed_s, r.most_missing.empty() ? "" : "; markers most often unlabelled: ",
                     r.most_missing);
  }
  return s;
}

Result<SimArrayReport> write_sim_array_dataset(const SimArrayOptions& options, const SimArrayCallbacks& callbacks) {
  if (auto st = options.validate(); !st) return st.error();
  SimArrayOptions o = options;
  const auto start = std::chrono::steady_clock::now();
  auto shared = build_shared(o);
  if (!shared) return shared.error();
  o.board.timing.row_rate_hz = o.frame_rate_hz * static_cast<double>(shared->layout.measurement_plan(true).size());
  logger().info("{}", o.describe());

  std::vector<SessionPlan> plans;
  for (int i = 0; i < o.train_sessions; ++i) {
    plans.push_back({fmt::format("{}-train-{}", o.motion, i), "train", 0, o.train_minutes, mix(o.seed, 100 + i)});
  }
  for (int i = 0; i < o.test_sessions; ++i) {
    plans.push_back({fmt::format("{}-test-{}", o.motion, i), "test", 0, o.test_minutes, mix(o.seed, 200 + i)});
  }
  if (o.redonned_test) plans.push_back({o.motion + "-test-redonned", "test", 1, o.test_minutes, mix(o.seed, 300)});

  ArrayDatasetShape shape;
  shape.layout = shared->layout.name;
  for (const auto& c : shared->layout.cells) shape.cell_names.push_back(c.name);
  for (std::size_t m = 0; m < shared->marker_vertices.size(); ++m) {
    const int cell = shared->recon.cell_of_vertex[shared->marker_vertices[m]];
    shape.marker_names.push_back(fmt::format("m{}-{}", m, cell >= 0 ? shared->layout.cells[static_cast<std::size_t>(cell)].name : "?"));
  }
  shape.mesh_vertex_count = shared->recon.vertex_count();
  shape.frame_rate_hz = o.frame_rate_hz;
  {
    const auto body = es::make_body(shared->body, 1);
    shape.pose_name = body->pose_name();
    shape.rest_radius_m = body->rest_radius_m();
  }
  auto writer = ArrayDatasetWriter::create(o.out, shape, o.force);
  if (!writer) return writer.error();

  const std::size_t threads = std::min<std::size_t>(
      plans.size(), o.threads > 0 ? static_cast<std::size_t>(o.threads) : std::max(1u, std::thread::hardware_concurrency()));
  std::vector<std::optional<Result<SessionResult>>> results(plans.size());
  std::atomic<std::size_t> next{0};
  std::atomic<double> minutes_done{0.0};
  std::atomic<std::size_t> finished{0};
  std::vector<std::thread> pool;
  for (std::size_t w = 0; w < threads; ++w) {
    pool.emplace_back([&] {
      for (std::size_t i = next++; i < plans.size(); i = next++) {
        results[i] = simulate_session(o, *shared, plans[i], minutes_done);
        ++finished;
      }
    });
  }
  while (finished.load() < plans.size()) {
    if (callbacks.on_progress) callbacks.on_progress(minutes_done.load());
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  for (auto& t : pool) t.join();
  if (callbacks.on_progress) callbacks.on_progress(minutes_done.load());

  SimArrayReport report;
  report.threads = threads;
  for (std::size_t i = 0; i < plans.size(); ++i) {
    if (!*results[i]) return results[i]->error().with_context("session " + plans[i].name);
    SessionResult& s = results[i]->value();
    if (auto st = writer->add_session(s.data); !st) return st.error();
    report.frames += s.report.frames;
    report.frames_dropped += s.report.frames_dropped;
    report.sessions.push_back(s.report);
  }
  nlohmann::ordered_json gen;
  gen["tool"] = o.tool;
  gen["version"] = o.version;
  gen["seed"] = o.seed;
  gen["motion"] = o.motion;
  gen["layout"] = o.layout_file.empty() ? shared->layout.name : o.layout_file;
  gen["frame_rate_hz"] = o.frame_rate_hz;
  gen["board"] = o.board.describe();
  gen["mocap"] = o.mocap.describe();
  gen["note"] = "simulated: body proxy, elastic sheet, board and mocap models (docs/stretch-arrays.md); "
                "simulated accuracy is not real-world accuracy";
  if (auto st = writer->finish(gen.dump()); !st) return st.error();
  report.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace proprio::stretch_array_eval
