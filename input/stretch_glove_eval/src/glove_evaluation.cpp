#include "proprio/stretch_glove_eval/glove_evaluation.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <limits>
#include <mutex>
#include <thread>

#include "proprio/core/random.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/sim/hand_truth_writer.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_glove/glove_board_source.hpp"
#include "proprio/stretch_glove/glove_hand_source.hpp"
#include "proprio/stretch_glove/onnx_pose_model.hpp"
#include "proprio/stretch_glove/readout.hpp"

namespace proprio::stretch_glove_eval {
namespace {

using WallClock = std::chrono::steady_clock;

double percentile(std::vector<float> v, double q) {
  if (v.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

std::string_view to_string(GloveRealismEffect e) noexcept {
  switch (e) {
    case GloveRealismEffect::noise: return "noise";
    case GloveRealismEffect::outliers: return "outliers";
    case GloveRealismEffect::drift: return "drift";
    case GloveRealismEffect::fabrication: return "fabrication";
    case GloveRealismEffect::donning: return "donning";
    case GloveRealismEffect::creep: return "creep";
    case GloveRealismEffect::wrist: return "wrist";
  }
  return "?";
}

std::optional<GloveRealismEffect> parse_glove_realism_effect(std::string_view s) noexcept {
  for (GloveRealismEffect e : kGloveRealismEffects) {
    if (to_string(e) == s) return e;
  }
  return std::nullopt;
}

void GloveSessionSpec::switch_off(GloveRealismEffect e) {
  switch (e) {
    case GloveRealismEffect::noise: simulator.enable_noise = false; break;
    case GloveRealismEffect::outliers: simulator.enable_outliers = false; break;
    case GloveRealismEffect::drift: simulator.enable_drift = false; break;
    case GloveRealismEffect::fabrication: simulator.enable_fabrication_spread = false; break;
    case GloveRealismEffect::donning: simulator.enable_donning_variation = false; break;
    case GloveRealismEffect::creep: simulator.enable_creep = false; break;
    case GloveRealismEffect::wrist: wrist_motion = false; break;
  }
}

std::string_view to_string(CalibrationMode m) noexcept {
  return m == CalibrationMode::session ? "session min-max" : "training-data min-max";
}

Result<GloveSessionResult> run_glove_session(const StretchGloveLayout& layout, const std::filesystem::path& model_path,
                                             const GloveSessionSpec& spec) {
  auto subject = sim::sim_subject(spec.subject);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();
  sim::StretchGloveSimOptions so = spec.simulator;
  so.glove_seed = spec.seed;  // the physical glove the shipped model was trained on (seed 1)
  so.seed = mix_seed(mix_seed(spec.seed, 7000 + static_cast<std::uint64_t>(spec.subject)),
                     static_cast<std::uint64_t>(spec.session));
  auto simulator = sim::StretchGloveSimulator::create(layout, *shape, so, 100 + spec.session);
  if (!simulator) return simulator.error();
  simulator->set_faults(spec.faults);
  sim::StretchSessionOptions sess;
  sess.exploration_s = spec.exploration_s;
  sess.task_s = spec.task_s;
  sess.task_motion.hand = subject->dominant_hand;
  sess.wrist_motion = spec.wrist_motion;
  sim::StretchGloveSession session(std::move(*simulator), sess);

  // Two models: the network as it is, and what an app sees (1€-filtered).
  auto model = stretch_glove::OnnxPoseModel::load(model_path, layout);
  if (!model) return model.error();
  auto model_filtered = stretch_glove::OnnxPoseModel::load(model_path, layout);
  if (!model_filtered) return model_filtered.error();
  auto readout = stretch_glove::make_readout(layout);
  if (!readout) return readout.error();
  auto calibrator = stretch_glove::MinMaxCalibrator::create(layout);
  if (!calibrator) return calibrator.error();

  GloveSessionResult res;
  res.spec = spec;
  stretch_glove::GloveTrackerOptions to;
  to.hand = subject->dominant_hand;
  to.hand_length_m = subject->hand_length_m;
  to.hand_width_m = subject->hand_width_m;
  std::optional<stretch_glove::GloveTracker> raw, filtered;
  auto start_tracking = [&]() -> Status {
    stretch_glove::MinMaxCalibration cal;
    if (spec.calibration == CalibrationMode::session) {
      res.calibration_coverage = calibrator->progress().overall;
      auto c = calibrator->finish("glove_eval exploration");
      if (!c) return c.error();
      cal = std::move(*c);
    } else {
      const auto& sc = model->sidecar();
      if (!sc || sc->global_min_pf.size() != layout.cell_count()) {
        return make_error(Errc::not_found, model_path.string() +
                                               ": the model's sidecar has no training-data min-max "
                                               "(global_min_pf/global_max_pf) for the uncalibrated scenario");
      }
      cal.layout_name = layout.name;
      cal.min_pf = sc->global_min_pf;
      cal.max_pf = sc->global_max_pf;
    }
    to.filter_output = false;
    auto r = stretch_glove::GloveTracker::create(layout, cal, std::move(*model), to);
    if (!r) return r.error();
    raw.emplace(std::move(*r));
    to.filter_output = true;
    auto f = stretch_glove::GloveTracker::create(layout, cal, std::move(*model_filtered), to);
    if (!f) return f.error();
    filtered.emplace(std::move(*f));
    return {};
  };

  stretch_glove::CellFrame frame = readout->make_frame();
  HandPose pose;
  sim::StretchSample s;
  std::array<double, kHandDofCount> dof_sum{};
  double filtered_sum = 0.0;
  std::optional<TimeNs> task_start;
  TimeNs task_end = 0;
  WallClock::duration pipeline{};
  while (session.next(s)) {
    const bool exploring = s.phase == sim::StretchPhase::exploration;
    const auto& m = s.measurement;
    const auto t0 = WallClock::now();
    const bool ready = readout->push(m.combination, m.capacitance_pf, m.time_ns, frame);
    if (exploring) {
      if (ready && frame.all_valid()) calibrator->add(frame);
      continue;
    }
    if (!raw) {
      if (auto st = start_tracking(); !st) return st.error();
      task_start = m.time_ns;
    }
    if (!ready) {
      pipeline += WallClock::now() - t0;
      continue;
    }
    raw->process(frame, pose);
    pipeline += WallClock::now() - t0;
    ++res.pipeline_frames;
    filtered->process(frame, pose);
    task_end = m.time_ns;
    // The first 2 s of the task are not scored: the 5-frame mean still holds exploration frames.
    if (m.time_ns - *task_start < 2 * kNsPerSecond) continue;
    ++res.frames;
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      const double e = rad_to_deg(std::abs(raw->angles()[d] - s.angles[d]));
      dof_sum[d] += e;
      res.errors_deg.push_back(static_cast<float>(e));
      filtered_sum += rad_to_deg(std::abs(filtered->angles()[d] - s.angles[d]));
    }
  }
  if (res.frames == 0) {
    return make_error(Errc::invalid_argument, "glove session: no task frames to score (task_s too short?)");
  }
  double total = 0.0;
  for (std::size_t d = 0; d < kHandDofCount; ++d) {
    res.dof_mean_deg[d] = dof_sum[d] / static_cast<double>(res.frames);
    total += dof_sum[d];
  }
  const double n = static_cast<double>(res.frames * kHandDofCount);
  res.mean_deg = total / n;
  res.filtered_mean_deg = filtered_sum / n;
  res.p95_deg = percentile(res.errors_deg, 0.95);
  res.task_seconds = task_start ? 1e-9 * static_cast<double>(task_end - *task_start) : 0.0;
  res.pipeline_seconds = std::chrono::duration<double>(pipeline).count();
  res.tracker = raw->stats();
  return res;
}

GloveAggregate aggregate(const std::vector<GloveSessionResult>& sessions) {
  GloveAggregate a;
  std::vector<float> all;
  double sum = 0.0, fsum = 0.0, secs = 0.0;
  std::size_t pframes = 0;
  for (const auto& s : sessions) {
    ++a.sessions;
    a.frames += s.frames;
    const double n = static_cast<double>(s.frames);
    sum += s.mean_deg * n;
    fsum += s.filtered_mean_deg * n;
    for (std::size_t d = 0; d < kHandDofCount; ++d) a.dof_mean_deg[d] += s.dof_mean_deg[d] * n;
    all.insert(all.end(), s.errors_deg.begin(), s.errors_deg.end());
    secs += s.pipeline_seconds;
    pframes += s.pipeline_frames;
  }
  if (a.frames > 0) {
    const double n = static_cast<double>(a.frames);
    a.mean_deg = sum / n;
    a.filtered_mean_deg = fsum / n;
    for (auto& d : a.dof_mean_deg) d /= n;
  }
  a.p95_deg = percentile(std::move(all), 0.95);
  a.pipeline_us_per_frame = pframes ? 1e6 * secs / static_cast<double>(pframes) : 0.0;
  return a;
}

namespace {

// The wearer's true hand, written as HandTruthWriter rows: the subject's
// hand model (the tracker's: both come from the subject's length and width)
// at the tracker's wrist, so served fingers compare with these directly.
class TruthRecorder {
 public:
  static Result<std::unique_ptr<TruthRecorder>> open(const std::filesystem::path& path, const HandShape& shape,
                                                     Handedness hand, const Pose& T_world_wrist, int every) {
    auto writer = sim::HandTruthWriter::open(path);
    if (!writer) return writer.error();
    return std::unique_ptr<TruthRecorder>(new TruthRecorder(std::move(*writer), shape, hand, T_world_wrist, every));
  }
  // The hand behind sample s, at time_ns (CLOCK_MONOTONIC), when s is one of every `every` measurements.
  void record(const sim::StretchSample& s, TimeNs time_ns) {
    if (s.measurement.index % every_ != 0) return;
    writer_->write(model_.forward(hand_, s.angles, T_world_wrist_, time_ns));
  }

 private:
  TruthRecorder(std::unique_ptr<sim::HandTruthWriter> writer, const HandShape& shape, Handedness hand,
                const Pose& T_world_wrist, int every)
      : writer_(std::move(writer)),
        model_(shape),
        hand_(hand),
        T_world_wrist_(T_world_wrist),
        every_(static_cast<std::uint64_t>(every)) {}
  std::unique_ptr<sim::HandTruthWriter> writer_;
  HandModel model_;
  Handedness hand_;
  Pose T_world_wrist_;
  std::uint64_t every_;
};

class SimGloveSource final : public HandSource {
 public:
  SimGloveSource(std::unique_ptr<stretch_glove::GloveHandSource> inner, sim::StretchGloveSession session,
                 std::unique_ptr<TruthRecorder> truth, const Clock& clock)
      : inner_(std::move(inner)), session_(std::move(session)), truth_(std::move(truth)), clock_(clock) {
    thread_ = std::thread([this] { run(); });
  }
  ~SimGloveSource() override {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  std::string_view name() const noexcept override { return "glove"; }
  bool available(Handedness hand) const noexcept override { return inner_->available(hand); }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override { return inner_->pose_at(hand, t_ns); }
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override {
    return inner_->lookup(hand, t_ns, out);
  }

 private:
  // Measurements are due at their simulated time after the task start; they
  // are fed in 10 ms batches, like USB reports.
  void run() {
    sim::StretchSample s;
    std::optional<TimeNs> offset;
    while (session_.next(s)) {
      if (s.phase == sim::StretchPhase::exploration) continue;  // already used for the calibration
      if (!offset) offset = clock_.now_ns() - s.measurement.time_ns;
      const TimeNs due = s.measurement.time_ns + *offset;
      if (due > clock_.now_ns() + 10 * kNsPerMillisecond) {
        std::unique_lock lock(mutex_);
        cv_.wait_for(lock, std::chrono::nanoseconds(due - clock_.now_ns()), [&] { return stop_; });
      }
      {
        std::lock_guard lock(mutex_);
        if (stop_) return;
      }
      if (truth_) truth_->record(s, due);
      inner_->push_measurement(s.measurement.combination, s.measurement.capacitance_pf, due);
    }
  }

  std::unique_ptr<stretch_glove::GloveHandSource> inner_;
  sim::StretchGloveSession session_;
  std::unique_ptr<TruthRecorder> truth_;
  const Clock& clock_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace

static sim::StretchGloveSimOptions simulated_glove(std::uint64_t seed, int subject) {
  sim::StretchGloveSimOptions so;
  so.glove_seed = seed;
  so.seed = mix_seed(seed, 9000 + static_cast<std::uint64_t>(subject));
  return so;
}

Result<SimulatedCalibration> calibrate_simulated(const StretchGloveLayout& layout, int subject_id, std::uint64_t seed,
                                                 double exploration_s, std::string source) {
  auto subject = sim::sim_subject(subject_id);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();
  auto simulator = sim::StretchGloveSimulator::create(layout, *shape, simulated_glove(seed, subject_id));
  if (!simulator) return simulator.error();
  sim::StretchSessionOptions sess;
  sess.exploration_s = exploration_s;
  sess.task_s = 0.0;
  sess.task_motion.hand = subject->dominant_hand;
  sim::StretchGloveSession exploration(std::move(*simulator), sess);
  auto readout = stretch_glove::make_readout(layout);
  if (!readout) return readout.error();
  auto calibrator = stretch_glove::MinMaxCalibrator::create(layout);
  if (!calibrator) return calibrator.error();
  stretch_glove::CellFrame frame = readout->make_frame();
  sim::StretchSample s;
  while (exploration.next(s)) {
    if (readout->push(s.measurement.combination, s.measurement.capacitance_pf, s.measurement.time_ns, frame) &&
        frame.all_valid()) {
      calibrator->add(frame);
    }
  }
  SimulatedCalibration out;
  out.progress = calibrator->progress();
  char created[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(created, sizeof created, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  auto cal = calibrator->finish(std::move(source), created);
  if (!cal) return cal.error();
  out.calibration = std::move(*cal);
  return out;
}

Status SimGloveSourceOptions::validate() const {
  if (subject < 0 || subject >= sim::kSimSubjectCount) {
    return make_error(Errc::invalid_argument, "simulated glove wearer: subject " + std::to_string(subject) +
                                                  " is not one of the simulated subjects 0-" +
                                                  std::to_string(sim::kSimSubjectCount - 1));
  }
  if (model.empty()) return make_error(Errc::invalid_argument, "simulated glove wearer: no pose model (.onnx) given");
  if (!(exploration_s > 0.0)) {
    return make_error(Errc::invalid_argument, "simulated glove wearer: exploration_s must be > 0 (the calibration "
                                              "needs an exploration phase)");
  }
  if (truth_every < 1) {
    return make_error(Errc::invalid_argument, "simulated glove wearer: truth_every must be at least 1 measurement");
  }
  if (auto st = tracker.validate(); !st) return st;
  return {};
}

std::string SimGloveSourceOptions::describe() const {
  char buf[512];
  std::snprintf(buf, sizeof buf, "simulated glove wearer: subject %d, seed %llu, model %s, layout %s, exploration %.0f s, "
                "truth %s (every %d measurements)",
                subject, static_cast<unsigned long long>(seed), model.string().c_str(), layout.name.c_str(),
                exploration_s, truth_path.empty() ? "not written" : truth_path.string().c_str(), truth_every);
  return buf;
}

namespace {

// What the sim and emulated inputs share: the wearer calibrated by the
// simulated exploration, the pipeline set up for their hand, the live session
// (the same donning, already calibrated: no exploration of its own, task
// motion for a day from t = 0) and the truth file.
struct LiveWearer {
  sim::SimSubject subject;
  stretch_glove::MinMaxCalibration calibration;
  std::optional<stretch_glove::OnnxPoseModel> model;
  stretch_glove::GloveHandSourceOptions pipeline;
  std::optional<sim::StretchGloveSession> session;
  std::unique_ptr<TruthRecorder> truth;
};

Result<LiveWearer> prepare_live_wearer(const SimGloveSourceOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  LiveWearer w;
  auto subject = sim::sim_subject(options.subject);
  if (!subject) return subject.error();
  w.subject = *subject;
  auto shape = subject->shape();
  if (!shape) return shape.error();
  auto live_sim = sim::StretchGloveSimulator::create(options.layout, *shape, simulated_glove(options.seed, options.subject));
  if (!live_sim) return live_sim.error();

  auto calibration = calibrate_simulated(options.layout, options.subject, options.seed, options.exploration_s,
                                         "simulated subject " + std::to_string(options.subject) + " exploration");
  if (!calibration) return calibration.error();
  w.calibration = std::move(calibration->calibration);

  auto model = stretch_glove::OnnxPoseModel::load(options.model, options.layout);
  if (!model) return model.error();
  w.model.emplace(std::move(*model));
  w.pipeline.tracker = options.tracker;
  const Handedness hand = options.hand.value_or(subject->dominant_hand);
  w.pipeline.tracker.hand = hand;
  w.pipeline.tracker.hand_length_m = subject->hand_length_m;
  w.pipeline.tracker.hand_width_m = subject->hand_width_m;
  w.pipeline.history = options.history;

  sim::StretchSessionOptions sess;
  sess.task_motion.hand = hand;
  sess.exploration_s = 0.0;
  sess.task_s = 24 * 3600.0;
  w.session.emplace(std::move(*live_sim), sess);

  if (!options.truth_path.empty()) {
    auto truth = TruthRecorder::open(options.truth_path, *shape, hand,
                                     w.pipeline.tracker.T_world_wrist_fixed, options.truth_every);
    if (!truth) return truth.error();
    w.truth = std::move(*truth);
  }
  return w;
}

}  // namespace

Result<std::unique_ptr<HandSource>> make_sim_glove_source(const SimGloveSourceOptions& options, const Clock& clock) {
  auto w = prepare_live_wearer(options);
  if (!w) return w.error();
  auto inner = stretch_glove::GloveHandSource::create(options.layout, std::move(w->calibration), std::move(*w->model),
                                                      w->pipeline);
  if (!inner) return inner.error();
  return std::unique_ptr<HandSource>(
      new SimGloveSource(std::move(*inner), std::move(*w->session), std::move(w->truth), clock));
}

// ---------------------------------------------------------------------------
// The emulated input.

Status EmulatedGloveSourceOptions::validate() const {
  if (auto st = wearer.validate(); !st) return st;
  if (auto st = faults.validate(); !st) return st;
  if (serve.latency_min_ns < 0 || serve.latency_jitter_ns < 0 || serve.lookahead_ns < 0 || serve.pump_interval_ns <= 0) {
    return make_error(Errc::invalid_argument, "emulated glove: the link's latency, jitter and lookahead must be >= 0 "
                                              "and the pump interval > 0");
  }
  if (wearer.layout.top_strips > 255 || wearer.layout.bottom_strips > 255) {
    return make_error(Errc::invalid_argument, "emulated glove: the layout has more strips than a board reports (255)");
  }
  return {};
}

std::string EmulatedGloveSourceOptions::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf, "; emulated read-out board: link latency %.1f-%.1f ms, %zu unplug(s)%s",
                1e-6 * static_cast<double>(serve.latency_min_ns),
                1e-6 * static_cast<double>(serve.latency_min_ns + serve.latency_jitter_ns), faults.unplugs.size(),
                faults.any() ? ", faults on" : "");
  return wearer.describe() + buf;
}

namespace {

// The board's capacitance provider: the live wearer measured at the board's
// measurement times. Runs on the emulator server's thread, under its lock.
class EmulatedWearer {
 public:
  EmulatedWearer(sim::StretchGloveSession session, std::unique_ptr<TruthRecorder> truth)
      : session_(std::move(session)),
        truth_(std::move(truth)),
        cells_(session_.simulator().layout().cell_count()),
        half_period_ns_(seconds_to_ns(0.5 / session_.simulator().options().measurement_rate_hz)) {}

  double capacitance(std::size_t combination, TimeNs t_ns) {
    const sim::StretchGloveSimulator& simulator = session_.simulator();
    // Advance the wearer to the measurement nearest t_ns (the board and the
    // simulator share the rate, so normally exactly t_ns).
    while (!have_ || simulator.measurement_time(simulator.next_index()) <= t_ns + half_period_ns_) {
      if (!session_.next(current_)) break;  // a day is over: the hand holds still
      have_ = true;
      record_truth(current_);
    }
    if (!have_) return std::numeric_limits<double>::quiet_NaN();
    const sim::StretchMeasurement& m = current_.measurement;
    if (m.combination == combination) return m.capacitance_pf;
    off_cycle_.fetch_add(1, std::memory_order_relaxed);
    if (cells_index_ != m.index) {
      simulator.cell_capacitances(current_.angles, cells_, current_.wrist);
      cells_index_ = m.index;
    }
    double sum = 0.0;
    for (const auto c : simulator.cells_in(combination)) sum += cells_[c];
    return sum * current_.truth.drift_gain + current_.truth.noise_pf + current_.truth.outlier_pf;
  }

  // Any thread, once: CLOCK_MONOTONIC of emulator time 0. Until then truth rows wait.
  void set_time_zero(TimeNs t0_ns) { t0_ns_.store(t0_ns, std::memory_order_release); }
  std::uint64_t off_cycle() const { return off_cycle_.load(std::memory_order_relaxed); }

 private:
  void record_truth(const sim::StretchSample& s) {
    if (!truth_) return;
    const TimeNs t0 = t0_ns_.load(std::memory_order_acquire);
    if (t0 == kUnknown) {
      // The server's first pump can run before its start() has returned the time zero.
      pending_.push_back(s);
      return;
    }
    for (const auto& p : pending_) truth_->record(p, t0 + p.measurement.time_ns);
    pending_.clear();
    truth_->record(s, t0 + s.measurement.time_ns);
  }

  static constexpr TimeNs kUnknown = std::numeric_limits<TimeNs>::min();
  sim::StretchGloveSession session_;
  std::unique_ptr<TruthRecorder> truth_;
  sim::StretchSample current_;
  bool have_ = false;
  std::vector<double> cells_;
  std::uint64_t cells_index_ = std::numeric_limits<std::uint64_t>::max();
  DurationNs half_period_ns_;
  std::atomic<TimeNs> t0_ns_{kUnknown};
  std::vector<sim::StretchSample> pending_;
  std::atomic<std::uint64_t> off_cycle_{0};
};

}  // namespace

struct EmulatedGloveSource::Impl {
  std::shared_ptr<EmulatedWearer> wearer;
  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<devices::StretchEmulatorServer> server;
  std::unique_ptr<stretch_glove::GloveBoardSource> board;  // last: its reader stops first
};

EmulatedGloveSource::EmulatedGloveSource(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
EmulatedGloveSource::~EmulatedGloveSource() = default;

bool EmulatedGloveSource::available(Handedness hand) const noexcept { return impl_->board->available(hand); }
Result<HandPose> EmulatedGloveSource::pose_at(Handedness hand, TimeNs t_ns) { return impl_->board->pose_at(hand, t_ns); }
PoseLookup EmulatedGloveSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  return impl_->board->lookup(hand, t_ns, out);
}
stretch_glove::GloveSourceStats EmulatedGloveSource::stats() const { return impl_->board->stats(); }
devices::StretchDeviceStats EmulatedGloveSource::device_stats() { return impl_->board->device_stats(); }
devices::StretchEmulatorStats EmulatedGloveSource::emulator_stats() const { return impl_->server->emulator_stats(); }
TimeNs EmulatedGloveSource::time_zero_ns() const { return impl_->server->time_zero_ns(); }
std::uint64_t EmulatedGloveSource::off_cycle_readings() const { return impl_->wearer->off_cycle(); }

Result<std::unique_ptr<EmulatedGloveSource>> make_emulated_glove_source(const EmulatedGloveSourceOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  auto w = prepare_live_wearer(options.wearer);
  if (!w) return w.error();
  const StretchGloveLayout& layout = options.wearer.layout;
  const sim::StretchGloveSimOptions& so = w->session->simulator().options();
  const double rate = std::round(so.measurement_rate_hz);
  if (rate != so.measurement_rate_hz || rate < 1.0 || rate > devices::kStretchMaxRateHz) {
    return make_error(Errc::invalid_argument, "emulated glove: the simulated glove's measurement rate " +
                                                  std::to_string(so.measurement_rate_hz) +
                                                  " Hz is not one a read-out board can be set to");
  }

  // The board the simulated glove is wired to: its strips, rate and full scale.
  devices::StretchEmulatorOptions eo;
  eo.top_strips = static_cast<std::uint8_t>(layout.top_strips);
  eo.bottom_strips = static_cast<std::uint8_t>(layout.bottom_strips);
  eo.rate_hz = static_cast<std::uint16_t>(rate);
  eo.full_scale_pf = so.full_scale_pf;
  eo.seed = mix_seed(options.wearer.seed, 0x5b0a4d);
  eo.faults = options.faults;

  auto impl = std::make_unique<EmulatedGloveSource::Impl>();
  impl->wearer = std::make_shared<EmulatedWearer>(std::move(*w->session), std::move(w->truth));
  auto emulator = devices::StretchEmulator::create(
      eo, [wearer = impl->wearer](std::size_t c, TimeNs t_ns) { return wearer->capacitance(c, t_ns); });
  if (!emulator) return emulator.error();
  impl->link = std::make_shared<hid::FakeHidLink>();
  devices::StretchServeOptions serve = options.serve;
  serve.seed = mix_seed(options.wearer.seed, 0x11a7);
  impl->server = std::make_unique<devices::StretchEmulatorServer>(std::move(*emulator), impl->link, serve);

  devices::StretchDeviceOptions device = options.device;
  device.stream.nominal_rate_hz = rate;
  stretch_glove::GloveHandSourceOptions pipeline = w->pipeline;
  // The board's full scale, which the read-out must refuse readings at.
  pipeline.readout.full_scale_pf = so.full_scale_pf;
  auto board = stretch_glove::GloveBoardSource::start(std::make_unique<hid::FakeHidTransport>(impl->link), layout,
                                                      std::move(w->calibration), std::move(*w->model), pipeline, device);
  if (!board) return board.error();
  impl->board = std::move(*board);

  impl->server->start();
  const TimeNs t0 = impl->server->time_zero_ns();
  impl->wearer->set_time_zero(t0);
  for (const devices::StretchOutage& u : options.faults.unplugs) impl->link->schedule_unplug(t0 + u.at_ns, u.duration_ns);
  return std::unique_ptr<EmulatedGloveSource>(new EmulatedGloveSource(std::move(impl)));
}

}  // namespace proprio::stretch_glove_eval
