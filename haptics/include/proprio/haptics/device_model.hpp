#pragma once
// Fingertip cutaneous device models: what a device can render, and the map
// between the force it presses on the fingertip (FingertipForce, fingertip
// frame) and its motors' output-shaft angles. Three kinds, each described by a
// TOML file (config/haptics/*.toml; equations and keys in
// docs/haptic-devices.md):
//   band_2dof     a belt over the pad wound by two pulleys (Minamizawa's
//                 "gravity grabber", the device of Lee 2021 ch. 2.2);
//   platform_3dof a plate under the pad pulled by three wires at 120 deg
//                 (after Prattichizzo, Chinello, Pacchierotti & Malvezzi 2013);
//   force_vector  a device with its own force control that takes the force.
//
// renderable(), inverse(), forward(), load_torques() and rest() run in the
// 1 kHz servo loop: they are noexcept and never allocate, lock or throw.
// Errors there are flags (ClampReason), never strings.
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/fingertip_device/fingertip_protocol.hpp"
#include "proprio/haptics/fingertip_force.hpp"

namespace proprio::haptics {

// The wire protocol carries at most this many motors; a model cannot drive more.
inline constexpr std::size_t kMaxDeviceMotors = devices::kFingertipMaxMotors;

// Output-shaft angles, rad, motor i in rad[i]; entries past motor_count() are
// unused and zero. (force_vector carries newtons here: see its model.)
struct MotorAngles {
  std::array<double, kMaxDeviceMotors> rad{};
};

// What a device may press on a fingertip. Every model's renderable() and the
// SafetyGate enforce these; a config cannot set them outside sane bounds
// (validate()).
struct DeviceLimits {
  double max_normal_n = 2.0;
  double max_shear_n = 1.0;
  double max_rate_n_per_s = 50.0;  // slew limit on each component
  // |shear| <= mu * normal: a cutaneous device cannot shear skin it does not press.
  double friction_coefficient = 0.9;
  double ramp_in_s = 0.4;
  DurationNs watchdog_ns = 50 * kNsPerMillisecond;

  Status validate() const;
  std::string describe() const;  // "normal<=2 N shear<=1 N mu=0.9 rate<=50 N/s ramp-in 0.4 s watchdog 50 ms"
};

// Which FingertipForce components a device renders at all.
struct ForceAxes {
  bool shear_x = true;
  bool shear_z = true;
};

// Why renderable() changed a force: bit flags, so the loop can count them
// without strings.
enum ClampReason : std::uint8_t {
  kClampNone = 0,
  kClampNonFinite = 1u << 0,        // a NaN or inf component: the whole force became zero
  kClampNormalNegative = 1u << 1,   // pulling on the pad: a device only presses
  kClampNormalMax = 1u << 2,        // normal above max_normal_n
  kClampShearMax = 1u << 3,         // |shear| above max_shear_n
  kClampFrictionCone = 1u << 4,     // |shear| above mu * normal
  kClampAxisDropped = 1u << 5,      // a shear component the device lacks was non-zero
};

// The clamp every model starts from: normal to [0, max], shear components the
// device lacks dropped, then shear magnitude to min(max_shear, mu * normal)
// with its direction kept. A non-finite force becomes zero. `reasons` (if not
// null) gets the ClampReason bits that applied.
FingertipForce clamp_to_limits(const FingertipForce& desired, const DeviceLimits& limits, ForceAxes axes,
                               std::uint8_t* reasons = nullptr) noexcept;

// The gearing between a motor and its output shaft, for drivers that count
// encoder ticks. A device without encoders (force_vector) has counts = 0.
struct MotorSpec {
  double gear_ratio = 1.0;                       // motor turns per output-shaft turn
  std::int64_t encoder_counts_per_motor_rev = 0;  // 0: no encoder (continuous)
  // Output-shaft angle per encoder count, rad; 0 when there is no encoder.
  double output_resolution_rad() const noexcept;
};

class FingertipDeviceModel {
 public:
  virtual ~FingertipDeviceModel() = default;
  virtual std::string_view kind() const noexcept = 0;  // "band_2dof", "platform_3dof", "force_vector"
  virtual std::size_t motor_count() const noexcept = 0;
  virtual const DeviceLimits& limits() const noexcept = 0;
  virtual ForceAxes axes() const noexcept = 0;
  virtual MotorSpec motor_spec() const noexcept = 0;
  // Clamp to what the device can render: normal to [0, max], shear magnitude to max and to the
  // friction cone, components the device lacks (the band has no shear_x) dropped. Direction kept.
  virtual FingertipForce renderable(const FingertipForce& desired) const noexcept = 0;
  // force -> motors. Clamps through renderable() first, so any input gives safe angles.
  virtual MotorAngles inverse(const FingertipForce& renderable_force) const noexcept = 0;
  // motors -> force. Non-finite angles give a non-finite force.
  virtual FingertipForce forward(const MotorAngles& q) const noexcept = 0;
  // Torque the fingertip's reaction puts on each output shaft at q (the emulator's load), N·m,
  // positive in the direction of positive shaft angle.
  virtual std::array<double, kMaxDeviceMotors> load_torques(const MotorAngles& q) const noexcept = 0;
  // Both at once, as the device emulator needs them at every physics substep;
  // models whose two share their kinematics compute it once.
  struct Plant {
    FingertipForce force;
    std::array<double, kMaxDeviceMotors> load_torques_nm{};
  };
  virtual Plant plant(const MotorAngles& q) const noexcept { return {forward(q), load_torques(q)}; }
  virtual MotorAngles rest() const noexcept = 0;  // zero rendered force (the band keeps its pretension)
  virtual std::string describe() const = 0;
};

// --- band_2dof ---------------------------------------------------------------
// A belt runs from pulley 0 on the proximal side (+Z, toward the wrist) down
// and under the pad to pulley 1 on the distal side. Take-up of pulley i is
// s_i = r * w_i * (q_i - q_i,rest), with w_i the winding direction (+1 or -1)
// mapping shaft angle to winding. Winding both in (equal take-up; opposite
// shaft rotations when w = [+1, -1], the thesis's Fig. 2.2) presses the pad:
// normal = N(s_0 + s_1) - N(0) from the calibrated table N; winding one in and
// the other out moves the belt along the pad: shear_z = k_t * (s_0 - s_1) / 2.
struct BandParams {
  struct Row {
    double takeup_m = 0.0;  // total take-up s_0 + s_1
    double normal_n = 0.0;  // force the belt presses on the pad (row 0: the pretension)
  };
  std::string name;
  std::vector<Row> force_table;  // strictly increasing in both columns, row 0 at take-up 0
  double shear_stiffness_n_per_m = 500.0;
  double pulley_radius_m = 0.004;
  std::array<double, 2> rest_angles_rad{};
  std::array<int, 2> winding_direction{{+1, -1}};
  MotorSpec motor;

  Status validate(const DeviceLimits& limits) const;
  std::string describe() const;
};
Result<std::unique_ptr<FingertipDeviceModel>> make_band_device(BandParams params, DeviceLimits limits);

// --- platform_3dof -----------------------------------------------------------
// A plate under the pad, translating without rotating, hung from three wires.
// Wire i leaves the plate at B_i = R_b (cos a_i, 0, sin a_i) (plate frame,
// origin at the plate's rest centre, axes of the fingertip frame) and runs to
// its pulley's exit point A_i = (R_a cos a_i, h, R_a sin a_i) on the static
// body. Winding shortens the wire: l_i = l_i,rest - r (q_i - q_i,rest). The
// plate displacement d (= its centre) presses the pad through the fingertip
// stiffness: normal = f_n(d.y) for d.y > 0 (else no contact, zero force),
// shear_x = k_x d.x, shear_z = k_z d.z.
struct PlatformParams {
  enum class NormalModel : std::uint8_t {
    linear,       // f_n(d) = k d
    exponential,  // f_n(d) = (b / m) (exp(m d) - 1): b the initial stiffness, m the stiffening rate
  };
  std::string name;
  double plate_radius_m = 0.007;   // R_b
  double anchor_radius_m = 0.017;  // R_a
  double anchor_height_m = 0.005;  // h, above the plate's rest position along +Y
  // a_i, from +X toward +Z: 90, 210, 330 deg (one wire proximal, two distal).
  std::array<double, 3> leg_angles_rad{{1.5707963267948966, 3.6651914291880923, 5.7595865315812871}};
  double pulley_radius_m = 0.003;
  std::array<double, 3> rest_angles_rad{};
  MotorSpec motor;
  NormalModel normal_model = NormalModel::exponential;
  double normal_stiffness_n_per_m = 500.0;        // linear
  double exp_initial_stiffness_n_per_m = 250.0;   // exponential: b
  double exp_rate_per_m = 1000.0;                 // exponential: m
  double shear_stiffness_x_n_per_m = 600.0;
  double shear_stiffness_z_n_per_m = 600.0;

  // Besides ranges, checks that every force the limits allow is reachable
  // with all three wires taut and the plate below the wire exits.
  Status validate(const DeviceLimits& limits) const;
  std::string describe() const;
};
Result<std::unique_ptr<FingertipDeviceModel>> make_platform_device(PlatformParams params, DeviceLimits limits);

// --- force_vector ------------------------------------------------------------
// The device takes the force itself: "motor" 0, 1, 2 are normal, shear_x and
// shear_z in newtons (MotorAngles carries them unchanged). inverse() is the
// clamp, forward() the identity, load_torques() zero (no shaft to model).
struct ForceVectorParams {
  std::string name;
  std::string describe() const;
};
Result<std::unique_ptr<FingertipDeviceModel>> make_force_vector_device(ForceVectorParams params,
                                                                       DeviceLimits limits);

// --- configuration -----------------------------------------------------------
// `kind` selects the model; [limits] and the kind's own tables follow
// (docs/haptic-devices.md). Errors name the file, the key (and the table row)
// and what to do.
Result<std::unique_ptr<FingertipDeviceModel>> load_device_model(const std::filesystem::path& toml_file);
Result<std::unique_ptr<FingertipDeviceModel>> parse_device_model(std::string_view toml_text,
                                                                 std::string_view source_name);

}  // namespace proprio::haptics
