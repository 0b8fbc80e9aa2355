#pragma once
// The 1 kHz haptic servo loop. Each tick it:
//   1. takes the newest tracked hands from their mailboxes (any thread submits
//      them; one or two hands, as the contact simulation has proxies),
//   2. steps the contact simulation (proxy hands under virtual coupling, both
//      in one world) unless it is switched off (forces only),
//   3. reads each fingertip's contact force, as its pad feels it
//      (FingertipContact::on_pad: a press on the tip's end is pad pressure),
//   4. adds what an ExtraForces source asks for (an app's own forces and
//      vibrations, through the OpenXR layer), scales, and passes the sum
//      through that device's safety gate (clamp, rate limit, ramp-in,
//      watchdog, NaN -> zero),
//   5. maps it to motor angles with the device model, and
//   6. hands both to the device's sink (HID driver or emulator).
// Nothing in a tick allocates, locks or throws. The proxy pose and the
// forces go out through a mailbox for rendering and logging.
//
// Timing: the thread sleeps to absolute deadlines (clock_nanosleep on
// CLOCK_MONOTONIC) and asks for SCHED_FIFO when allowed; a busy-waiting
// real-time thread trips the kernel's RT throttling, and without RT priority
// it still runs, just with more jitter (docs/platform-notes.md). It records
// wake-up lateness (jitter), tick duration and overruns.
//
// Shutdown: stop() (and the destructor) disengage every gate and send zero
// force to every device before returning.
#include <array>
#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/safety.hpp"

namespace proprio::haptics {

// Where one fingertip device's commands go.
class FingertipSink {
 public:
  virtual ~FingertipSink() = default;
  // Servo thread, every tick: must not block, allocate or throw. `force` is
  // what the gate let through (already renderable), `motors` its motor angles
  // under the device model; `enabled` is false when the gate is disengaged.
  virtual void send(const MotorAngles& motors, const FingertipForce& force, bool enabled, TimeNs now) noexcept = 0;
  // What the device reports it renders (force sensors), when it can; else the
  // last command.
  virtual FingertipForce measured() const noexcept = 0;
  virtual bool connected() const noexcept = 0;
  virtual std::string describe() const = 0;
};

struct ServoChannel {
  Finger finger = Finger::index;
  std::shared_ptr<const FingertipDeviceModel> model;
  std::shared_ptr<FingertipSink> sink;  // null: computed and published, sent nowhere
  // Which proxy of the contact simulation the finger belongs to
  // (ContactSimulation::hand_index; 0 with one hand).
  std::size_t hand = 0;
};

inline constexpr std::size_t kMaxServoChannels = kMaxProxyHands * kFingerCount;

// Forces added to the contact forces before a channel's gate: an app's own
// forces, vibrations. Servo thread, every tick and channel: must not block,
// allocate or throw. A non-finite force faults that channel's gate (zero).
class ExtraForces {
 public:
  virtual ~ExtraForces() = default;
  virtual FingertipForce force(std::size_t channel, TimeNs now) noexcept = 0;
};

// The kinematic colliders of the simulation's slots, as one table: whoever
// owns them (one thread) publishes the whole table when any changes.
struct ColliderTable {
  struct Slot {
    bool active = false;
    ColliderShape shape;
    Pose T_world_collider;
  };
  std::array<Slot, kMaxColliderSlots> slots{};
};

struct ServoLoopOptions {
  DurationNs period_ns = kNsPerMillisecond;
  bool realtime_priority = true;  // SCHED_FIFO if the OS allows; otherwise a warning and normal priority
  int realtime_priority_level = 80;
  // A tracked hand older than this is stale: the proxy keeps its last target
  // (it does not fly off), and ticks are counted as stale.
  DurationNs tracked_hand_timeout_ns = 200 * kNsPerMillisecond;
  // Study conditions (Lee 2021 §3.3.3): "without AA" removes the fingers'
  // ab/adduction before coupling (the thumb's CMC keeps it: without it there
  // is no opposition); "without haptics" sends zero force while the
  // simulation runs unchanged.
  bool remove_finger_abduction = false;
  bool haptics_enabled = true;
  // Rendered force = force_scale x simulated contact force (+ extra forces, unscaled), before the
  // safety gate's clamps. A fingertip device presses at most a couple of
  // newtons, so a task whose forces matter up to 5 N is scaled into the
  // device's range; at 1 everything above max_normal_n feels the same.
  double force_scale = 1.0;
  // Engage the gates (ramp-in) when the loop starts.
  bool engage_on_start = true;

  std::string describe() const;
  Status validate() const;
};

struct ServoSnapshot {
  TimeNs time_ns = 0;
  std::uint64_t tick = 0;
  // Per proxy hand, in the simulation's order.
  struct Hand {
    Handedness side = Handedness::right;
    HandPose proxy;  // the rendered hand
    std::array<FingertipForce, kFingerCount> contact{};  // the simulation's (filtered) fingertip forces
    std::array<FingertipForce, kFingerCount> on_pad{};   // FingertipContact::on_pad: what the devices are sent (before scale and gate)
    std::array<double, kFingerCount> contact_normal_n{};  // FingertipContact::contact_normal_n
    std::array<double, kFingerCount> object_normal_n{};   // FingertipContact::object_normal_n
  };
  std::array<Hand, kMaxProxyHands> hands{};
  std::size_t hand_count = 0;
  bool simulating = true;  // false: the simulation was switched off (contact forces zero)
  struct Channel {
    Finger finger = Finger::index;
    std::size_t hand = 0;
    FingertipForce commanded;  // after the safety gate
    FingertipForce measured;   // what the sink reports
    MotorAngles motors;
    GateState gate = GateState::disengaged;
    bool connected = false;
  };
  std::array<Channel, kMaxServoChannels> channels{};
  std::size_t channel_count = 0;
  // Free objects' poses, in ContactSimulation::free_object_name order (the
  // renderer and a study's rules read them while the loop owns the simulation).
  static constexpr std::size_t kMaxObjects = 16;
  std::array<Pose, kMaxObjects> object_poses{};
  std::size_t object_count = 0;
};

struct ServoTiming {
  std::uint64_t ticks = 0;
  std::uint64_t overruns = 0;  // a tick ended after the next deadline
  std::uint64_t stale_hand_ticks = 0;
  std::uint64_t rejected_hands = 0;  // inactive or non-finite submissions
  bool realtime = false;             // SCHED_FIFO granted
  // Wake-up lateness past each deadline, and tick durations (microseconds).
  double jitter_p50_us = 0, jitter_p99_us = 0, jitter_max_us = 0;
  double tick_p50_us = 0, tick_p99_us = 0, tick_max_us = 0;
  std::string describe() const;
};

class ServoLoop {
 public:
  static Result<std::unique_ptr<ServoLoop>> create(ContactSimulation simulation, std::vector<ServoChannel> channels,
                                                   ServoLoopOptions options = {},
                                                   const Clock& clock = MonotonicClock::instance());
  ~ServoLoop();  // stop()s
  ServoLoop(const ServoLoop&) = delete;
  ServoLoop& operator=(const ServoLoop&) = delete;

  // Any one producer thread per hand: the tracked hand (inverse kinematics
  // runs here, on the caller's thread, not in the loop). The pose's side
  // picks the proxy; poses of a side the simulation lacks, inactive or
  // non-finite poses are counted and dropped.
  void submit_tracked_hand(const HandPose& pose);
  void submit_tracked_hand(TimeNs time_ns, const Pose& T_world_wrist, const HandAngles& angles, std::size_t hand = 0);

  // Before start(): where extra forces come from (null: none).
  void set_extra_forces(std::shared_ptr<ExtraForces> extra) { extra_ = std::move(extra); }
  // Any thread: skip the contact simulation's step (its forces read zero)
  // while off; the channels still run (forces only). Takes effect next tick.
  void set_simulation_enabled(bool on) noexcept { simulate_.store(on, std::memory_order_release); }
  // Any thread: engage every gate (ramp-in) or disengage and zero them at
  // the next tick, e.g. when an app gains or loses input focus.
  void request_output(bool on) noexcept {
    output_request_.store(on ? kRequestOn : kRequestOff, std::memory_order_release);
  }
  // One producer thread: the colliders, applied at the next tick.
  void publish_colliders(const ColliderTable& table) { colliders_.publish(table); }

  // Starts the 1 kHz thread. Errc::invalid_argument if running.
  Status start();
  // Stops the thread, disengages every gate and sends zero to every device.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }

  // Without the thread: one tick at `now` (tests, benchmarks, offline runs
  // that step simulated time). Not while running.
  void tick(TimeNs now) noexcept;
  // Engage/disengage all gates (ramp-in on engage). Loop thread or, when not
  // running, the caller's.
  void engage(TimeNs now) noexcept;
  void disengage_and_zero(TimeNs now) noexcept;

  // Consumer thread (one): the newest snapshot, or nullptr before the first tick.
  const ServoSnapshot* latest() { return snapshots_.read(); }
  ServoTiming timing() const;
  // Owned by the loop; touch only while it is not running.
  ContactSimulation& simulation() noexcept { return simulation_; }
  SafetyGate& gate(std::size_t channel) noexcept { return gates_[channel]; }
  std::size_t channel_count() const noexcept { return channels_.size(); }
  const ServoLoopOptions& options() const noexcept { return options_; }

 private:
  struct Target {
    TimeNs time_ns = 0;
    Pose T_world_wrist;
    HandAngles angles{};
  };
  ServoLoop(ContactSimulation simulation, std::vector<ServoChannel> channels, ServoLoopOptions options,
            const Clock& clock);
  void run();
  void record(std::array<std::atomic<std::uint32_t>, 4096>& histogram, DurationNs value_ns) noexcept;
  static constexpr int kRequestNone = 0, kRequestOn = 1, kRequestOff = 2;

  ContactSimulation simulation_;
  std::vector<ServoChannel> channels_;
  std::vector<SafetyGate> gates_;
  ServoLoopOptions options_;
  const Clock& clock_;

  std::array<Mailbox<Target>, kMaxProxyHands> targets_;
  Mailbox<ServoSnapshot> snapshots_;
  Mailbox<ColliderTable> colliders_;
  ColliderTable collider_scratch_;
  ServoSnapshot scratch_;
  std::array<TimeNs, kMaxProxyHands> last_target_ns_{};
  std::array<bool, kMaxProxyHands> have_target_{};
  std::shared_ptr<ExtraForces> extra_;
  std::atomic<bool> simulate_{true};
  std::atomic<int> output_request_{kRequestNone};

  // 10 us bins up to 40.96 ms; the last bin collects everything beyond.
  std::array<std::atomic<std::uint32_t>, 4096> jitter_histogram_{};
  std::array<std::atomic<std::uint32_t>, 4096> tick_histogram_{};
  std::atomic<std::uint64_t> ticks_{0}, overruns_{0}, stale_ticks_{0}, rejected_hands_{0};
  std::atomic<std::int64_t> jitter_max_ns_{0}, tick_max_ns_{0};
  std::atomic<bool> realtime_{false};

  std::atomic<bool> running_{false};
  std::atomic<bool> stop_requested_{false};
  std::thread thread_;
};

// A sink that keeps what it was sent (for tests and display-only setups).
class RecordingSink final : public FingertipSink {
 public:
  void send(const MotorAngles& motors, const FingertipForce& force, bool enabled, TimeNs now) noexcept override;
  FingertipForce measured() const noexcept override { return last_force_; }
  bool connected() const noexcept override { return true; }
  std::string describe() const override { return "recording sink (no device)"; }
  MotorAngles last_motors() const noexcept { return last_motors_; }
  bool last_enabled() const noexcept { return last_enabled_; }
  TimeNs last_time() const noexcept { return last_time_; }
  std::uint64_t sends() const noexcept { return sends_; }

 private:
  MotorAngles last_motors_;
  FingertipForce last_force_;
  bool last_enabled_ = false;
  TimeNs last_time_ = 0;
  std::uint64_t sends_ = 0;
};

}  // namespace proprio::haptics
