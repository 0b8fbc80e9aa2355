#include "proprio/haptics/servo_loop.hpp"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>

#include "proprio/core/log.hpp"

namespace proprio::haptics {

namespace {
constexpr DurationNs kBinNs = 10'000;  // histogram bin: 10 us

FingertipForce scaled(FingertipForce f, double k) noexcept {
  f.normal_n *= k;
  f.shear_x_n *= k;
  f.shear_z_n *= k;
  return f;
}

bool finite_angles(const HandAngles& a) {
  for (double x : a) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}
}  // namespace

std::string ServoLoopOptions::describe() const {
  std::ostringstream s;
  s << "servo loop: period " << period_ns / 1000 << " us, " << (realtime_priority ? "SCHED_FIFO requested" : "normal priority")
    << ", stale hand after " << tracked_hand_timeout_ns / kNsPerMillisecond << " ms, finger AA "
    << (remove_finger_abduction ? "removed" : "tracked") << ", haptics " << (haptics_enabled ? "on" : "off (zero output)")
    << ", force scale " << force_scale;
  return s.str();
}

Status ServoLoopOptions::validate() const {
  if (period_ns < 100'000 || period_ns > 20 * kNsPerMillisecond) {
    return make_error(Errc::invalid_argument, "servo loop period_ns must be in [0.1, 20] ms");
  }
  if (tracked_hand_timeout_ns <= 0) {
    return make_error(Errc::invalid_argument, "servo loop tracked_hand_timeout_ns must be > 0");
  }
  if (!(force_scale > 0.0 && force_scale <= 10.0)) {
    return make_error(Errc::invalid_argument, "servo loop force_scale must be in (0, 10]");
  }
  if (realtime_priority_level < 1 || realtime_priority_level > 99) {
    return make_error(Errc::invalid_argument, "servo loop realtime_priority_level must be in [1, 99]");
  }
  return {};
}

std::string ServoTiming::describe() const {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(1);
  s << ticks << " ticks, " << overruns << " overruns, " << stale_hand_ticks << " with a stale hand; "
    << (realtime ? "SCHED_FIFO" : "normal priority") << "; wake-up jitter p50 " << jitter_p50_us << " us, p99 "
    << jitter_p99_us << " us, max " << jitter_max_us << " us; tick p50 " << tick_p50_us << " us, p99 " << tick_p99_us
    << " us, max " << tick_max_us << " us";
  return s.str();
}

void RecordingSink::send(const MotorAngles& motors, const FingertipForce& force, bool enabled, TimeNs now) noexcept {
  last_motors_ = motors;
  last_force_ = force;
  last_enabled_ = enabled;
  last_time_ = now;
  ++sends_;
}

Result<std::unique_ptr<ServoLoop>> ServoLoop::create(ContactSimulation simulation, std::vector<ServoChannel> channels,
                                                     ServoLoopOptions options, const Clock& clock) {
  if (auto s = options.validate(); !s) return s.error();
  if (channels.size() > kMaxServoChannels) {
    return make_error(Errc::invalid_argument, "a servo loop drives at most one device per finger of each hand (10 channels)");
  }
  for (std::size_t i = 0; i < channels.size(); ++i) {
    if (!channels[i].model) {
      return make_error(Errc::invalid_argument, "servo channel " + std::to_string(i) + " has no device model");
    }
    if (channels[i].hand >= simulation.hand_count()) {
      return make_error(Errc::invalid_argument, "servo channel " + std::to_string(i) + " is on hand " +
                                                    std::to_string(channels[i].hand) + ", but the simulation has " +
                                                    std::to_string(simulation.hand_count()) + " proxy hand(s)");
    }
    for (std::size_t j = 0; j < i; ++j) {
      if (channels[j].finger == channels[i].finger && channels[j].hand == channels[i].hand) {
        return make_error(Errc::invalid_argument, "two servo channels drive the same finger (" +
                                                      std::string(to_string(channels[i].finger)) + ") of one hand");
      }
    }
  }
  return std::unique_ptr<ServoLoop>(new ServoLoop(std::move(simulation), std::move(channels), options, clock));
}

ServoLoop::ServoLoop(ContactSimulation simulation, std::vector<ServoChannel> channels, ServoLoopOptions options,
                     const Clock& clock)
    : simulation_(std::move(simulation)),
      channels_(std::move(channels)),
      options_(options),
      clock_(clock) {
  gates_.reserve(channels_.size());
  for (const auto& c : channels_) gates_.emplace_back(*c.model);
  scratch_.channel_count = channels_.size();
}

ServoLoop::~ServoLoop() { stop(); }

void ServoLoop::submit_tracked_hand(const HandPose& pose) {
  if (!pose.active || !pose.fully_valid()) {
    rejected_hands_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  // The proxy's own model (the user's bone lengths) gives the angles; it is
  // immutable, so reading it here while the loop runs is safe.
  const int h = simulation_.hand_index(pose.hand);
  if (h < 0) {
    rejected_hands_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  const auto hand = static_cast<std::size_t>(h);
  const InverseKinematicsResult ik = simulation_.hand_model(hand).inverse(pose);
  submit_tracked_hand(pose.time_ns, ik.T_world_wrist, ik.angles, hand);
}

void ServoLoop::submit_tracked_hand(TimeNs time_ns, const Pose& T_world_wrist, const HandAngles& angles,
                                    std::size_t hand) {
  if (hand >= simulation_.hand_count() || !T_world_wrist.p.allFinite() || !T_world_wrist.q.coeffs().allFinite() ||
      !finite_angles(angles)) {
    rejected_hands_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  Target t;
  t.time_ns = time_ns;
  t.T_world_wrist = T_world_wrist;
  t.angles = angles;
  if (options_.remove_finger_abduction) {
    for (Finger f : {Finger::index, Finger::middle, Finger::ring, Finger::little}) t.angles[first_dof_of(f) + 1] = 0.0;
  }
  targets_[hand].publish(t);
}

void ServoLoop::engage(TimeNs now) noexcept {
  for (auto& g : gates_) g.engage(now);
}

void ServoLoop::disengage_and_zero(TimeNs now) noexcept {
  for (std::size_t i = 0; i < channels_.size(); ++i) {
    gates_[i].disengage();
    if (channels_[i].sink) channels_[i].sink->send(channels_[i].model->rest(), FingertipForce{}, false, now);
  }
}

void ServoLoop::tick(TimeNs now) noexcept {
  switch (output_request_.exchange(kRequestNone, std::memory_order_acq_rel)) {
    case kRequestOn: engage(now); break;
    case kRequestOff: disengage_and_zero(now); break;
    default: break;
  }
  if (colliders_.fetch(collider_scratch_)) {
    for (int k = 0; k < simulation_.collider_slot_count(); ++k) {
      const ColliderTable::Slot& slot = collider_scratch_.slots[static_cast<std::size_t>(k)];
      if (!slot.active || !simulation_.set_collider(k, slot.shape, slot.T_world_collider)) simulation_.remove_collider(k);
    }
  }
  const std::size_t hands = simulation_.hand_count();
  bool stale = false;
  for (std::size_t h = 0; h < hands; ++h) {
    Target target;
    if (targets_[h].fetch(target)) {
      simulation_.set_target(target.T_world_wrist, target.angles, h);
      last_target_ns_[h] = target.time_ns;
      have_target_[h] = true;
    }
    stale |= !have_target_[h] || now - last_target_ns_[h] > options_.tracked_hand_timeout_ns;
  }
  if (stale) stale_ticks_.fetch_add(1, std::memory_order_relaxed);
  const bool simulating = simulate_.load(std::memory_order_acquire);
  if (simulating) simulation_.step();

  ServoSnapshot& snap = scratch_;
  snap.simulating = simulating;
  snap.object_count = std::min(simulation_.free_object_count(), ServoSnapshot::kMaxObjects);
  for (std::size_t i = 0; i < snap.object_count; ++i) snap.object_poses[i] = simulation_.free_object_pose(i);
  snap.hand_count = hands;
  for (std::size_t h = 0; h < hands; ++h) {
    ServoSnapshot::Hand& sh = snap.hands[h];
    sh.side = simulation_.hand(h);
    for (std::size_t f = 0; f < kFingerCount; ++f) {
      const FingertipContact& tip = simulation_.fingertips(h)[f];
      sh.contact[f] = simulating ? tip.force : FingertipForce{};
      sh.on_pad[f] = simulating ? tip.on_pad : FingertipForce{};
      sh.contact_normal_n[f] = simulating ? tip.contact_normal_n : 0.0;
      sh.object_normal_n[f] = simulating ? tip.object_normal_n : 0.0;
    }
  }
  for (std::size_t i = 0; i < channels_.size(); ++i) {
    const ServoChannel& c = channels_[i];
    SafetyGate& gate = gates_[i];
    // The device presses on the pad: it gets the contacts as the pad feels
    // them, so a press on the tip's end is rendered, not read as a pull.
    // The scale is for simulated contact only: extra forces are newtons as asked.
    FingertipForce desired = scaled(snap.hands[c.hand].on_pad[static_cast<std::size_t>(c.finger)], options_.force_scale);
    if (extra_) {
      const FingertipForce e = extra_->force(i, now);
      desired.normal_n += e.normal_n;
      desired.shear_x_n += e.shear_x_n;
      desired.shear_z_n += e.shear_z_n;
    }
    if (!options_.haptics_enabled) desired = FingertipForce{};
    gate.command(desired, now);
    const FingertipForce out = gate.output(now);
    const bool enabled = gate.engaged();
    const MotorAngles motors = enabled ? c.model->inverse(out) : c.model->rest();
    if (c.sink) c.sink->send(motors, out, enabled, now);
    ServoSnapshot::Channel& sc = snap.channels[i];
    sc.finger = c.finger;
    sc.hand = c.hand;
    sc.commanded = out;
    sc.measured = c.sink ? c.sink->measured() : out;
    sc.motors = motors;
    sc.gate = gate.state();
    sc.connected = c.sink ? c.sink->connected() : false;
  }
  snap.time_ns = now;
  snap.tick = ticks_.fetch_add(1, std::memory_order_relaxed) + 1;
  for (std::size_t h = 0; h < hands; ++h) snap.hands[h].proxy = simulation_.proxy_pose(now, h);
  snapshots_.publish(snap);
}

void ServoLoop::record(std::array<std::atomic<std::uint32_t>, 4096>& histogram, DurationNs value_ns) noexcept {
  const auto bin = static_cast<std::size_t>(std::clamp<DurationNs>(value_ns / kBinNs, 0, 4095));
  histogram[bin].fetch_add(1, std::memory_order_relaxed);
}

Status ServoLoop::start() {
  if (running_.load(std::memory_order_acquire)) {
    return make_error(Errc::invalid_argument, "the servo loop is already running");
  }
  stop_requested_.store(false, std::memory_order_release);
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
  return {};
}

void ServoLoop::stop() {
  if (thread_.joinable()) {
    stop_requested_.store(true, std::memory_order_release);
    thread_.join();
  }
  running_.store(false, std::memory_order_release);
}

void ServoLoop::run() {
  if (options_.realtime_priority) {
    sched_param param{};
    param.sched_priority = options_.realtime_priority_level;
    const int err = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (err == 0) {
      realtime_.store(true, std::memory_order_relaxed);
    } else {
      logger().warn(
          "haptics: SCHED_FIFO refused ({}); the servo loop runs at normal priority with more jitter. "
          "Grant it with `ulimit -r 99` / CAP_SYS_NICE, or an rtprio entry in /etc/security/limits.conf",
          std::strerror(err));
    }
  }
  if (options_.engage_on_start) engage(clock_.now_ns());
  TimeNs deadline = clock_.now_ns() + options_.period_ns;
  while (!stop_requested_.load(std::memory_order_acquire)) {
    // Sleep to the absolute deadline. The Clock abstraction is CLOCK_MONOTONIC
    // in production; a test clock would make this wait meaningless, so the
    // thread always sleeps on the real clock's timeline.
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(deadline / kNsPerSecond);
    ts.tv_nsec = static_cast<long>(deadline % kNsPerSecond);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    const TimeNs woke = clock_.now_ns();
    const DurationNs late = woke - deadline;
    record(jitter_histogram_, late);
    if (late > jitter_max_ns_.load(std::memory_order_relaxed)) jitter_max_ns_.store(late, std::memory_order_relaxed);

    tick(woke);

    const TimeNs done = clock_.now_ns();
    const DurationNs took = done - woke;
    record(tick_histogram_, took);
    if (took > tick_max_ns_.load(std::memory_order_relaxed)) tick_max_ns_.store(took, std::memory_order_relaxed);
    deadline += options_.period_ns;
    if (done > deadline) {
      // Overrun: skip the missed deadlines rather than bursting to catch up.
      overruns_.fetch_add(1, std::memory_order_relaxed);
      const DurationNs behind = done - deadline;
      deadline += (behind / options_.period_ns + 1) * options_.period_ns;
    }
  }
  disengage_and_zero(clock_.now_ns());
}

ServoTiming ServoLoop::timing() const {
  ServoTiming t;
  t.ticks = ticks_.load(std::memory_order_relaxed);
  t.overruns = overruns_.load(std::memory_order_relaxed);
  t.stale_hand_ticks = stale_ticks_.load(std::memory_order_relaxed);
  t.rejected_hands = rejected_hands_.load(std::memory_order_relaxed);
  t.realtime = realtime_.load(std::memory_order_relaxed);
  const auto percentiles = [](const std::array<std::atomic<std::uint32_t>, 4096>& h, double& p50, double& p99) {
    std::uint64_t total = 0;
    for (const auto& b : h) total += b.load(std::memory_order_relaxed);
    if (total == 0) return;
    std::uint64_t seen = 0;
    bool have50 = false;
    for (std::size_t i = 0; i < h.size(); ++i) {
      seen += h[i].load(std::memory_order_relaxed);
      const double upper_us = static_cast<double>((i + 1) * kBinNs) / 1000.0;  // bin's upper edge: conservative
      if (!have50 && seen * 2 >= total) {
        p50 = upper_us;
        have50 = true;
      }
      if (seen * 100 >= total * 99) {
        p99 = upper_us;
        return;
      }
    }
  };
  percentiles(jitter_histogram_, t.jitter_p50_us, t.jitter_p99_us);
  percentiles(tick_histogram_, t.tick_p50_us, t.tick_p99_us);
  t.jitter_max_us = static_cast<double>(jitter_max_ns_.load(std::memory_order_relaxed)) / 1000.0;
  t.tick_max_us = static_cast<double>(tick_max_ns_.load(std::memory_order_relaxed)) / 1000.0;
  return t;
}

}  // namespace proprio::haptics
