#include "proprio/stretch_glove_eval/glove_evaluation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <ctime>
#include <mutex>
#include <thread>

#include "proprio/core/random.hpp"
#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_glove/glove_hand_source.hpp"
#include "proprio/stretch_glove/onnx_pose_model.hpp"
#include "proprio/stretch_glove/readout.hpp"
#include "proprio/sim/subjects.hpp"

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

std::string_view to_string(CalibrationMode m) noexcept {
  return m == CalibrationMode::session ? "session min-max" : "training-data min-max";
}

Result<GloveSessionResult> run_glove_session(const StretchGloveLayout& layout, const std::filesystem::path& model_path,
                                             const GloveSessionSpec& spec) {
  auto subject = sim::sim_subject(spec.subject);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();
  sim::StretchGloveSimOptions so;
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
  sim::StretchGloveSession session(std::move(*simulator), sess);

  // Two models: the network as it is, and what an app sees (1€-filtered).
  auto model = stretch_glove::OnnxPoseModel::load(model_path, layout);
  if (!model) return model.error();
  auto model_filtered = stretch_glove::OnnxPoseModel::load(model_path, layout);
  if (!model_filtered) return model_filtered.error();
  auto readout = stretch_glove::MatrixReadout::create(layout);
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

class SimGloveSource final : public HandSource {
 public:
  SimGloveSource(std::unique_ptr<stretch_glove::GloveHandSource> inner, sim::StretchGloveSession session, const Clock& clock)
      : inner_(std::move(inner)), session_(std::move(session)), clock_(clock) {
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
      inner_->push_measurement(s.measurement.combination, s.measurement.capacitance_pf, due);
    }
  }

  std::unique_ptr<stretch_glove::GloveHandSource> inner_;
  sim::StretchGloveSession session_;
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
  auto readout = stretch_glove::MatrixReadout::create(layout);
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

Result<std::unique_ptr<HandSource>> make_sim_glove_source(const SimGloveSourceOptions& options, const Clock& clock) {
  auto subject = sim::sim_subject(options.subject);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();
  auto live_sim = sim::StretchGloveSimulator::create(options.layout, *shape, simulated_glove(options.seed, options.subject));
  if (!live_sim) return live_sim.error();

  auto calibration = calibrate_simulated(options.layout, options.subject, options.seed, options.exploration_s,
                                         "simulated subject " + std::to_string(options.subject) + " exploration");
  if (!calibration) return calibration.error();

  auto model = stretch_glove::OnnxPoseModel::load(options.model, options.layout);
  if (!model) return model.error();
  stretch_glove::GloveHandSourceOptions go;
  go.tracker = options.tracker;
  go.tracker.hand = subject->dominant_hand;
  go.tracker.hand_length_m = subject->hand_length_m;
  go.tracker.hand_width_m = subject->hand_width_m;
  go.history = options.history;
  auto inner = stretch_glove::GloveHandSource::create(options.layout, std::move(calibration->calibration), std::move(*model), go);
  if (!inner) return inner.error();

  // The live session skips its own exploration (same donning, already calibrated) and runs for a day.
  sim::StretchSessionOptions sess;
  sess.task_motion.hand = subject->dominant_hand;
  sess.exploration_s = 0.0;
  sess.task_s = 24 * 3600.0;
  sim::StretchGloveSession live(std::move(*live_sim), sess);
  return std::unique_ptr<HandSource>(new SimGloveSource(std::move(*inner), std::move(live), clock));
}

}  // namespace proprio::stretch_glove_eval
