#pragma once
// The Hall-sensor joint of thesis Fig. 3.5, simulated with ground truth.
//
// Frames (shafts along +z; see joint_kinematics.hpp):
//   inlet  I : the inlet shaft, origin on its face;
//   yoke1  Y1 = I * Rz(twist_in): the inlet twist ring and the Cardan joint's
//              first yoke, which turn together;
//   yoke2  Y2 = Y1 * Rx(bend_x) * Ry(bend_y), origin at the Cardan centre
//              (z = length_in in Y1): the outgoing shaft's base;
//   outlet O  = Y2 * Rz(twist_out), origin on the outlet face (z = length_out
//              in Y2).
//
// Both twist rings are modelled (the thesis's joint); for a kind with one ring
// (JointKind::twist_rings = 1) the caller commands the missing ring's twist
// to 0.
//
// Sensing (three sensor sites per joint, as in the thesis):
//   bend: an axial magnet (moment along Y1's z) at the Cardan centre and a 2-D
//     Hall sensor on Y2's axis, kBendSensorDistanceM beyond the centre,
//     measuring the field along Y2's x and y. Ideally B_x ~ sin(bend_y)
//     cos(bend_x), B_y ~ -sin(bend_x). The thesis puts the magnet "into the
//     cross-shaft"; a magnet that turned with the cross about the first hinge
//     would show a sensor on the outgoing shaft only the second hinge's angle,
//     so we read it as held by the first yoke through the ring-shaped cross's
//     bore (the cross turns around it).
//   twist: a diametrical disc magnet on each ring's axis and 1-D Hall elements
//     at radius kTwistSensorRadiusM in its plane, measuring the radial field,
//     which goes as cos(angle). One element is two-valued over a turn and,
//     near its peaks, loses resolution (at 12 bits and this field, about 2 deg
//     at a peak: sqrt(2 LSB / amplitude)), so each twist site carries a pair of elements
//     90 deg apart around the ring (a quadrature pair, as magnetic rotary
//     encoders do) and the angle comes from both: the thesis's "1D Hall
//     sensor" per ring is, here, a two-element 1-D sensor. Inlet ring: magnet
//     in Y1, elements on I. Outlet ring: magnet on O, elements on Y2.
//
// The field at each element is the sum of point dipoles (this joint's three
// magnets and any neighbours' given in the environment) plus a uniform
// ambient field, projected on the element's sensitive axis. Each element is a
// ratiometric linear Hall sensor read by a 12-bit ADC: counts = round((Vcc/2 +
// offset + S B + noise) / Vcc * 4096), clamped to 0..4095, averaged over
// kOversampling conversions (the firmware's 20 ms report leaves time for it;
// the noise dithers the quantisation).
//
// Manufacturing errors are drawn per joint from its seed: magnet tilt, offset
// and strength; element placement, axis tilt, sensitivity and offset.
// Mechanical stops: a Cardan joint's yokes touch when the angle between the
// shafts reaches a limit, whichever hinge bends, so JointKind::bend_limit_rad
// bounds each hinge and also the shaft angle acos(cos bend_x cos bend_y).
// That second stop matters for sensing too: the 2-D sensor sees the magnet's
// axis projected on its plane, sin(shaft angle) long, which stops changing as
// the shaft angle nears 90 deg (both hinges at 80 deg make 88 deg), and
// magnet and sensor offsets fold it (two bend pairs, one reading) short of
// 90: with this file's tolerances, inside 75-80 deg for some joints. The
// default kit's stops are at 70 deg (kit.hpp).
// Mechanics: each of the four angles goes through a play (backlash) operator
// whose width is the hinge's backlash plus the stick-slip band of its friction:
// the shaft stops up to half the width short of where the hand or the jig
// pushed it, on the side it came from.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"
#include "proprio/rig_device/kit.hpp"

namespace proprio::rig_device {

// --- Named constants (SI units; the source of each is in its comment) --------

// mu0 / 4 pi, T m / A (SI definition; exact to 1e-10 after the 2019 redefinition).
inline constexpr double kMu0Over4Pi = 1e-7;
// Remanence of sintered NdFeB grade N42, T (1.28..1.32 T in grade tables).
inline constexpr double kNdFeBRemanenceT = 1.3;
// Bend magnet: axial cylinder 4 mm diameter x 3 mm (a stock size that fits
// a ~8 mm ring-shaped cross); moment = Br V / mu0 = 0.039 A m^2. What limits
// the bends' accuracy is not the magnet's strength but the ratio of its field
// to fields the calibration cannot know (Earth's, the neighbours' magnets,
// which scale with the same magnet size), so the sensor sits as close to the
// magnet as the cross allows: these errors fall as the distance cubed.
inline constexpr double kBendMagnetDiameterM = 4e-3;
inline constexpr double kBendMagnetLengthM = 3e-3;
// Twist magnets: diametrically magnetised discs 3 mm x 2 mm (stock size).
inline constexpr double kTwistMagnetDiameterM = 3e-3;
inline constexpr double kTwistMagnetThicknessM = 2e-3;
// Geometry (our design within the kit's 30 mm shafts): 2-D sensor 4.8 mm past
// the Cardan centre (the magnet's half length plus 3.3 mm for the cross's
// ring and the package; transverse field up to 35 mT there); elements 4 mm
// from the ring axis (disc radius 1.5 mm plus a package; radial field 46 mT).
inline constexpr double kBendSensorDistanceM = 4.8e-3;
inline constexpr double kTwistSensorRadiusM = 4e-3;
// Inlet ring 10 mm in from the inlet face; outlet ring 18 mm past the Cardan
// centre (13 mm from the 2-D sensor): each ring's neighbour magnets are
// >= 22 mm away.
inline constexpr double kTwistInRingFromInletM = 10e-3;
inline constexpr double kTwistOutRingFromCardanM = 18e-3;

// Hall elements: ratiometric linear sensors at Vcc = 3.3 V, quiescent Vcc/2.
inline constexpr double kSupplyV = 3.3;
// Sensitivities of ratiometric linear Hall grades at 3.3 V (DRV5055-like:
// A2 30 mV/mT, +-42 mT; A3 15 mV/mT, +-85 mT), chosen so each signal fills
// most of the ADC's range: A2 for the 2-D bend sensor, A3 for the twist
// elements.
inline constexpr double kBendSensitivityVPerT = 30.0;
inline constexpr double kTwistSensitivityVPerT = 15.0;
// Input-referred noise, T rms per conversion: ~130 nT/sqrt(Hz) over the
// ~20 kHz bandwidth (DRV5055 datasheet, typical).
inline constexpr double kHallNoiseT = 18e-6;
// 12-bit ADC (the thesis's microcontrollers), full scale = Vcc.
inline constexpr int kAdcBits = 12;
inline constexpr int kAdcMaxCount = (1 << kAdcBits) - 1;
// Conversions averaged per channel and report: 6 x 64 at ~10 us fit the 20 ms
// report period; the noise (0.3 LSB) dithers the quantisation away.
inline constexpr int kOversampling = 64;

// Manufacturing spread (1 sigma unless said): magnet tilt in its pocket 2 deg,
// offset 0.05 mm per axis (a reamed pocket), strength 3 % (grade tolerance);
// element placement 0.05 mm per axis (pick-and-place plus the die's place in
// its package), sensitive-axis tilt 1 deg, sensitivity 2.5 %, quiescent
// offset 5 mV (DRV5055-like). The offsets matter most: a magnet-to-sensor
// offset d mixes about 3 d / kBendSensorDistanceM of the axial field into the
// transverse reading, which folds the 2-D reading (two bend pairs, one
// reading) short of a 90 deg shaft angle; at 0.1 mm sigma some joints fold
// inside 75 deg (measured, see the report of issue 31).
inline constexpr double kMagnetTiltSigmaRad = 2.0 * M_PI / 180.0;
inline constexpr double kMagnetOffsetSigmaM = 0.05e-3;
inline constexpr double kMagnetStrengthSigma = 0.03;
inline constexpr double kSensorPlacementSigmaM = 0.05e-3;
inline constexpr double kSensorAxisTiltSigmaRad = 1.0 * M_PI / 180.0;
inline constexpr double kSensitivitySigma = 0.025;
inline constexpr double kSensorOffsetSigmaV = 5e-3;
// Play per axis, rad: backlash uniform in 0.05..0.15 deg (a 3-D printed hinge
// with a reamed pin) plus a friction band of 0.05 deg.
inline constexpr double kBacklashMinRad = 0.05 * M_PI / 180.0;
inline constexpr double kBacklashMaxRad = 0.15 * M_PI / 180.0;
inline constexpr double kFrictionBandRad = 0.05 * M_PI / 180.0;
// Earth's field magnitude at mid latitudes, T (~25..65 uT worldwide).
inline constexpr double kEarthFieldT = 50e-6;
// The calibration jig stands in a mu-metal box: one layer attenuates a static
// field ~50x, leaving ~1 uT. (Unshielded, Earth's field in the jig turns with
// the inlet twist, which the map does not model, and costs ~0.2 deg p99.)
inline constexpr double kShieldedJigFieldT = 1e-6;

// Dipole field at r from a point moment m (both in one frame): mu0/4pi
// (3 r (m.r) / |r|^5 - m / |r|^3). Zero at r = 0.
Vec3 dipole_field_t(const Vec3& moment_am2, const Vec3& r_m);

// Moment of a uniformly magnetised volume, A m^2.
double magnet_moment_am2(double remanence_t, double volume_m3);

// A 12-bit ratiometric read of one element: field along its axis -> counts.
int adc_counts(double field_t, double sensitivity_v_per_t, double offset_v, double noise_t, Rng& rng);

// The bends pulled back to the stops: each hinge to +-limit, then both
// scaled down together until the shaft angle is within the limit.
void clamp_bends_to_stops(double& bend_x_rad, double& bend_y_rad, double limit_rad);
// The angle between the inlet and outgoing shafts, rad.
double shaft_angle_rad(double bend_x_rad, double bend_y_rad);

struct Magnet {
  Vec3 p_m = Vec3::Zero();
  Vec3 moment_am2 = Vec3::Zero();
};
// Re-expresses magnets given in frame b in frame a.
std::vector<Magnet> transform_magnets(const Pose& T_a_b, const std::vector<Magnet>& magnets_in_b);
// For an emulated device: the other modules' magnets (all in one device
// frame) as one joint's environment sees them, in its inlet frame, keeping
// those within radius_m of the inlet (a joint is 60 mm long; at 0.15 m the
// strongest magnet here adds ~1 nT, far below one ADC count). The caller
// leaves the joint's own magnets out.
std::vector<Magnet> neighbour_magnets_in_inlet(const Pose& T_device_inlet, const std::vector<Magnet>& magnets_device,
                                               double radius_m = 0.15);

// Six channels, each the mean of kOversampling ADC conversions (counts, 0..4095).
struct HallReadings {
  std::array<double, 2> bend{};       // 2-D sensor: Y2's x, y
  std::array<double, 2> twist_in{};   // inlet ring elements at 0 and 90 deg
  std::array<double, 2> twist_out{};  // outlet ring elements at 0 and 90 deg
};

struct JointEnvironment {
  Quat q_world_inlet = Quat::Identity();  // the inlet's orientation, for the ambient field
  Vec3 ambient_field_world_t = Vec3::Zero();
  std::vector<Magnet> neighbour_magnets_inlet;  // other modules' magnets, in this joint's inlet frame
};

// Which disturbances a simulated joint has; all on is the realistic joint.
struct HallJointOptions {
  JointKind kind;
  bool manufacturing_errors = true;
  bool noise = true;
  bool backlash = true;  // play and friction
  std::uint64_t seed = 1;

  Status validate() const;
  std::string describe() const;
};

// The as-built element and magnet geometry one seed gives (simulator-only).
struct Element {
  Vec3 p_m;          // in the frame it is mounted in
  Vec3 axis;         // sensitive axis, unit
  double sensitivity_v_per_t;
  double offset_v;
};

class HallJoint {
 public:
  static Result<HallJoint> create(const HallJointOptions& options);

  // The hand (or jig) pushes towards `commanded`; the shafts follow through
  // the play operator. Bends are held inside the stops. Returns nothing:
  // what the joint actually did is ground truth (actual_angles()).
  void move_to(const JointAngles& commanded);
  // Ground truth, for evaluation only.
  const JointAngles& actual_angles() const { return actual_; }

  // One 20 ms report of the six channels at the current actual angles.
  HallReadings read(const JointEnvironment& environment, Rng& rng) const;

  // This joint's three magnets at its actual angles, in its inlet frame (for
  // an emulator that places neighbours), and the inlet -> outlet transform.
  std::vector<Magnet> magnets_in_inlet() const;
  Pose T_inlet_outlet() const;

  const HallJointOptions& options() const { return options_; }

 private:
  HallJoint() = default;
  HallJointOptions options_;
  // As built, in their mounting frames: magnets {twist_in: Y1, bend: Y1, twist_out: O}.
  Magnet twist_in_magnet_, bend_magnet_, twist_out_magnet_;
  std::array<Element, 2> bend_elements_{};       // in Y2
  std::array<Element, 2> twist_in_elements_{};   // in I
  std::array<Element, 2> twist_out_elements_{};  // in Y2
  std::array<double, 4> play_width_rad_{};       // twist_in, bend_x, bend_y, twist_out
  JointAngles actual_;
};

// --- The calibration jig (simulator side) -----------------------------------
// A real jig holds the joint at angles it knows (its own encoders) and logs
// the joint's reports; it knows nothing of magnets. Our jig visits a grid of
// bend pairs over the kind's limits in a serpentine, then the same grid in
// reverse (so each point is approached from both sides and the play averages
// out; points past the shaft-angle stop are pulled back to it), with both twists stepped by golden-ratio increments so every twist
// angle meets every bend.
struct JigOptions {
  int bend_grid = 15;        // points per hinge, 3..41
  int reports_per_pose = 1;  // 20 ms reports averaged at each pose, 1..64

  Status validate() const;
  std::string describe() const;
};

struct JigSample {
  JointAngles jig_angles;  // what the jig commanded (the only angles a real jig knows)
  HallReadings readings;
};

// Runs the jig on `joint` in a quiet lab: no neighbours, the ambient field
// at a fixed direction (the jig does not turn the inlet).
Result<std::vector<JigSample>> run_calibration_jig(HallJoint& joint, const JigOptions& options,
                                                   const Vec3& ambient_field_world_t, Rng& rng);

}  // namespace proprio::rig_device
