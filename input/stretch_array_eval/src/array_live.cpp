#include "proprio/stretch_array_eval/array_live.hpp"
#include "proprio/stretch_array_eval/sim_array.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>

#include <fmt/format.h>

#include "proprio/elastic_sheet/elastic_sheet.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"
#include "proprio/hid/link_state.hpp"
#include "proprio/stretch_array_recon/array_reconstructor.hpp"
#include "proprio/stretch_array_recon/marker_regressor.hpp"
#include "proprio/stretch_array_recon/recon_mesh.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"
#include "proprio/stretch_board/stretch_array_reader.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "sheet_timeline.hpp"

namespace proprio::stretch_array_eval {

namespace es = elastic_sheet;
namespace sa = stretch_array;
namespace sas = stretch_array_sim;
namespace sar = stretch_array_recon;
namespace dev = devices;
namespace fs = std::filesystem;

Status ArrayLiveOptions::validate() const {
  if (auto body = es::parse_body_kind(motion); !body) return body.error();
  if (model.empty()) {
    return make_error(Errc::invalid_argument, "no regressor (--model): give an .onnx file or the folder `proprio "
                                              "train array` wrote");
  }
  if (!(frame_rate_hz > 0.0 && frame_rate_hz <= 100.0)) {
    return make_error(Errc::invalid_argument, "the frame rate must be in (0, 100] full plans per second");
  }
  if (mechanics_steps_per_frame < 1 || mechanics_steps_per_frame > 64) {
    return make_error(Errc::invalid_argument, "mechanics steps per frame must be 1-64");
  }
  if (!(rest_s > 0.0 && rest_s < 60.0)) return make_error(Errc::invalid_argument, "the rest time must be in (0, 60) s");
  if (truth_samples_per_frame < 1 || truth_samples_per_frame > 64) {
    return make_error(Errc::invalid_argument, "truth samples per frame must be 1-64");
  }
  if (cable_latency_min_ns < 0 || cable_latency_jitter_ns < 0 || read_timeout_ns <= 0 ||
      reconnect_backoff_min_ns <= 0 || reconnect_backoff_max_ns < reconnect_backoff_min_ns) {
    return make_error(Errc::invalid_argument, "cable latencies must be >= 0, the read timeout and backoffs positive "
                                              "(max >= min)");
  }
  if (arap_iterations < 1 || arap_iterations > 100) return make_error(Errc::invalid_argument, "ARAP iterations must be 1-100");
  for (const auto& u : unplugs) {
    if (u.at_ns < 0 || u.duration_ns <= 0) {
      return make_error(Errc::invalid_argument, "an unplug needs a time >= 0 and a positive duration");
    }
  }
  return board.validate();
}

std::string ArrayLiveOptions::describe() const {
  return fmt::format("live array: {} on {}, model {}, {} Hz plans, {} mechanics steps per frame, {} s at rest for C0, "
                     "seed {}, cable latency {:.2f}-{:.2f} ms{}, {} ARAP iterations on the {} rest sheet",
                     motion, layout_file.empty() ? "the default layout" : layout_file, model.string(), frame_rate_hz,
                     mechanics_steps_per_frame, rest_s, seed, cable_latency_min_ns * 1e-6,
                     (cable_latency_min_ns + cable_latency_jitter_ns) * 1e-6,
                     unplugs.empty() ? "" : fmt::format(", {} unplug(s)", unplugs.size()), arap_iterations,
                     wrapped_rest_shape ? "wrapped" : "flat");
}

Result<fs::path> resolve_array_model(const fs::path& model) {
  std::error_code ec;
  if (fs::is_regular_file(model, ec)) return model;
  if (fs::is_directory(model, ec)) {
    for (const fs::path& p : {model / "model.onnx", model / "dnn" / "model.onnx"}) {
      if (fs::is_regular_file(p, ec)) return p;
    }
    return make_error(Errc::not_found, fmt::format("{} holds neither model.onnx nor dnn/model.onnx; train one with "
                                                   "`proprio train array DATASET --out {}`",
                                                   model.string(), model.string()));
  }
  return make_error(Errc::not_found, fmt::format("the regressor {} does not exist", model.string()));
}

std::string ArrayLiveStats::describe() const {
  return fmt::format("{} frames ({:.1f} /s), {} cell frames ({} superseded), latency mean {:.1f} ms max {:.1f} ms, "
                     "reconstruction mean {:.2f} ms max {:.2f} ms, simulated wearer + board {:.1f} ms per plan (max "
                     "{:.1f}, the board waited {} times), link {} ({} disconnects, {} board epochs){}{}",
                     frames, frame_rate_hz, cell_frames, superseded, 1e3 * latency_mean_s, 1e3 * latency_max_s,
                     reconstruct_mean_ms, reconstruct_max_ms, simulate_mean_ms, simulate_max_ms, board_waits, link,
                     disconnects, epochs,
                     calibrating ? ", calibrating" : "", last_error.empty() ? "" : "; last error: " + last_error);
}

namespace {

std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t salt) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (salt + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

}  // namespace

struct ArrayLiveTruth {
  TimeNs t_ns = 0;  // emulator time
  std::vector<Eigen::Vector3d> vertices_m;
};

// A board frame computed ahead: every row of one plan (pF, as sent).
struct ArrayLiveBoardFrame {
  double t0_s = 0.0;  // emulator time of row 0
  std::vector<double> rows_pf;  // empty: the simulation failed (rows read no signal)
};

// The wearer and the board. The mechanics and the board's physics of a whole
// plan cost tens of ms, so a wearer thread computes each board frame ahead
// of the emulator (the simulator's cost must not stall the emulated board
// and show up as link latency); the emulator thread's provider only serves
// the rows. The timeline and board belong to the wearer thread.
struct ArrayLiveWearer {
  std::shared_ptr<const es::BodyProxy> body;
  std::optional<es::ElasticSheet> sheet;
  std::optional<sas::ArraySheet> array;  // the timeline's; the board holds its own copy
  std::optional<sas::BoardSimulator> board;
  std::optional<SheetTimeline> timeline;
  double rest_s = 1.0;
  double row_period_s = 0.0;
  int truth_every_rows = 1;
  double plan_period_s = 0.0;
  // The frame being served (emulator thread).
  bool have_frame = false;
  ArrayLiveBoardFrame current;
  // Wearer thread <-> emulator thread.
  std::mutex mutex;
  std::condition_variable cv;
  std::deque<ArrayLiveBoardFrame> ahead;  // at most kAhead
  double next_t0_s = 0.0;                 // the next frame the wearer thread computes
  bool in_flight = false;
  double in_flight_t0_s = 0.0;
  std::uint64_t generation = 0;  // bumped when the emulator restarts the schedule
  bool stop = false;
  std::thread thread;
  static constexpr std::size_t kAhead = 2;
};

struct ArrayLiveSource::Impl {
  ArrayLiveOptions options;
  sa::StripArrayLayout layout;
  sa::SheetMesh sheet_mesh;
  std::vector<es::MaterialPoint> recon_points;
  std::size_t cells = 0, markers = 0, vertices = 0;

  std::unique_ptr<ArrayLiveWearer> wearer;
  std::optional<sar::ArrayReconstructor> reconstructor;  // the reconstruction thread's
  std::optional<dev::StretchArrayReader> reader;         // the reader thread's
  std::vector<dev::StretchSample> burst;                 // the reader thread's

  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<dev::StretchEmulatorServer> server;
  std::unique_ptr<dev::StretchDevice> device;
  bool started = false;
  TimeNs t0_host_ns = 0;

  // Truth, written by the emulator thread, read by the reconstruction thread.
  std::mutex truth_mutex;
  std::deque<ArrayLiveTruth> truth;

  // Reader thread -> reconstruction thread: the newest cell frame.
  std::mutex handoff_mutex;
  std::condition_variable handoff_cv;
  std::optional<sa::CellFrame> pending;
  bool stop_requested = false;
  std::thread recon_thread;

  // Published for latest().
  mutable std::mutex published_mutex;
  std::shared_ptr<const ArrayLiveFrame> frame;
  ArrayLiveStats stats;  // link state kept in `link_state`
  std::atomic<hid::LinkState> link_state{hid::LinkState::stopped};
  std::atomic<std::uint64_t> disconnects{0};

  // Reconstruction thread only.
  std::vector<double> c0_sum;
  std::size_t rest_count = 0;
  Eigen::VectorXd c0;
  std::deque<TimeNs> done_times;
  double latency_sum_s = 0.0, recon_sum_ms = 0.0;
  // Wearer thread only (read under published_mutex).
  std::uint64_t simulated_plans = 0;
  double simulate_sum_ms = 0.0;

  void note_error(std::string message) {
    std::lock_guard lock(published_mutex);
    stats.last_error = std::move(message);
  }

  // --- emulator thread -----------------------------------------------------
  double provide(std::size_t combination, TimeNs t_ns) {
    ArrayLiveWearer& w = *wearer;
    const double t = static_cast<double>(t_ns) * 1e-9;
    const double t0 = t - static_cast<double>(combination) * w.row_period_s;
    if (!w.have_frame || std::abs(t0 - w.current.t0_s) > 0.5 * w.row_period_s) fetch(t0);
    return w.have_frame && combination < w.current.rows_pf.size() ? w.current.rows_pf[combination]
                                                                   : std::numeric_limits<double>::quiet_NaN();
  }

  // The board frame whose row 0 is at t0 (emulator thread). Waits only when
  // the wearer thread has not got there: at the start, after the board
  // restarted (its plan runs on a new schedule) or when the machine is too
  // slow for real time.
  void fetch(double t0) {
    ArrayLiveWearer& w = *wearer;
    const double half = 0.5 * w.row_period_s;
    std::unique_lock lock(w.mutex);
    for (;;) {
      if (w.stop) {
        w.have_frame = false;
        return;
      }
      while (!w.ahead.empty() && w.ahead.front().t0_s < t0 - half) w.ahead.pop_front();
      if (!w.ahead.empty() && w.ahead.front().t0_s <= t0 + half) {
        w.current = std::move(w.ahead.front());
        w.ahead.pop_front();
        w.have_frame = true;
        w.cv.notify_all();
        return;
      }
      {
        std::lock_guard plock(published_mutex);
        ++stats.board_waits;
      }
      const bool coming = w.in_flight && std::abs(w.in_flight_t0_s - t0) <= half;
      if (!coming) {
        // Another schedule (or the wearer fell behind): start over from t0.
        ++w.generation;
        w.ahead.clear();
        w.next_t0_s = t0;
        w.cv.notify_all();
      }
      w.cv.wait(lock);
    }
  }

  void wearer_loop() {
    ArrayLiveWearer& w = *wearer;
    std::unique_lock lock(w.mutex);
    for (;;) {
      w.cv.wait(lock, [&] { return w.stop || w.ahead.size() < ArrayLiveWearer::kAhead; });
      if (w.stop) return;
      const double t0 = w.next_t0_s;
      const std::uint64_t generation = w.generation;
      w.next_t0_s += w.plan_period_s;
      w.in_flight = true;
      w.in_flight_t0_s = t0;
      lock.unlock();
      ArrayLiveBoardFrame board_frame;
      board_frame.t0_s = t0;
      const auto start = std::chrono::steady_clock::now();
      if (auto st = measure(t0, board_frame.rows_pf); !st) {
        note_error(st.error().message);
        board_frame.rows_pf.clear();
      }
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      {
        std::lock_guard plock(published_mutex);
        ++simulated_plans;
        simulate_sum_ms += ms;
        stats.simulate_mean_ms = simulate_sum_ms / static_cast<double>(simulated_plans);
        stats.simulate_max_ms = std::max(stats.simulate_max_ms, ms);
      }
      lock.lock();
      w.in_flight = false;
      if (generation == w.generation) w.ahead.push_back(std::move(board_frame));
      w.cv.notify_all();
    }
  }

  Status measure(double t0_s, std::vector<double>& rows_pf) {
    ArrayLiveWearer& w = *wearer;
    std::size_t row = 0;
    const sas::StateProvider at = [&](double t_s) -> Result<sas::SheetState> {
      auto state = w.timeline->state_at(t_s);
      if (state && row % static_cast<std::size_t>(w.truth_every_rows) == 0) record_truth(t_s);
      ++row;
      return state;
    };
    auto measured = w.board->measure_frame(t0_s, at);
    if (!measured) return measured.error().with_context(fmt::format("the simulated board at t = {:.3f} s", t0_s));
    // The board subtracts its own open-pads reading before it sends (the
    // thesis's way); the host's calibration takes the rest of each row.
    rows_pf.resize(measured->rows_pf.size());
    for (std::size_t r = 0; r < rows_pf.size(); ++r) rows_pf[r] = measured->rows_pf[r] - measured->open_pads_pf;
    return {};
  }

  void record_truth(double t_s) {
    auto x = wearer->timeline->vertices_at(t_s);
    if (!x) return;
    ArrayLiveTruth s;
    s.t_ns = static_cast<TimeNs>(std::llround(t_s * 1e9));
    s.vertices_m.resize(vertices);
    for (std::size_t v = 0; v < vertices; ++v) {
      s.vertices_m[v] = es::material_point_position_m(sheet_mesh, *x, recon_points[v]);
    }
    std::lock_guard lock(truth_mutex);
    if (!truth.empty() && truth.back().t_ns >= s.t_ns) return;
    truth.push_back(std::move(s));
    while (truth.size() > 512) truth.pop_front();
  }

  // --- reader thread ---------------------------------------------------------
  void on_burst() {
    if (burst.empty()) return;
    sa::CellFrame out = reader->make_frame();
    const bool solved = reader->add(burst, out);
    const std::uint64_t n = burst.size();
    burst.clear();
    {
      std::lock_guard lock(published_mutex);
      stats.samples += n;
      stats.epochs = reader->stats().epochs;
      if (solved) ++stats.cell_frames;
    }
    if (!solved) return;
    {
      std::lock_guard lock(handoff_mutex);
      if (pending) {
        std::lock_guard plock(published_mutex);
        ++stats.superseded;
      }
      pending = std::move(out);
    }
    handoff_cv.notify_one();
  }

  // --- reconstruction thread -------------------------------------------------
  void recon_loop() {
    for (;;) {
      sa::CellFrame f;
      {
        std::unique_lock lock(handoff_mutex);
        handoff_cv.wait_for(lock, std::chrono::milliseconds(50), [this] { return stop_requested || pending; });
        if (stop_requested) return;
        if (!pending) continue;
        f = std::move(*pending);
        pending.reset();
      }
      process(f);
    }
  }

  bool calibrating() {
    std::lock_guard lock(published_mutex);
    return stats.calibrating;
  }

  void process(const sa::CellFrame& f) {
    if (!f.all_valid()) return;  // before a full cycle, or rows out after a fault: nothing to normalise
    if (calibrating()) {
      const bool at_rest = f.time_ns - t0_host_ns <= static_cast<TimeNs>(options.rest_s * 1e9);
      if (at_rest || rest_count == 0) {
        for (std::size_t c = 0; c < cells; ++c) c0_sum[c] += f.cells_pf[c];
        ++rest_count;
        std::lock_guard lock(published_mutex);
        stats.rest_frames = rest_count;
      }
      if (at_rest) return;
      c0.resize(static_cast<Eigen::Index>(cells));
      for (std::size_t c = 0; c < cells; ++c) {
        c0[static_cast<Eigen::Index>(c)] = c0_sum[c] / static_cast<double>(rest_count);
        if (!(c0[static_cast<Eigen::Index>(c)] > 0.0)) {
          note_error(fmt::format("cell {} reads {} pF at rest; it cannot be normalised (C0 taken again)",
                                 layout.cells[c].name, c0[static_cast<Eigen::Index>(c)]));
          std::fill(c0_sum.begin(), c0_sum.end(), 0.0);
          rest_count = 0;
          return;
        }
      }
      // The rest frames read C/C0 = 1: the regressor's rest markers place S^0.
      if (auto st = reconstructor->align_session_from_cells(Eigen::VectorXd::Ones(static_cast<Eigen::Index>(cells)));
          !st) {
        note_error(st.error().message);
      }
      std::lock_guard lock(published_mutex);
      stats.calibrating = false;
    }
    Eigen::VectorXd ratio(static_cast<Eigen::Index>(cells));
    for (std::size_t c = 0; c < cells; ++c) {
      ratio[static_cast<Eigen::Index>(c)] = f.cells_pf[c] / c0[static_cast<Eigen::Index>(c)];
    }
    sar::ReconstructedFrame r;
    const auto start = std::chrono::steady_clock::now();
    if (auto st = reconstructor->reconstruct(ratio, r); !st) {
      std::lock_guard lock(published_mutex);
      ++stats.failed;
      stats.last_error = st.error().message;
      return;
    }
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    auto out = std::make_shared<ArrayLiveFrame>();
    out->measured_ns = f.time_ns;
    out->reconstruct_ms = ms;
    out->regressor_ms = 1e3 * r.regressor_s;
    out->arap_ms = 1e3 * r.arap_s;
    out->vertices_m.resize(vertices);
    for (std::size_t v = 0; v < vertices; ++v) out->vertices_m[v] = r.vertices_m.row(static_cast<Eigen::Index>(v)).transpose();
    out->truth_m = truth_at(f.time_ns - t0_host_ns);
    out->mean_error_m = std::numeric_limits<double>::quiet_NaN();
    if (out->truth_m.size() == vertices) {
      double sum = 0.0;
      for (std::size_t v = 0; v < vertices; ++v) sum += (out->vertices_m[v] - out->truth_m[v]).norm();
      out->mean_error_m = sum / static_cast<double>(vertices);
    }
    out->done_ns = MonotonicClock::instance().now_ns();
    out->latency_s = static_cast<double>(out->done_ns - out->measured_ns) * 1e-9;
    done_times.push_back(out->done_ns);
    while (!done_times.empty() && done_times.front() < out->done_ns - kNsPerSecond) done_times.pop_front();
    std::lock_guard lock(published_mutex);
    out->index = stats.frames;
    ++stats.frames;
    latency_sum_s += out->latency_s;
    recon_sum_ms += ms;
    stats.latency_mean_s = latency_sum_s / static_cast<double>(stats.frames);
    stats.latency_max_s = std::max(stats.latency_max_s, out->latency_s);
    stats.reconstruct_mean_ms = recon_sum_ms / static_cast<double>(stats.frames);
    stats.reconstruct_max_ms = std::max(stats.reconstruct_max_ms, ms);
    stats.frame_rate_hz = static_cast<double>(done_times.size());
    frame = std::move(out);
  }

  // The true vertices at emulator time t, interpolated between the samples
  // around it (empty when none is near: the wearer has not got there yet).
  std::vector<Eigen::Vector3d> truth_at(TimeNs t_ns) {
    std::lock_guard lock(truth_mutex);
    if (truth.empty()) return {};
    auto after = std::lower_bound(truth.begin(), truth.end(), t_ns,
                                  [](const ArrayLiveTruth& s, TimeNs t) { return s.t_ns < t; });
    if (after == truth.begin()) return after->vertices_m;
    if (after == truth.end()) return truth.back().vertices_m;
    const ArrayLiveTruth& a = *(after - 1);
    const ArrayLiveTruth& b = *after;
    const double w = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
    std::vector<Eigen::Vector3d> v(a.vertices_m.size());
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = a.vertices_m[i] + w * (b.vertices_m[i] - a.vertices_m[i]);
    return v;
  }

  void stop_all() {
    if (device) device->stop();
    {
      std::lock_guard lock(handoff_mutex);
      stop_requested = true;
    }
    handoff_cv.notify_all();
    if (recon_thread.joinable()) recon_thread.join();
    // The emulator thread may be waiting for the wearer: release it first.
    if (wearer) {
      {
        std::lock_guard lock(wearer->mutex);
        wearer->stop = true;
      }
      wearer->cv.notify_all();
    }
    if (server) server->stop();
    if (wearer && wearer->thread.joinable()) wearer->thread.join();
    link_state.store(hid::LinkState::stopped);
  }
};

namespace {

using LiveImpl = ArrayLiveSource::Impl;

// The layout (the file, or the motion's shipped one), the reconstruction mesh
// and markers, and the reconstructor with the regressor checked against them.
Result<sar::ReconMesh> setup_reconstruction(LiveImpl& s, const ArrayLiveOptions& options, es::BodyKind body_kind) {
  auto layout = layout_for_motion(options.layout_file, es::to_string(body_kind));
  if (!layout) return layout.error();
  s.layout = std::move(*layout);
  auto recon_mesh = sar::build_recon_mesh(s.layout);
  if (!recon_mesh) return recon_mesh.error().with_context("the reconstruction mesh");
  auto marker_vertices = sar::select_marker_vertices(*recon_mesh);
  if (!marker_vertices) return marker_vertices.error();
  s.cells = s.layout.cell_count();
  s.markers = marker_vertices->size();
  s.vertices = recon_mesh->vertex_count();
  auto model_file = resolve_array_model(options.model);
  if (!model_file) return model_file.error();
  auto regressor = sar::MarkerRegressor::load(*model_file, s.cells, s.markers);
  if (!regressor) {
    return regressor.error().with_context(fmt::format("the regressor for {} ({} cells, {} markers)", s.layout.name,
                                                      s.cells, s.markers));
  }
  sar::ArrayReconstructorOptions recon_options;
  recon_options.arap.max_iterations = options.arap_iterations;
  if (options.wrapped_rest_shape) {
    // The body's nominal size, as sim-array writes it into a dataset (rest_radius_m) and bench array uses it.
    recon_options.rest_cylinder_radius_m = es::make_body(body_kind, 1)->rest_radius_m();
  }
  auto reconstructor = sar::ArrayReconstructor::create(*recon_mesh, std::move(*marker_vertices), std::move(*regressor),
                                                       recon_options);
  if (!reconstructor) return reconstructor.error();
  s.reconstructor.emplace(std::move(*reconstructor));
  s.c0_sum.assign(s.cells, 0.0);
  return std::move(*recon_mesh);
}

// The host side over any transport: the reader with the rows' parasitics,
// the driver, and the callbacks that feed the reconstruction thread.
Status attach_host(LiveImpl& s, const ArrayLiveOptions& options, std::unique_ptr<hid::HidTransport> transport,
                   std::vector<double> row_parasitic_pf) {
  dev::StretchArrayReaderOptions reader_options;
  reader_options.row_parasitic_pf = std::move(row_parasitic_pf);
  auto reader = dev::StretchArrayReader::create(s.layout, reader_options);
  if (!reader) return reader.error();
  s.reader.emplace(std::move(*reader));
  dev::StretchDeviceOptions device_options;
  device_options.read_timeout_ns = options.read_timeout_ns;
  device_options.reconnect_backoff_min_ns = options.reconnect_backoff_min_ns;
  device_options.reconnect_backoff_max_ns = options.reconnect_backoff_max_ns;
  device_options.stream = s.reader->stream_options();
  s.device = std::make_unique<dev::StretchDevice>(std::move(transport), device_options);
  s.burst.reserve(dev::kStretchMaxBurst * dev::kStretchMeasurementsPerReport);
  LiveImpl* ip = &s;
  s.device->set_sample_callback([ip](const dev::StretchSample& sample) { ip->burst.push_back(sample); });
  s.device->set_burst_callback([ip] { ip->on_burst(); });
  s.device->set_state_callback([ip](hid::LinkState state, std::string_view) {
    const hid::LinkState before = ip->link_state.exchange(state);
    if (before == hid::LinkState::streaming && state == hid::LinkState::disconnected) ++ip->disconnects;
  });
  return {};
}

}  // namespace

Result<std::unique_ptr<ArrayLiveSource>> ArrayLiveSource::create_usb(const ArrayLiveOptions& options,
                                                                    std::vector<double> row_parasitic_pf,
                                                                    const std::string& hid_path) {
  if (auto st = options.validate(); !st) return st.error();
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  auto body_kind = es::parse_body_kind(options.motion);
  if (!body_kind) return body_kind.error();
  auto mesh = setup_reconstruction(*impl, options, *body_kind);
  if (!mesh) return mesh.error();
  hid::HidDeviceSelector selector = dev::stretch_board_selector();
  selector.path = hid_path;
  if (auto st = attach_host(*impl, options, std::make_unique<hid::HidapiTransport>(selector), std::move(row_parasitic_pf));
      !st) {
    return st.error();
  }
  return std::unique_ptr<ArrayLiveSource>(new ArrayLiveSource(std::move(impl)));
}

Result<std::unique_ptr<ArrayLiveSource>> ArrayLiveSource::create_simulated(const ArrayLiveOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  Impl& s = *impl;
  auto body_kind = es::parse_body_kind(options.motion);
  if (!body_kind) return body_kind.error();
  auto recon_mesh = setup_reconstruction(s, options, *body_kind);
  if (!recon_mesh) return recon_mesh.error();
  auto sheet_mesh = sa::build_sheet_mesh(s.layout);
  if (!sheet_mesh) return sheet_mesh.error().with_context("the simulated sheet");
  s.sheet_mesh = std::move(*sheet_mesh);

  // Reconstruction-mesh vertices as material points of the simulated sheet
  // (as sim-array's truth): a boundary vertex is looked up a micrometre inward.
  Eigen::Vector2d lo = recon_mesh->sheet_xy_m[0], hi = lo;
  for (const auto& p : recon_mesh->sheet_xy_m) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Eigen::Vector2d mid = 0.5 * (lo + hi);
  for (const auto& p : recon_mesh->sheet_xy_m) {
    const Eigen::Vector2d d = mid - p;
    const Eigen::Vector2d q = d.norm() > 0 ? Eigen::Vector2d(p + 1e-6 * d.normalized()) : p;
    auto point = es::locate_material_point(s.sheet_mesh, q);
    if (!point) return point.error().with_context("a reconstruction vertex outside the simulated sheet");
    s.recon_points.push_back(*point);
  }

  // The board's rate: one plan per frame.
  auto plan = dev::stretch_array_plan(s.layout);
  if (!plan) return plan.error();
  const double rate = std::round(options.frame_rate_hz * static_cast<double>(plan->rows()));
  if (rate < 1.0 || rate > 65535.0) {
    return make_error(Errc::invalid_argument, fmt::format("{} plans per second of {} rows is {} measurements per "
                                                          "second; the board's rate field holds 1-65535",
                                                          options.frame_rate_hz, plan->rows(), rate));
  }

  // The wearer: body, sheet donned on it, the board that reads it.
  s.wearer = std::make_unique<ArrayLiveWearer>();
  ArrayLiveWearer& w = *s.wearer;
  w.rest_s = options.rest_s;
  w.row_period_s = 1.0 / rate;
  w.plan_period_s = static_cast<double>(plan->rows()) / rate;
  w.truth_every_rows = std::max(1, static_cast<int>(plan->rows()) / options.truth_samples_per_frame);
  w.body = es::make_body(*body_kind, mix_seed(options.seed, 1));
  auto sheet = es::ElasticSheet::create(s.sheet_mesh, w.body, es::ElasticSheetOptions::from_layout(s.layout));
  if (!sheet) return sheet.error().with_context("donning the sheet");
  w.sheet.emplace(std::move(*sheet));
  auto array = sas::ArraySheet::create(s.layout, s.sheet_mesh);
  if (!array) return array.error();
  w.array.emplace(std::move(*array));
  sas::BoardOptions board_options = options.board;
  board_options.seed = mix_seed(options.seed, 3);
  board_options.timing.row_rate_hz = rate;
  auto board = sas::BoardSimulator::create(*w.array, board_options);
  if (!board) return board.error();
  w.board.emplace(std::move(*board));
  // The host's calibration: the sheet flat on the table before it is put on.
  auto calibration = w.board->calibrate_at_rest(0.0, 8);
  if (!calibration) return calibration.error().with_context("the rest calibration");
  w.board->set_donning(0);
  std::vector<double> row_parasitic_pf(calibration->parasitic_pf.size());
  for (std::size_t r = 0; r < row_parasitic_pf.size(); ++r) {
    row_parasitic_pf[r] = calibration->parasitic_pf[r] - calibration->open_pads_pf;
  }
  const double frame_s = 1.0 / options.frame_rate_hz;
  ArrayLiveWearer* wp = &w;
  w.timeline.emplace(
      [wp](double t_s) -> Result<std::vector<Eigen::Vector3d>> {
        auto step = wp->sheet->step(std::max(0.0, t_s - wp->rest_s));
        if (!step) return step.error().with_context(fmt::format("the sheet at t = {:.3f} s", t_s));
        return std::vector<Eigen::Vector3d>(wp->sheet->vertices_m().begin(), wp->sheet->vertices_m().end());
      },
      *w.array, frame_s / options.mechanics_steps_per_frame);
  if (auto st = w.timeline->start(); !st) return st.error();

  // The board's firmware, its provider the wearer.
  dev::StretchEmulatorOptions base;
  base.rate_hz = static_cast<std::uint16_t>(rate);
  base.parasitic_pf = calibration->open_pads_pf;
  base.seed = mix_seed(options.seed, 5);
  for (const auto& u : options.unplugs) base.faults.unplugs.push_back({u.at_ns, u.duration_ns});
  auto emulator_options = dev::stretch_array_emulator_options(s.layout, base);
  if (!emulator_options) return emulator_options.error();
  Impl* ip = impl.get();
  auto emulator = dev::StretchEmulator::create(
      *emulator_options, [ip](std::size_t combination, TimeNs t_ns) { return ip->provide(combination, t_ns); });
  if (!emulator) return emulator.error();
  s.link = std::make_shared<hid::FakeHidLink>(MonotonicClock::instance());
  dev::StretchServeOptions serve;
  serve.latency_min_ns = options.cable_latency_min_ns;
  serve.latency_jitter_ns = options.cable_latency_jitter_ns;
  serve.seed = mix_seed(options.seed, 6);
  s.server = std::make_unique<dev::StretchEmulatorServer>(std::move(*emulator), s.link, serve);

  if (auto st = attach_host(s, options, std::make_unique<hid::FakeHidTransport>(s.link), std::move(row_parasitic_pf));
      !st) {
    return st.error();
  }
  return std::unique_ptr<ArrayLiveSource>(new ArrayLiveSource(std::move(impl)));
}

ArrayLiveSource::ArrayLiveSource(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ArrayLiveSource::~ArrayLiveSource() { stop(); }

Status ArrayLiveSource::start() {
  Impl& s = *impl_;
  if (s.started) return make_error(Errc::invalid_argument, "the live array source is already started (or was stopped)");
  s.started = true;
  s.recon_thread = std::thread([&s] { s.recon_loop(); });
  if (s.server) {
    s.wearer->thread = std::thread([&s] { s.wearer_loop(); });
    s.server->start();
    s.t0_host_ns = s.server->time_zero_ns();
    // The cable comes out with the board's outages: the host sees the handle die.
    for (const auto& outage : s.options.unplugs) {
      s.link->schedule_unplug(s.t0_host_ns + outage.at_ns, outage.duration_ns);
    }
  } else {
    s.t0_host_ns = MonotonicClock::instance().now_ns();  // a real board: the rest starts now
  }
  if (auto st = s.device->start(); !st) {
    stop();
    return st;
  }
  return {};
}

void ArrayLiveSource::stop() {
  if (impl_) impl_->stop_all();
}

ArrayLiveSnapshot ArrayLiveSource::latest() const {
  ArrayLiveSnapshot out;
  {
    std::lock_guard lock(impl_->published_mutex);
    out.frame = impl_->frame;
    out.stats = impl_->stats;
  }
  out.stats.link = hid::to_string(impl_->link_state.load());
  out.stats.disconnects = impl_->disconnects.load();
  return out;
}

const sar::ReconMesh& ArrayLiveSource::mesh() const noexcept { return impl_->reconstructor->mesh(); }
std::size_t ArrayLiveSource::vertex_count() const noexcept { return impl_->vertices; }
std::size_t ArrayLiveSource::cell_count() const noexcept { return impl_->cells; }
std::size_t ArrayLiveSource::marker_count() const noexcept { return impl_->markers; }
TimeNs ArrayLiveSource::time_zero_ns() const { return impl_->t0_host_ns; }

}  // namespace proprio::stretch_array_eval
