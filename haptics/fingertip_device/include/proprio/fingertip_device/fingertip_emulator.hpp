#pragma once
// FingertipEmulator: what the firmware and the hardware of a cutaneous
// fingertip device do, without the device. Stepped in device time at the
// control rate (1 kHz by default), deterministic for a given seed and plant:
//
//   per motor   a brushed DC motor (resistance, optional inductance, torque
//               constant = back-EMF constant in SI, rotor inertia, viscous
//               friction, supply-voltage saturation), a gearbox (16:1 like the
//               thesis's 10 mm 3 W Maxon DCX), an encoder on the motor shaft
//               (1024 counts/rev), integrated with `physics_substeps` steps per
//               control period;
//   firmware    PD position control on the motor-shaft angle at the control
//               rate, plus a slow gated integral that removes the steady-state
//               error a fingertip's stiffness leaves a pure PD with; the
//               voltage is limited so the current stays under the current
//               limit, and to the supply;
//   safety      a watchdog that returns to the rest angles after 50 ms without
//               a valid command, clamping to the force and angle limits, a
//               ramp-in after each enable, latched faults (over-current,
//               encoder loss, stall) that switch the bridges off, all reported
//               in the feedback status bits;
//   plant       the mechanics the motors drive, from a caller-supplied callback
//               (the haptics module wraps its device models into one); the
//               default is a linear fingertip spring per output shaft.
//
// It speaks the bytes of fingertip_protocol.hpp: commands in, feedback and
// device-info reports out. FingertipEmulatorServer serves one over a
// hid::FakeHidLink in real time, which is what the FingertipDevice tests use.
// The model, its parameters and the measured step responses are in
// docs/fingertip-hid-protocol.md §8.
#include <array>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/fingertip_device/fingertip_protocol.hpp"
#include "proprio/hid/emulator_server.hpp"
#include "proprio/hid/hid_transport.hpp"

namespace proprio::devices {

// What the mechanics do to the motors at a set of output-shaft angles.
struct FingertipPlantLoad {
  std::array<double, kFingertipMaxMotors> load_torque_nm{};  // on each output shaft, opposing motion
  std::array<double, kFingertipMaxMotors> fsr_force_n{};     // what each force sensor reads
};
using FingertipPlant =
    std::function<FingertipPlantLoad(const std::array<double, kFingertipMaxMotors>& output_angle_rad)>;
// For force-mode commands (the firmware holds the model): output-shaft angles that render a force.
using FingertipForceToAngles =
    std::function<std::array<double, kFingertipMaxMotors>(double normal_n, double shear_x_n, double shear_z_n)>;

// ---------------------------------------------------------------------------
// The default plant: output shaft i turns a lever of radius r whose tactor
// deflects the fingertip pad along axis i (0 normal, 1 shear_x, 2 shear_z)
// against a linear spring: F_i = k_i r θ_i, torque on the shaft F_i r, and
// force sensor i reads F_i. The normal tactor only pushes: below angle 0 it
// leaves the skin. Pad stiffness is of the order of 1 N/mm in compression
// and half that in shear.
struct FingertipSpringPlantOptions {
  double lever_radius_m = 0.005;
  std::array<double, kFingertipMaxMotors> stiffness_n_per_m{800.0, 500.0, 500.0};  // normal, shear_x, shear_z
  bool normal_unilateral = true;

  // Output-shaft stiffness of axis i, N·m/rad (k_i r²).
  double shaft_stiffness_nm_per_rad(std::size_t axis) const noexcept;
  Status validate() const;
  std::string describe() const;
};
FingertipPlant make_spring_plant(FingertipSpringPlantOptions options = {});
// Its exact inverse: θ_i = F_i / (k_i r), normal force below 0 rendered as 0.
FingertipForceToAngles make_spring_force_to_angles(FingertipSpringPlantOptions options = {});

// ---------------------------------------------------------------------------
// Motor, gearbox, encoder and drive. Defaults are representative of a 10 mm,
// 3 W coreless DC motor with a 6 V winding (the class of the thesis's Maxon
// DCX 10 L) on a 16:1 planetary gearhead; they are not one datasheet's
// numbers, so put yours in for a real device.
struct FingertipMotorParams {
  double resistance_ohm = 6.0;
  double inductance_h = 90e-6;  // 0: the current follows the voltage at once
  double torque_constant_nm_per_a = 4.3e-3;  // = back-EMF constant, V·s/rad
  double rotor_inertia_kgm2 = 7.0e-9;
  double viscous_friction_nms_per_rad = 6.0e-8;  // motor shaft
  double output_inertia_kgm2 = 2.0e-7;  // gearhead output, lever and tactor; seen at the motor divided by ratio²
  double gear_ratio = 16.0;             // motor turns per output turn
  std::uint32_t encoder_counts_per_rev = 1024;  // motor shaft, quadrature edges
  double supply_voltage_v = 6.0;
  double current_limit_a = 0.6;      // the drive limits its voltage to keep the current below this
  double overcurrent_trip_a = 1.0;   // a measured current above this latches fault_overcurrent

  // Inertia the motor shaft sees, kg·m².
  double effective_inertia_kgm2() const noexcept {
    return rotor_inertia_kgm2 + output_inertia_kgm2 / (gear_ratio * gear_ratio);
  }
  Status validate() const;
  std::string describe() const;
};

// The firmware's position controller, on the motor shaft:
//   u = kp e + ∫ ki e dt − kd ω_measured, e = ratio·θ_target − θ_measured (rad),
// ω from encoder differences, the integral only within integral_band_rad of
// the target and below integral_speed_gate_rad_s (output shaft), so a step's
// transient does not wind it up, and bounded by integral_limit_v.
struct FingertipControllerGains {
  double kp_v_per_rad = 0.0;
  double kd_v_s_per_rad = 0.0;
  double ki_v_per_rad_s = 0.0;
  double integral_limit_v = 1.0;
  double integral_band_rad = 0.1;
  double integral_speed_gate_rad_s = 0.5;

  Status validate() const;
  std::string describe() const;
};
// PD gains that give the unloaded motor (current limit aside) the natural
// frequency and damping ratio asked for, counting the back-EMF's own damping:
//   kp = ωn² R J / kt,  kd = (2 ζ ωn J − b − kt²/R) R / kt (at least 0),
// with ki = kp ωn / 3. The default gains are design(default motor, 60 Hz, 0.8).
FingertipControllerGains design_fingertip_gains(const FingertipMotorParams& motor, double natural_frequency_hz,
                                                double damping_ratio);

// The continuous-time second-order prediction of a PD step (ki ignored,
// inductance neglected, no saturation): the closed loop
//   J θ̈ + (b + kt (kt + kd)/R) θ̇ + (kt kp/R + k_load/ratio²) θ = kt kp/R θ_ref.
struct FingertipStepPrediction {
  double natural_frequency_rad_s = 0.0;
  double damping_ratio = 0.0;
  double overshoot = 0.0;          // fraction of the step
  double settling_time_s = 0.0;    // to within tolerance of the final value
  double steady_state_fraction = 1.0;  // final value / target (below 1 against a load)
  std::string describe() const;
};
// load_stiffness_nm_per_rad: output-shaft stiffness of the plant (0: free shaft).
FingertipStepPrediction predict_fingertip_step(const FingertipMotorParams& motor, const FingertipControllerGains& gains,
                                               double load_stiffness_nm_per_rad = 0.0, double tolerance = 0.02);

struct FingertipSafetyOptions {
  DurationNs watchdog_ns = 50 * kNsPerMillisecond;  // without a valid command: back to rest
  DurationNs ramp_ns = 100 * kNsPerMillisecond;     // output scaled 0 to 1 after each enable
  double max_normal_force_n = 2.0;
  double max_shear_force_n = 1.0;  // magnitude of (shear_x, shear_z)
  double min_angle_rad = -1.0;     // output shaft; rest is 0
  double max_angle_rad = 1.0;
  // At the current limit with the encoder not moving this long: fault_stall.
  DurationNs stall_time_ns = 300 * kNsPerMillisecond;

  Status validate() const;
  std::string describe() const;
};

enum class FingertipInjectedFault : std::uint8_t {
  encoder_loss,   // the encoder's signal is lost (its line-break detection fires): fault_encoder
  // The motor's terminals short together (a pinched lead): the bridge drives
  // into a few tens of mΩ, its current sense reads far above the trip level,
  // fault_overcurrent. (The motor, its winding shorted, brakes.)
  terminal_short,
  stuck,          // the rotor is jammed: it holds at the current limit, fault_stall after stall_time_ns
};
const char* to_string(FingertipInjectedFault fault) noexcept;

struct FingertipEmulatorOptions {
  FingertipDeviceKind kind = FingertipDeviceKind::force_vector;
  std::uint8_t motor_count = 3;  // 1-3
  std::uint8_t fsr_count = 3;    // 0-3
  std::uint16_t control_rate_hz = kFingertipDefaultControlRateHz;
  std::uint16_t feedback_rate_hz = kFingertipDefaultControlRateHz;  // divides the control rate
  std::uint32_t physics_substeps = 20;  // per control period: 50 µs at 1 kHz
  FingertipMotorParams motor;
  FingertipControllerGains gains = design_fingertip_gains(FingertipMotorParams{}, 60.0, 0.8);
  FingertipSafetyOptions safety;
  double fsr_noise_n = 0.002;  // standard deviation of each force reading's white noise
  std::string serial = "FTEMU-0001";  // up to 16 printable ASCII characters
  std::optional<Handedness> hand;     // the fingertip it is assigned to (reported in the info report)
  std::optional<Finger> finger;
  std::array<std::uint8_t, 3> firmware{1, 0, 0};
  std::uint32_t boot_timestamp_us = 0;  // µs counter at power-up (near 2^32 to test wrapping)
  // Emulator time of the first power-up: its first control tick. A caller
  // that steps the emulator with a live clock sets this to that clock's now,
  // or the first advance_to() simulates everything since time 0.
  TimeNs boot_time_ns = 0;
  std::uint64_t seed = 1;               // force-sensor noise

  Status validate() const;
  std::string describe() const;
  // The info report this device sends.
  FingertipDeviceInfo info() const;
};

// One feedback report as it leaves the device.
struct FingertipEmulatedReport {
  TimeNs send_ns = 0;  // emulator time: the control tick it reports
  std::array<std::uint8_t, kFingertipReportSize> bytes{};
};

// Ground truth after the latest control tick, for tests.
struct FingertipMotorTruth {
  double output_angle_rad = 0.0;
  double output_velocity_rad_s = 0.0;
  double current_a = 0.0;          // what the drive's current sense reads
  double voltage_v = 0.0;          // what the drive applies until the next tick
  double target_output_rad = 0.0;  // the controller's target (after clamping and the ramp)
  std::int32_t encoder_counts = 0;
  bool bridge_on = true;
};
struct FingertipEmulatorSnapshot {
  TimeNs t_ns = 0;  // the tick's emulator time
  std::uint64_t tick = 0;
  std::array<FingertipMotorTruth, kFingertipMaxMotors> motors{};
  std::array<double, kFingertipMaxMotors> fsr_force_n{};  // true forces, before noise and quantisation
  std::uint16_t status = 0;                               // fingertip_status bits
  FingertipMode mode = FingertipMode::idle;
  double ramp = 0.0;
  // When the newest valid command arrived, and when the watchdog last tripped (-1: never).
  TimeNs last_valid_command_ns = -1;
  TimeNs watchdog_trip_ns = -1;
};

struct FingertipEmulatorStats {
  std::uint64_t ticks = 0;
  std::uint64_t feedback_sent = 0;
  std::uint64_t commands_applied = 0;
  std::uint64_t commands_rejected = 0;  // bad bytes, stale sequences, wrong counts
  std::uint64_t commands_superseded = 0;  // received but replaced by a newer one before the next tick
  std::uint64_t clamped_commands = 0;
  std::uint64_t watchdog_trips = 0;
  std::uint64_t faults_latched = 0;
  std::uint64_t stalls = 0;         // skip_to() calls that skipped ticks
  std::uint64_t stalled_ticks = 0;  // control ticks never run, over all stalls
  FingertipLinkCounters link;  // the command stream as the device received it
};

class FingertipEmulator {
 public:
  // An empty plant or model means the default spring plant (and its inverse).
  static Result<FingertipEmulator> create(FingertipEmulatorOptions options, FingertipPlant plant = {},
                                          FingertipForceToAngles force_to_angles = {});

  // Runs every control tick due up to t_ns (emulator time; earlier is a no-op)
  // and appends the feedback reports sent by then.
  void advance_to(TimeNs t_ns, std::vector<FingertipEmulatedReport>& out);
  // The same, discarding the reports.
  void advance_to(TimeNs t_ns);
  // The firmware stalled until t_ns: the ticks due before it never run and
  // send nothing, the motors hold their state, and the next tick is the first
  // at or after t_ns. What a host too busy to run the emulation in real time
  // gets instead of an ever-growing backlog. Counted in stats().
  void skip_to(TimeNs t_ns);

  // Host -> device: a command report received at t_ns (taken as the
  // emulator's current time if that is later). Checked at once (bytes,
  // sequence, value count); a valid one feeds the watchdog and is applied at
  // the next control tick, unless a newer one arrives first. Never throws.
  FingertipCommandResult handle_command(std::span<const std::uint8_t> report, TimeNs t_ns);
  // The device-info feature report.
  std::array<std::uint8_t, kFingertipReportSize> info_report() const noexcept { return info_bytes_; }

  // Fault injection: active until called again with active = false. Latched
  // faults stay until a command with clear_faults finds their cause gone.
  void inject_fault(FingertipInjectedFault fault, std::size_t motor, bool active = true) noexcept;
  // The device loses power and boots at t_ns: rest, sequences restarted,
  // faults and commands forgotten, device_start on the next feedback.
  void power_cycle(TimeNs t_ns);

  const FingertipEmulatorSnapshot& snapshot() const noexcept { return snapshot_; }
  const FingertipFeedback& last_feedback() const noexcept { return last_feedback_; }
  std::uint32_t device_time_us(TimeNs t_ns) const noexcept;
  // Emulator time of control tick `tick` since the latest boot.
  TimeNs tick_time_ns(std::uint64_t tick) const noexcept { return boot_ns_ + tick_offset_ns(tick); }
  TimeNs control_period_ns() const noexcept { return tick_offset_ns(1); }
  TimeNs now_ns() const noexcept { return now_ns_; }  // the latest tick run
  const FingertipEmulatorOptions& options() const noexcept { return options_; }
  const FingertipEmulatorStats& stats() const noexcept { return stats_; }

 private:
  struct Motor {
    double theta = 0.0;  // motor shaft, rad
    double omega = 0.0;  // rad/s
    double current = 0.0;
    double voltage = 0.0;
    double integral_v = 0.0;
    double prev_measured = 0.0;
    std::int32_t counts = 0;
    std::int32_t stall_counts = 0;
    TimeNs stall_since = -1;
    bool encoder_lost = false;
    bool terminal_short = false;
    double sense_current = 0.0;  // what the bridge's current sense reads
    bool stuck = false;
  };

  FingertipEmulator(FingertipEmulatorOptions options, FingertipPlant plant, FingertipForceToAngles model);
  TimeNs tick_offset_ns(std::uint64_t tick) const noexcept;
  void boot(TimeNs t_ns) noexcept;
  void run_until(TimeNs t_ns, std::vector<FingertipEmulatedReport>* out);
  void integrate(TimeNs from_ns, TimeNs to_ns);
  void control_tick(TimeNs t_ns, std::vector<FingertipEmulatedReport>* out);
  void apply_command(const FingertipCommand& command, TimeNs t_ns);
  std::array<double, kFingertipMaxMotors> targets(TimeNs t_ns);
  std::uint16_t status_bits() const noexcept;
  std::array<double, kFingertipMaxMotors> output_angles() const noexcept;

  FingertipEmulatorOptions options_;
  FingertipPlant plant_;
  FingertipForceToAngles force_to_angles_;
  std::array<std::uint8_t, kFingertipReportSize> info_bytes_{};
  Rng fsr_rng_;
  std::array<Motor, kFingertipMaxMotors> motors_{};
  FingertipPlantLoad load_{};  // the plant at the current state
  double count_angle_ = 0.0;   // motor rad per encoder count
  std::uint64_t feedback_divider_ = 1;

  TimeNs boot_ns_ = 0;
  std::uint64_t next_tick_ = 0;  // ticks since boot
  TimeNs now_ns_ = 0;
  FingertipCommandStream command_stream_;
  std::optional<FingertipCommand> pending_;
  TimeNs pending_arrival_ns_ = 0;
  bool have_active_ = false;
  FingertipCommand active_{};
  TimeNs last_valid_ns_ = -1;
  bool enabled_ = false;
  TimeNs enable_ns_ = 0;
  bool watchdog_tripped_ = false;
  bool clamped_ = false;
  std::uint16_t latched_faults_ = 0;
  double ramp_ = 0.0;
  FingertipMode mode_ = FingertipMode::idle;
  std::uint16_t feedback_sequence_ = 0;
  bool device_start_pending_ = true;
  std::uint16_t rejected_ = 0;
  FingertipCommandResult last_result_ = FingertipCommandResult::none;
  FingertipFeedback last_feedback_{};
  FingertipEmulatorSnapshot snapshot_{};
  FingertipEmulatorStats stats_{};
};

// ---------------------------------------------------------------------------
// Serving the emulator over a fake cable, in real time.

struct FingertipServeOptions {
  // Each feedback report reaches the host this long after it left the device:
  // a floor plus a uniform extra up to jitter.
  DurationNs latency_min_ns = 200'000;
  DurationNs latency_jitter_ns = 300'000;
  // The pumping thread's period. The emulator runs up to the link's clock,
  // never ahead, so a command takes effect at the first tick after it arrives.
  DurationNs pump_interval_ns = kNsPerMillisecond;
  // Where the emulation falls further behind the link's clock than this (a
  // host too busy to run it in real time), the device stalls (skip_to) rather
  // than catching up: each catch-up would take longer than the time it covers,
  // holding the lock that host writes wait on, and never end. 0: never skip.
  DurationNs max_lag_ns = 100 * kNsPerMillisecond;
  std::uint64_t seed = 1;  // latency draws

  std::string describe() const;
};

// The device's end of a hid::FakeHidLink (hid::EmulatorServer): a thread runs
// the emulator in step with the link's clock, never ahead, and queues its
// feedback on the link. While the cable is out, commands cannot arrive, so
// the emulated device's watchdog trips as a real one's would.
struct FingertipEmulatorServerTraits {
  using Emulator = FingertipEmulator;
  using Options = FingertipServeOptions;
  using Report = FingertipEmulatedReport;
  // Stalls (skip_to) instead of catching up when more than max_lag_ns behind.
  static void advance(FingertipEmulator& emulator, const FingertipServeOptions& options, TimeNs now_ns,
                      std::vector<FingertipEmulatedReport>& out);
  static void handle_command(FingertipEmulator& emulator, std::span<const std::uint8_t> bytes, TimeNs now_ns);
  static std::size_t feature(FingertipEmulator& emulator, std::uint8_t report_id, TimeNs now_ns,
                             std::span<std::uint8_t> out);
};
using FingertipEmulatorServer = hid::EmulatorServer<FingertipEmulatorServerTraits>;

}  // namespace proprio::devices
