#include "proprio/ftm_sources/ftm_sources.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <limits>
#include <mutex>
#include <thread>
#include <vector>

#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/ftm_sim/wearer_calibration.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/sim/hand_truth_writer.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::ftm_sources {

Status FtmSimSourceOptions::validate() const {
  if (subject < -1 || subject >= sim::kSimSubjectCount) {
    return make_error(Errc::invalid_argument, "ftm sim source: subject " + std::to_string(subject) +
                                                  " is not -1 or one of the simulated subjects 0-" +
                                                  std::to_string(sim::kSimSubjectCount - 1));
  }
  if (!(task_s > 0.0) || task_s > 3600.0) {
    return make_error(Errc::invalid_argument, "ftm sim source: task_s must be in (0, 3600] s");
  }
  if (truth_every < 1) return make_error(Errc::invalid_argument, "ftm sim source: truth_every must be at least 1");
  return {};
}

std::string FtmSimSourceOptions::describe() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "simulated FTM wearer: %s hand, subject %d, seed %llu, task %.0f s, calibration %s, abduction %s, "
                "truth %s",
                hand == Handedness::right ? "right" : "left", subject, static_cast<unsigned long long>(seed), task_s,
                calibration.empty() ? "from the wearer's figure-eight and three poses" : calibration.string().c_str(),
                track_abduction ? "tracked" : "held at 0",
                truth_path.empty() ? "not written" : truth_path.string().c_str());
  return buf;
}

Status FtmEmulatedSourceOptions::validate() const {
  if (auto st = wearer.validate(); !st) return st;
  if (auto st = faults.validate(); !st) return st;
  if (serve.latency_min_ns < 0 || serve.latency_jitter_ns < 0 || serve.lookahead_ns < 0 || serve.pump_interval_ns <= 0) {
    return make_error(Errc::invalid_argument, "ftm emulated source: the link's latency, jitter and lookahead must be "
                                              ">= 0 and the pump interval > 0");
  }
  return device.validate();
}

std::string FtmEmulatedSourceOptions::describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "; emulated FTM board: link latency %.1f-%.1f ms, %zu unplug(s)",
                1e-6 * static_cast<double>(serve.latency_min_ns),
                1e-6 * static_cast<double>(serve.latency_min_ns + serve.latency_jitter_ns), faults.unplugs.size());
  return wearer.describe() + buf;
}

Status FtmDeviceSourceOptions::validate() const {
  if (calibration.empty()) {
    return make_error(Errc::invalid_argument, "ftm device source: calibration: a board needs a calibration file "
                                              "(`proprio calibrate ftm` writes one)");
  }
  return device.validate();
}

std::string FtmDeviceSourceOptions::describe() const {
  return std::string("FTM board over USB: ") + (hand == Handedness::right ? "right" : "left") + " hand, calibration " +
         calibration.string() + ", abduction " + (track_abduction ? "tracked" : "held at 0") + "; " + device.describe();
}

namespace {

void ftm_src_shift(ftm::FtmEvent& e, DurationNs by) {
  switch (e.kind) {
    case ftm::FtmEvent::Kind::imu: e.imu.time_ns += by; break;
    case ftm::FtmEvent::Kind::bend: e.bend.time_ns += by; break;
    case ftm::FtmEvent::Kind::wrist: e.wrist.time_ns += by; break;
  }
}

bool ftm_src_is_dorsum(const ftm::FtmEvent& e) {
  return e.kind == ftm::FtmEvent::Kind::imu && e.index == static_cast<std::uint8_t>(ftm::FtmImu::dorsum);
}

// The wearer's true hand on the served poses' clock, once per truth_every dorsum ticks.
class FtmTruthRows {
 public:
  static Result<std::unique_ptr<FtmTruthRows>> open(const std::filesystem::path& path, int every) {
    if (path.empty()) return std::unique_ptr<FtmTruthRows>();
    auto w = sim::HandTruthWriter::open(path);
    if (!w) return w.error();
    return std::unique_ptr<FtmTruthRows>(new FtmTruthRows(std::move(*w), every));
  }
  // sim_ns: the wearer's time; host_ns: the same instant on the served clock.
  void on_event(const ftm_sim::FtmWearerSimulator& sim, const ftm::FtmEvent& e, TimeNs host_ns) {
    if (!ftm_src_is_dorsum(e) || (ticks_++ % every_) != 0) return;
    HandPose truth = sim.truth_at(e.time_ns()).pose;
    truth.time_ns = host_ns;
    writer_->write(truth);
  }
  ~FtmTruthRows() { writer_->flush(); }

 private:
  FtmTruthRows(std::unique_ptr<sim::HandTruthWriter> w, int every)
      : writer_(std::move(w)), every_(static_cast<std::uint64_t>(every)) {}
  std::unique_ptr<sim::HandTruthWriter> writer_;
  std::uint64_t every_;
  std::uint64_t ticks_ = 0;
};

ftm::FtmHandSourceOptions ftm_src_pipeline(Handedness hand, bool track_abduction, const PoseHistoryOptions& history) {
  ftm::FtmHandSourceOptions o;
  o.tracker.hand = hand;
  o.tracker.track_abduction = track_abduction;
  o.history = history;
  return o;
}

// The wearer, calibrated (or given its calibration), ready at its task's start.
struct FtmPreparedWearer {
  std::unique_ptr<ftm_sim::FtmWearerSimulator> sim;
  std::unique_ptr<ftm::FtmHandSource> source;
  std::vector<ftm::FtmEvent> warmup;  // the calibration phases' events: converge the filters first
};

Result<FtmPreparedWearer> ftm_src_prepare(const FtmSimSourceOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  ftm_sim::FtmWearerOptions wo;
  wo.hand = options.hand;
  wo.seed = options.seed;
  wo.subject.subject_index = options.subject;
  wo.task_s = options.task_s;
  std::optional<ftm::FtmCalibration> file;
  if (!options.calibration.empty()) {
    auto c = ftm::load_ftm_calibration(options.calibration);
    if (!c) return c.error();
    file = std::move(*c);
    wo.calibration.enabled = false;  // a calibrated user starts with the task
  }
  auto sim = ftm_sim::FtmWearerSimulator::create(wo);
  if (!sim) return sim.error();
  FtmPreparedWearer w;
  w.sim = std::move(*sim);
  ftm::FtmCalibration calibration;
  if (file) {
    calibration = std::move(*file);
  } else {
    auto cal = ftm_sim::calibrate_from_wearer(*w.sim);
    if (!cal) return cal.error();
    calibration = std::move(cal->outcome.calibration);
    w.warmup = std::move(cal->events);
  }
  auto source = ftm::FtmHandSource::create(ftm_src_pipeline(options.hand, options.track_abduction, options.history),
                                           std::move(calibration));
  if (!source) return source.error();
  w.source = std::move(*source);
  return w;
}

// What the three inputs share: the FtmHandSource and its freshness.
class FtmSourceBase : public FtmLiveSource {
 public:
  FtmSourceBase(std::unique_ptr<ftm::FtmHandSource> source, const Clock& clock)
      : source_(std::move(source)), clock_(clock) {}
  bool available(Handedness hand) const noexcept override {
    const TimeNs last = last_publish_ns_.load(std::memory_order_acquire);
    return source_->available(hand) && last != 0 && clock_.now_ns() - last < kFtmStaleAfterNs;
  }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override { return source_->pose_at(hand, t_ns); }
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override {
    return source_->lookup(hand, t_ns, out);
  }

 protected:
  // Producer thread only.
  void push(const ftm::FtmEvent& e) {
    if (source_->push(e)) last_publish_ns_.store(clock_.now_ns(), std::memory_order_release);
  }
  // Waits up to `d`; false once stopping.
  bool wait_for(DurationNs d) {
    std::unique_lock lock(mutex_);
    cv_.wait_for(lock, std::chrono::nanoseconds(std::max<DurationNs>(d, 0)), [&] { return stop_; });
    return !stop_;
  }
  void stop_thread() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

  std::unique_ptr<ftm::FtmHandSource> source_;
  const Clock& clock_;
  std::atomic<TimeNs> last_publish_ns_{0};
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

// ---------------------------------------------------------------------------
// sim: the wearer's samples fall due at their time after the task start, fed
// in 5 ms batches (a board's reports arrive in bursts like these).

class FtmSimSource final : public FtmSourceBase {
 public:
  FtmSimSource(FtmPreparedWearer w, std::unique_ptr<FtmTruthRows> truth, const Clock& clock)
      : FtmSourceBase(std::move(w.source), clock), sim_(std::move(w.sim)), truth_(std::move(truth)) {
    offset_ns_ = clock_.now_ns() - sim_->task_begin_ns();
    for (auto e : w.warmup) {
      ftm_src_shift(e, offset_ns_);
      push(e);
    }
    thread_ = std::thread([this] { run(); });
  }
  ~FtmSimSource() override { stop_thread(); }
  FtmLiveStats live_stats() override {
    FtmLiveStats s;
    s.source = source_->stats();
    s.time_zero_ns = offset_ns_ + sim_->task_begin_ns();
    return s;
  }

 private:
  void run() {
    std::vector<ftm::FtmEvent> events;
    constexpr DurationNs kBatch = 5 * kNsPerMillisecond;
    do {
      const TimeNs sim_now = std::min(clock_.now_ns() - offset_ns_, sim_->end_ns());
      events.clear();
      sim_->advance(sim_now, events);
      for (auto& e : events) {
        if (truth_) truth_->on_event(*sim_, e, e.time_ns() + offset_ns_);
        ftm_src_shift(e, offset_ns_);
        push(e);
      }
      // After the task the hand is gone from the simulation: the source goes stale.
    } while (wait_for(kBatch));
  }

  std::unique_ptr<ftm_sim::FtmWearerSimulator> sim_;
  std::unique_ptr<FtmTruthRows> truth_;
  DurationNs offset_ns_ = 0;
};

// ---------------------------------------------------------------------------
// emulated: the wearer's task in emulator time (0 = the task's start) behind
// the board emulator; its wrist samples go to the source beside the board.

class FtmWristQueue {
 public:
  void push(const ftm::FtmEvent& e) {
    std::lock_guard lock(mutex_);
    q_.push_back(e);
  }
  void drain(std::vector<ftm::FtmEvent>& out) {
    std::lock_guard lock(mutex_);
    out.insert(out.end(), q_.begin(), q_.end());
    q_.clear();
  }

 private:
  std::mutex mutex_;
  std::deque<ftm::FtmEvent> q_;
};

// Runs on the emulator server's thread, under its lock.
class FtmTaskFeed final : public ftm::FtmSampleFeed {
 public:
  FtmTaskFeed(std::unique_ptr<ftm_sim::FtmWearerSimulator> sim, std::unique_ptr<FtmTruthRows> truth,
              std::shared_ptr<FtmWristQueue> wrist, std::shared_ptr<std::atomic<TimeNs>> t0)
      : sim_(std::move(sim)), truth_(std::move(truth)), wrist_(std::move(wrist)), t0_(std::move(t0)) {}
  void advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) override {
    const TimeNs begin = sim_->task_begin_ns();
    buf_.clear();
    sim_->advance(std::min(begin + t_ns, sim_->end_ns()), buf_);
    const TimeNs t0 = t0_->load(std::memory_order_acquire);
    for (auto& e : buf_) {
      ftm_src_shift(e, -begin);
      if (e.kind == ftm::FtmEvent::Kind::wrist) {
        if (t0 != kUnknown) {
          ftm::FtmEvent w = e;
          ftm_src_shift(w, t0);
          wrist_->push(w);
        }
        continue;
      }
      if (truth_ && t0 != kUnknown) truth_->on_event(*sim_, shifted_back(e, begin), t0 + e.time_ns());
      out.push_back(e);
    }
  }
  static constexpr TimeNs kUnknown = std::numeric_limits<TimeNs>::min();

 private:
  static ftm::FtmEvent shifted_back(ftm::FtmEvent e, TimeNs begin) {
    ftm_src_shift(e, begin);
    return e;
  }
  std::unique_ptr<ftm_sim::FtmWearerSimulator> sim_;
  std::unique_ptr<FtmTruthRows> truth_;
  std::shared_ptr<FtmWristQueue> wrist_;
  std::shared_ptr<std::atomic<TimeNs>> t0_;
  std::vector<ftm::FtmEvent> buf_;
};

// A board (real or emulated) read on a consumer thread; `wrist` (may be null)
// adds a wrist tracker's samples.
class FtmBoardSource : public FtmSourceBase {
 public:
  FtmBoardSource(std::unique_ptr<ftm::FtmHandSource> source, std::unique_ptr<devices::FtmBoardDevice> device,
                 std::shared_ptr<FtmWristQueue> wrist)
      : FtmSourceBase(std::move(source), MonotonicClock::instance()),
        device_(std::move(device)),
        wrist_(std::move(wrist)) {}
  ~FtmBoardSource() override {
    stop_thread();
    device_->stop();
  }
  // Before start(): the producer thread does not run yet.
  void warm_up(const std::vector<ftm::FtmEvent>& warmup, DurationNs shift_ns) {
    for (auto e : warmup) {
      ftm_src_shift(e, shift_ns);
      push(e);
    }
  }
  Status start() {
    if (auto st = device_->start(); !st) return st;
    thread_ = std::thread([this] { run(); });
    return {};
  }
  FtmLiveStats live_stats() override {
    FtmLiveStats s;
    s.source = source_->stats();
    s.device = device_->stats();
    s.have_device = true;
    s.time_zero_ns = time_zero_ns_;
    return s;
  }
  TimeNs time_zero_ns_ = 0;

 protected:
  std::unique_ptr<devices::FtmBoardDevice> device_;

 private:
  void run() {
    std::vector<ftm::FtmEvent> batch, wrist;
    devices::FtmBoardSample s;
    do {
      batch.clear();
      while (device_->pop(s)) batch.push_back(s.event);
      if (wrist_) {
        wrist_->drain(wrist);
        // Wrist samples newer than the board's newest wait for the next round.
        const TimeNs horizon = batch.empty() ? std::numeric_limits<TimeNs>::min() : batch.back().time_ns();
        auto split = std::partition(wrist.begin(), wrist.end(), [&](const auto& w) { return w.time_ns() <= horizon; });
        batch.insert(batch.end(), wrist.begin(), split);
        wrist.erase(wrist.begin(), split);
        std::stable_sort(batch.begin(), batch.end(),
                         [](const auto& a, const auto& b) { return a.time_ns() < b.time_ns(); });
      }
      for (const auto& e : batch) push(e);
    } while (wait_for(2 * kNsPerMillisecond));
  }

  std::shared_ptr<FtmWristQueue> wrist_;
};

class FtmEmulatedSource final : public FtmBoardSource {
 public:
  using FtmBoardSource::FtmBoardSource;
  ~FtmEmulatedSource() override {
    // The consumer and the driver first, then the board they read.
    stop_thread();
    device_->stop();
    if (server) server->stop();
  }
  FtmLiveStats live_stats() override {
    FtmLiveStats s = FtmBoardSource::live_stats();
    if (server) s.time_zero_ns = server->time_zero_ns();
    return s;
  }
  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<devices::FtmBoardEmulatorServer> server;
};

}  // namespace

Result<std::unique_ptr<FtmLiveSource>> make_sim_ftm_source(const FtmSimSourceOptions& options, const Clock& clock) {
  auto w = ftm_src_prepare(options);
  if (!w) return w.error();
  auto truth = FtmTruthRows::open(options.truth_path, options.truth_every);
  if (!truth) return truth.error();
  return std::unique_ptr<FtmLiveSource>(new FtmSimSource(std::move(*w), std::move(*truth), clock));
}

Result<std::unique_ptr<FtmLiveSource>> make_emulated_ftm_source(const FtmEmulatedSourceOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  auto w = ftm_src_prepare(options.wearer);
  if (!w) return w.error();
  auto truth = FtmTruthRows::open(options.wearer.truth_path, options.wearer.truth_every);
  if (!truth) return truth.error();
  const TimeNs task_begin = w->sim->task_begin_ns();
  auto wrist = std::make_shared<FtmWristQueue>();
  auto t0 = std::make_shared<std::atomic<TimeNs>>(FtmTaskFeed::kUnknown);

  devices::FtmEmulatorOptions eo;
  eo.seed = mix_seed(options.wearer.seed, 0xf7b0a2d);
  eo.faults = options.faults;
  auto emulator = devices::FtmBoardEmulator::create(
      eo, std::make_unique<FtmTaskFeed>(std::move(w->sim), std::move(*truth), wrist, t0));
  if (!emulator) return emulator.error();
  auto link = std::make_shared<hid::FakeHidLink>();
  devices::FtmServeOptions serve = options.serve;
  serve.seed = mix_seed(options.wearer.seed, 0x11a7);
  auto server = std::make_unique<devices::FtmBoardEmulatorServer>(std::move(*emulator), link, serve);
  auto device = std::make_unique<devices::FtmBoardDevice>(std::make_unique<hid::FakeHidTransport>(link), options.device);
  auto source = std::make_unique<FtmEmulatedSource>(std::move(w->source), std::move(device), wrist);
  source->link = link;
  source->server = std::move(server);
  // The calibration phases happened just before emulator time 0 (they take
  // a moment to replay: the board starts after them, not during).
  source->warm_up(w->warmup, MonotonicClock::instance().now_ns() - task_begin);
  source->server->start();
  const TimeNs zero = source->server->time_zero_ns();
  t0->store(zero, std::memory_order_release);
  for (const devices::FtmOutage& u : options.faults.unplugs) link->schedule_unplug(zero + u.at_ns, u.duration_ns);
  if (auto st = source->start(); !st) return st.error();
  return std::unique_ptr<FtmLiveSource>(std::move(source));
}

Result<std::unique_ptr<FtmLiveSource>> make_board_ftm_source(std::unique_ptr<hid::HidTransport> transport,
                                                             const FtmDeviceSourceOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  auto calibration = ftm::load_ftm_calibration(options.calibration);
  if (!calibration) return calibration.error();
  auto source = ftm::FtmHandSource::create(ftm_src_pipeline(options.hand, options.track_abduction, options.history),
                                           std::move(*calibration));
  if (!source) return source.error();
  auto device = std::make_unique<devices::FtmBoardDevice>(std::move(transport), options.device);
  auto board = std::make_unique<FtmBoardSource>(std::move(*source), std::move(device), nullptr);
  if (auto st = board->start(); !st) return st.error();
  return std::unique_ptr<FtmLiveSource>(std::move(board));
}

Result<std::unique_ptr<FtmLiveSource>> make_device_ftm_source(const FtmDeviceSourceOptions& options) {
  return make_board_ftm_source(std::make_unique<hid::HidapiTransport>(devices::ftm_board_selector()), options);
}

}  // namespace proprio::ftm_sources
