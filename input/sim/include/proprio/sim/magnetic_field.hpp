#pragma once
// The magnetic field a glove's compasses sit in: the Earth's field plus point
// dipoles (magnets, motors, the fingertip haptic devices of the FTM glove, tools
// brought near the hand as in Lee 2021, Fig. 4.14). Ground truth only: what a
// magnetometer reads is ImuSimulator's business (imu_sim.hpp).
//
// A dipole of moment m (A·m²) at r from the point of interest gives
//
//   B(r) = μ0/4π · (3 (m·r̂) r̂ − m) / |r|³
//
// so on its axis |B| = 2·1e-7·|m|/r³ and in its equatorial plane half that.
// The moment is m_static + k·I(t): a permanent magnet plus the coil or motor
// term that scales with the current a caller sets per time (the haptic
// devices' motor currents; set_current() or a current function).
//
// Frames: world is OpenXR (+Y up). The Earth field is fixed by which world
// direction is geographic north (default −Z, "forward"); east = north × up.
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_pose.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio::sim {

// μ0/4π in T·m/A (CODATA 2018: μ0 = 1.25663706212e-6 N/A²).
inline constexpr double kMu0Over4Pi = 1.00000000055e-7;

// The geomagnetic field, uniform over the room.
struct EarthFieldOptions {
  // Total intensity and inclination (dip, positive = the field points below
  // the horizon, as in the northern hemisphere). 50 µT and 64° are rounded
  // central-European values (IGRF/WMM give about 48-50 µT and 63-66° between
  // Munich and Berlin; the brief asked for "~60°"; we took the value of the
  // southern German cities). Declination +3° (east of true north), also
  // central Europe. These are round figures, not a model evaluation for a date.
  double magnitude_T = 50e-6;
  double inclination_rad = deg_to_rad(64.0);
  double declination_rad = deg_to_rad(3.0);
  Vec3 north_world = Vec3(0.0, 0.0, -1.0);  // geographic north; unit, horizontal (⊥ +Y)

  // Errc::invalid_argument naming the field.
  Status validate() const;
  std::string describe() const;
};

// The Earth field vector in world coordinates (tesla).
Vec3 earth_field_world_T(const EarthFieldOptions& o);
// Dip of a field vector below the horizontal plane (world +Y up), rad in [−π/2, π/2].
double inclination_of(const Vec3& field_world);

// Field of a point dipole of moment m_world (A·m²) at displacement r_m = point − dipole
// (metres, same frame). Zero at r = 0 (undefined there); callers clamp |r|.
Vec3 dipole_field_T(const Vec3& m_world_Am2, const Vec3& r_m);

using CurrentFunction = std::function<double(TimeNs)>;  // amperes at t
using PoseFunction = std::function<Pose(TimeNs)>;       // T_world_dipole at t

struct MagneticDipole {
  std::string name;  // for describe() and error messages
  // Moment in the dipole's own frame: permanent part, and per ampere of current.
  Vec3 moment_static_Am2 = Vec3::Zero();
  Vec3 moment_per_current_Am2_per_A = Vec3::Zero();
  // Where it is: on a segment of the simulated hand (moves with it; the pose
  // comes from the HandPose given to field_world_T), or in the world along
  // T_world_dipole (a fixed pose or a script such as ScriptedApproach).
  std::optional<HandJoint> attached_to;
  Pose T_joint_dipole;          // used when attached_to is set
  PoseFunction T_world_dipole;  // used otherwise; required then
  // Current when no set_current() value applies yet; empty = 0 A.
  CurrentFunction current_A;
  // A real magnet or motor is not a point: closer than this the field is
  // evaluated at this distance (same direction), so it stays finite.
  double min_distance_m = 1e-3;
};

// A straight approach, hold and retreat of an object, minimum-jerk in
// position (10s³ − 15s⁴ + 6s⁵) and slerped in rotation. Before t_start it sits
// at far; after the retreat it is back at far.
struct ScriptedApproach {
  Pose T_world_far;
  Pose T_world_near;
  TimeNs t_start_ns = 0;
  DurationNs approach_ns = 2 * kNsPerSecond;
  DurationNs hold_ns = 2 * kNsPerSecond;
  DurationNs retreat_ns = 2 * kNsPerSecond;
  Pose operator()(TimeNs t) const;
};

// ---- Presets. The moments are order-of-magnitude estimates, not measurements;
// the thesis (Lee 2021, Fig. 4.14) shows these objects disturbing the compass
// but gives no field values. Each preset's dipole axis is its own +Z.

// The 10 mm rule (Lee 2021, §3.2.1 and Fig. 3.6: interference between the
// fingertip device's DC micromotors and an IMU "is only significant if the
// distance is less than one centimeter"; safe distance "above 10 [mm]").
inline constexpr double kHapticSafeDistance_m = 0.010;
// What "significant" means here (our choice; the thesis gives no threshold):
// a disturbance of 10 % of the Earth field, 5 µT. That is well above the
// compass's noise and quantisation (0.3 µT, 0.15 µT/LSB) and above the ~1 %
// residual of a hard/soft-iron calibration, and it would turn a heading by up
// to 13° against the 22 µT horizontal component at 64° dip, so a smaller
// threshold would not call 10 mm "safe".
inline constexpr double kSignificantDisturbance_T = 5e-6;

// Options of the fingertip device's dipole.
struct HapticDeviceDipoleOptions {
  // Sized from the two constants above: on the axis (the worst direction),
  // |B| = 2·1e-7·|m|/r³ = 5 µT at r = 10 mm gives |m| = 5e-6·(1e-2)³/2e-7 =
  // 2.5e-5 A·m² at full current. 80 % of it is taken as the motors'
  // permanent magnets and 20 % as the windings at full current (0.5 A, a
  // stalled 6 mm micromotor, our assumption), so the device disturbs more while
  // it pushes. By the r⁻³ law that is 40 µT at 5 mm and 0.6 µT at 20 mm.
  // CAUTION: at the FTM's own compasses (proximal phalanges, ~6 cm from the
  // tip) this moment gives ~0.02 µT, invisible; yet Fig. 4.14-D shows the
  // devices disturbing those compasses strongly, and a single 2 mm NdFeB cube
  // (~8e-3 A·m²) alone would be ~300x this moment. The 10 mm rule and Fig.
  // 4.14-D do not agree; scale these two moments for a disturbance scenario.
  double moment_static_Am2 = 2.0e-5;
  double moment_per_current_Am2_per_A = 1.0e-5;
  double full_current_A = 0.5;
  // The device on the tip segment: 8 mm out of the back of the finger
  // (joint +Y) over the nail, where the motors of a 3-DOF device sit; axis
  // along the finger (joint +Z). Our choice, not the thesis's drawing.
  Pose T_tip_device{Quat::Identity(), Vec3(0.0, 0.008, 0.0)};
};
// A dipole on `tip` (e.g. HandJoint::index_tip) sized by the 10 mm rule; its
// current comes from set_current() (the haptics emulator) or `current`.
MagneticDipole haptic_device_dipole(HandJoint tip, const HapticDeviceDipoleOptions& o = {},
                                    CurrentFunction current = {});

// A cordless hand drill: a brushed DC motor with two ferrite arc magnets
// (remanence ~0.4 T, ~6 cm³ together: M·V = 0.4/μ0·6e-6 ≈ 1.9 A·m²), about
// half of it closed by the steel can: 1 A·m² static. The armature adds
// ~0.05 A·m² per ampere (a few amperes running free). 200 µT at 10 cm on axis.
MagneticDipole drill_dipole(PoseFunction T_world_drill, CurrentFunction current = {});
// A handheld fan: a small outrunner BLDC motor whose multipole NdFeB rotor
// mostly cancels; 0.05 A·m² static net, 0.02 A·m² per ampere (~0.5 A).
// 10 µT at 10 cm on axis.
MagneticDipole fan_dipole(PoseFunction T_world_fan, CurrentFunction current = {});
// An earbud case: several small NdFeB magnets (lid catch, bud retention), each
// ~5×5×2 mm (Br 1.3 T: 0.05 A·m²), partly opposed: 0.1 A·m² net, no current.
// 160 µT at 5 cm on axis.
MagneticDipole earphone_case_dipole(PoseFunction T_world_case);

// The supply leads of a hand-worn device (issue 27; what the 10 mm dipole
// alone misses: Lee 2021 Fig. 4.14-D shows the fingertip devices disturbing
// the thumb-metacarpal and index-proximal compasses, ~6 cm from the
// devices). A pair of straight conductors per bone, supply and return, each
// carrying the device's current the opposite way, Biot–Savart per finite
// segment:
//
//   B = μ0 I / (4π d) · (cos θ1 − cos θ2) · (u × d̂)
//
// (d the distance to the segment's line, θ1, θ2 the angles to its ends).
// Far from a pair (r ≫ s) the two nearly cancel and |B| ≈ μ0 I s / (2π r²):
// 0.5 A, s = 1 mm at r = 9 mm gives 1.2 µT, some 100 times the device
// dipole's 10 mm-rule field there. ASSUMED geometry (the thesis shows no
// wiring): the leads run from the wrist along the back of the finger to its
// tip, p_joint_offset_m off each joint's origin (in that joint's frame: +X
// lateral, +Y dorsal), the return conductor separation_m further along the
// joint's +X (a flat two-core cable lying on the glove), not twisted (a
// twisted pair would cancel far more).
struct CurrentLeadPair {
  std::string name;
  std::vector<HandJoint> path;  // >= 2 joints, wrist to tip
  Vec3 p_joint_offset_m = Vec3(0.006, 0.006, 0.0);
  double separation_m = 0.001;
  // The current: that dipole's (set_current() or its function), e.g. the
  // device the leads feed; or current_A when not set.
  std::optional<std::size_t> current_of_dipole;
  CurrentFunction current_A;
  double min_distance_m = 1e-3;  // closer than this to a conductor, evaluated at this distance
};
// Field of a straight conductor from a to b (current along a→b) at p.
Vec3 segment_field_T(const Vec3& a, const Vec3& b, double amperes, const Vec3& p, double min_distance_m = 1e-3);
// The leads of the device on `tip`'s finger: wrist, metacarpal (not for the
// thumb), proximal, (intermediate,) distal, tip.
CurrentLeadPair fingertip_device_leads(HandJoint tip, std::optional<std::size_t> current_of_dipole);

// A pose that never changes, for fixed objects.
PoseFunction fixed_pose(const Pose& T_world_object);

// The Earth field plus dipoles. Copyable; not thread-safe. A simulator reads
// it through a shared_ptr while its owner may still call set_current()
// between ticks.
class MagneticEnvironment {
 public:
  // Validates the Earth options (Errc::invalid_argument naming the field).
  static Result<MagneticEnvironment> create(EarthFieldOptions earth = {});
  MagneticEnvironment() : MagneticEnvironment(EarthFieldOptions{}) {}

  // Returns the dipole's index. Errc::invalid_argument when it has no place
  // (neither attached_to nor T_world_dipole), a non-finite moment or a
  // min_distance_m <= 0.
  Result<std::size_t> add_dipole(MagneticDipole dipole);

  // From from_ns on (until a later set_current), dipole `index` carries
  // current_A. Calls may come in any time order. Before the first such time
  // the dipole's current function (or 0 A) applies.
  Status set_current(std::size_t index, TimeNs from_ns, double amperes);
  // Errc::invalid_argument: a path under 2 joints, a separation or minimum
  // distance <= 0, or a current_of_dipole that does not exist.
  Result<std::size_t> add_lead_pair(CurrentLeadPair leads);
  std::size_t lead_pair_count() const noexcept { return leads_.size(); }
  // One lead pair's field (zero without an active hand).
  Vec3 lead_field_world_T(std::size_t index, const Vec3& p_world, TimeNs t, const HandPose* hand) const;
  double current_A(std::size_t index, TimeNs t) const;

  // Total field (Earth + every dipole) at p_world at time t, tesla, world
  // frame. Dipoles attached to the hand need `hand` (the simulated hand at t);
  // with hand == nullptr (or an inactive hand) they are left out.
  Vec3 field_world_T(const Vec3& p_world, TimeNs t, const HandPose* hand = nullptr) const;
  // The dipoles' and lead pairs' part alone.
  Vec3 disturbance_world_T(const Vec3& p_world, TimeNs t, const HandPose* hand = nullptr) const;
  // One dipole's field; also its world pose at t (nullopt: attached, no hand).
  Vec3 dipole_field_world_T(std::size_t index, const Vec3& p_world, TimeNs t, const HandPose* hand = nullptr) const;
  std::optional<Pose> dipole_pose_world(std::size_t index, TimeNs t, const HandPose* hand = nullptr) const;

  Vec3 earth_field_world_T() const noexcept { return earth_world_T_; }
  const EarthFieldOptions& earth() const noexcept { return earth_; }
  std::size_t dipole_count() const noexcept { return dipoles_.size(); }
  const MagneticDipole& dipole(std::size_t index) const { return dipoles_.at(index); }
  std::string describe() const;

 private:
  EarthFieldOptions earth_;
  Vec3 earth_world_T_ = Vec3::Zero();
  std::vector<MagneticDipole> dipoles_;
  std::vector<CurrentLeadPair> leads_;
  // Per dipole: (from_ns, amperes), sorted by time.
  std::vector<std::vector<std::pair<TimeNs, double>>> schedules_;

  explicit MagneticEnvironment(EarthFieldOptions earth);
};

}  // namespace proprio::sim
