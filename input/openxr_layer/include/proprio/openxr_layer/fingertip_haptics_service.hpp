#pragma once
// What the OpenXR layer asks of the fingertip devices behind
// XR_PROPRIO_fingertip_haptics and xrApplyHapticFeedback. The layer itself
// links none of it: the `haptics` plugin (input/hand_sources/plugins/haptics)
// implements this interface with the servo loop, the device models, their
// safety gates, the contact simulation (MuJoCo) and the device drivers, and is
// loaded only when a [haptics] table is configured. An app that never asks
// for haptics maps none of that.
//
// Threads: the per-frame calls (apply_forces, vibrate, move_collider,
// proxy_hand, report) may come from any app thread; they take a short lock
// that only app threads share (never the 1 kHz thread), and never allocate.
// The service's own threads: the 1 kHz servo loop and, while the contact
// simulation runs, a 250 Hz feeder that asks TrackedHandFeed for the hands.
#include <array>
#include <cstdint>
#include <string>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio::openxr_layer {

struct FingertipCapability {
  bool present = false;    // a device is configured on this finger
  bool connected = false;  // and answers now
  int force_dofs = 0;      // 1 normal only, 2 normal + one shear axis, 3 all
  double max_normal_n = 0.0, max_shear_n = 0.0, max_rate_n_per_s = 0.0, friction_coefficient = 0.0;
  DurationNs watchdog_ns = 0;
  std::string device;  // what it is, for people
};
using HandCapabilities = std::array<FingertipCapability, kFingerCount>;

enum class FingertipGate : std::uint8_t { off, ramping, active, faulted };

struct FingertipReport {
  FingertipGate gate = FingertipGate::off;
  bool connected = false;
  Vec3 commanded_in_tip = Vec3::Zero();  // N, fingertip frame (FingertipForce::in_tip_frame)
  Vec3 measured_in_tip = Vec3::Zero();
  Vec3 contact_in_tip = Vec3::Zero();
};
struct FingertipHapticsReport {
  TimeNs time_ns = 0;  // CLOCK_MONOTONIC, the tick that wrote it
  std::array<FingertipReport, kFingerCount> fingers{};
};

enum class ColliderKind : std::uint8_t { sphere, box, capsule, cylinder };
struct ColliderSpec {
  ColliderKind kind = ColliderKind::sphere;
  double radius_m = 0.05, half_length_m = 0.05;
  Vec3 half_extents_m = Vec3(0.05, 0.05, 0.05);
  double friction = 0.8;
};

// The tracked hands in the contact simulation's world, from the layer (its
// sources, bound to the app's world space). The feeder thread calls it.
class TrackedHandFeed {
 public:
  virtual ~TrackedHandFeed() = default;
  virtual bool tracked_hand(Handedness hand, TimeNs t_ns, HandPose& out_in_world) noexcept = 0;
};

class FingertipHapticsService {
 public:
  virtual ~FingertipHapticsService() = default;  // zero force on every device, then stop them

  // Per hand (left, right): what each finger has.
  virtual const std::array<HandCapabilities, 2>& capabilities() const noexcept = 0;
  virtual bool contact_allowed() const noexcept = 0;

  // Level 1: the force on each fingertip of `hand`, newtons in its fingertip
  // frame, held until replaced and faded to zero over each device's watchdog
  // period after `now`. A non-finite component zeroes that finger (its gate
  // faults until the next good force) and makes the call return false.
  virtual bool apply_forces(Handedness hand, const std::array<Vec3, kFingerCount>& f_in_tip, TimeNs now) noexcept = 0;
  // xrApplyHapticFeedback: a press on every device of `hand`, amplitude in
  // [0, 1], until now + duration.
  virtual void vibrate(Handedness hand, double amplitude, DurationNs duration, TimeNs now) noexcept = 0;
  virtual void stop_vibration(Handedness hand) noexcept = 0;
  // Forget every app force and vibration at once (the app's handle is gone).
  virtual void clear_app_forces() noexcept = 0;
  // Output on (the gates ramp in) or off (zero at the next tick, within a
  // millisecond): the app's focus and session state.
  virtual void set_output(bool on) noexcept = 0;

  // Level 2. start_contact: the simulation runs (both hands' proxies in one
  // world) with hands from `feed`, which must outlive stop_contact().
  virtual Status start_contact(TrackedHandFeed* feed) = 0;
  virtual void stop_contact() noexcept = 0;
  enum : int { kCollidersFull = -1, kBadCollider = -2 };
  // A collider id (>= 0), or kCollidersFull / kBadCollider.
  virtual int add_collider(const ColliderSpec& spec, const Pose& T_world_collider) noexcept = 0;
  virtual bool move_collider(int id, const Pose& T_world_collider) noexcept = 0;
  virtual void remove_collider(int id) noexcept = 0;
  // The proxy of `hand` in the simulation's world (false: no contact
  // simulation, or no proxy for that hand yet).
  virtual bool proxy_hand(Handedness hand, HandPose& out) noexcept = 0;

  // The newest tick's per-finger state (false before the first tick).
  virtual bool report(Handedness hand, FingertipHapticsReport& out) noexcept = 0;
  virtual std::string describe() const = 0;
};

}  // namespace proprio::openxr_layer
