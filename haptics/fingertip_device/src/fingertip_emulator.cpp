#include "proprio/fingertip_device/fingertip_emulator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include "proprio/core/log.hpp"

namespace proprio::devices {

namespace {

constexpr double kTwoPi = 2.0 * M_PI;
// Lead and bridge resistance when the motor's terminals touch.
constexpr double kTerminalShortOhm = 0.05;

bool finite_positive(double v) noexcept { return std::isfinite(v) && v > 0.0; }
bool finite_non_negative(double v) noexcept { return std::isfinite(v) && v >= 0.0; }

Error option_error(const char* field, double value, const char* rule) {
  char buf[320];
  std::snprintf(buf, sizeof buf, "fingertip emulator option %s = %g: %s", field, value, rule);
  return make_error(Errc::invalid_argument, buf);
}

std::string emulator_ms(DurationNs ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g ms", static_cast<double>(ns) / kNsPerMillisecond);
  return buf;
}

std::int32_t quantise_counts(double theta, double count_angle) noexcept {
  // A quadrature counter counts whole edges, so the reading is the floor.
  const double c = std::floor(theta / count_angle);
  constexpr double lo = std::numeric_limits<std::int32_t>::min();
  constexpr double hi = std::numeric_limits<std::int32_t>::max();
  if (!(c > lo)) return std::numeric_limits<std::int32_t>::min();
  if (!(c < hi)) return std::numeric_limits<std::int32_t>::max();
  return static_cast<std::int32_t>(c);
}

template <typename T>
T saturate_cast(double v) noexcept {
  constexpr double lo = static_cast<double>(std::numeric_limits<T>::min());
  constexpr double hi = static_cast<double>(std::numeric_limits<T>::max());
  if (!(v > lo)) return std::numeric_limits<T>::min();
  if (!(v < hi)) return std::numeric_limits<T>::max();
  return static_cast<T>(std::nearbyint(v));
}

}  // namespace

// ---------------------------------------------------------------------------
// The default plant.

double FingertipSpringPlantOptions::shaft_stiffness_nm_per_rad(std::size_t axis) const noexcept {
  return axis < kFingertipMaxMotors ? stiffness_n_per_m[axis] * lever_radius_m * lever_radius_m : 0.0;
}

Status FingertipSpringPlantOptions::validate() const {
  if (!finite_positive(lever_radius_m)) return option_error("spring.lever_radius_m", lever_radius_m, "must be positive (m)");
  for (double k : stiffness_n_per_m) {
    if (!finite_positive(k)) return option_error("spring.stiffness_n_per_m", k, "every axis needs a positive stiffness (N/m)");
  }
  return {};
}

std::string FingertipSpringPlantOptions::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf, "lever %.1f mm, pad stiffness %.0f/%.0f/%.0f N/m (normal/shear_x/shear_z)%s",
                lever_radius_m * 1e3, stiffness_n_per_m[0], stiffness_n_per_m[1], stiffness_n_per_m[2],
                normal_unilateral ? ", normal tactor pushes only" : "");
  return buf;
}

FingertipPlant make_spring_plant(FingertipSpringPlantOptions options) {
  return [o = options](const std::array<double, kFingertipMaxMotors>& angle) {
    FingertipPlantLoad load;
    for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) {
      double x = o.lever_radius_m * angle[i];
      if (i == 0 && o.normal_unilateral && x < 0.0) x = 0.0;
      const double f = o.stiffness_n_per_m[i] * x;
      load.fsr_force_n[i] = f;
      load.load_torque_nm[i] = f * o.lever_radius_m;
    }
    return load;
  };
}

FingertipForceToAngles make_spring_force_to_angles(FingertipSpringPlantOptions options) {
  return [o = options](double normal_n, double shear_x_n, double shear_z_n) {
    const std::array<double, kFingertipMaxMotors> f{o.normal_unilateral ? std::max(normal_n, 0.0) : normal_n,
                                                     shear_x_n, shear_z_n};
    std::array<double, kFingertipMaxMotors> angle{};
    for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) {
      angle[i] = f[i] / (o.stiffness_n_per_m[i] * o.lever_radius_m);
    }
    return angle;
  };
}

// ---------------------------------------------------------------------------
// Motor, controller, safety.

Status FingertipMotorParams::validate() const {
  if (!finite_positive(resistance_ohm)) return option_error("motor.resistance_ohm", resistance_ohm, "must be positive (Ω)");
  if (!finite_non_negative(inductance_h)) return option_error("motor.inductance_h", inductance_h, "must be 0 or positive (H)");
  if (!finite_positive(torque_constant_nm_per_a)) {
    return option_error("motor.torque_constant_nm_per_a", torque_constant_nm_per_a, "must be positive (N·m/A)");
  }
  if (!finite_positive(rotor_inertia_kgm2)) {
    return option_error("motor.rotor_inertia_kgm2", rotor_inertia_kgm2, "must be positive (kg·m²)");
  }
  if (!finite_non_negative(viscous_friction_nms_per_rad)) {
    return option_error("motor.viscous_friction_nms_per_rad", viscous_friction_nms_per_rad, "must be 0 or positive");
  }
  if (!finite_non_negative(output_inertia_kgm2)) {
    return option_error("motor.output_inertia_kgm2", output_inertia_kgm2, "must be 0 or positive (kg·m²)");
  }
  if (!finite_positive(gear_ratio) || gear_ratio < 0.001 || gear_ratio > 4'000'000.0) {
    return option_error("motor.gear_ratio", gear_ratio, "must be 0.001 to 4e6 (the info report carries it x 1000 in 32 bits)");
  }
  if (encoder_counts_per_rev == 0) return option_error("motor.encoder_counts_per_rev", 0, "must be at least 1");
  if (!finite_positive(supply_voltage_v)) return option_error("motor.supply_voltage_v", supply_voltage_v, "must be positive (V)");
  if (!finite_positive(current_limit_a) || current_limit_a > 32.0) {
    return option_error("motor.current_limit_a", current_limit_a, "must be positive and at most 32 A (mA travel as 16 bits)");
  }
  if (!finite_positive(overcurrent_trip_a) || overcurrent_trip_a <= current_limit_a) {
    return option_error("motor.overcurrent_trip_a", overcurrent_trip_a, "must be above the current limit");
  }
  return {};
}

std::string FingertipMotorParams::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "R %.3g Ω, L %.3g mH, kt %.3g mN·m/A, J %.3g g·cm² (+ %.3g g·cm² at the output), b %.3g µN·m·s/rad, "
                "gear %.4g:1, encoder %u counts/rev, supply %.3g V, current limit %.3g A, trip %.3g A",
                resistance_ohm, inductance_h * 1e3, torque_constant_nm_per_a * 1e3, rotor_inertia_kgm2 * 1e7,
                output_inertia_kgm2 * 1e7, viscous_friction_nms_per_rad * 1e6, gear_ratio, encoder_counts_per_rev,
                supply_voltage_v, current_limit_a, overcurrent_trip_a);
  return buf;
}

Status FingertipControllerGains::validate() const {
  if (!finite_non_negative(kp_v_per_rad)) return option_error("gains.kp_v_per_rad", kp_v_per_rad, "must be 0 or positive");
  if (!finite_non_negative(kd_v_s_per_rad)) return option_error("gains.kd_v_s_per_rad", kd_v_s_per_rad, "must be 0 or positive");
  if (!finite_non_negative(ki_v_per_rad_s)) return option_error("gains.ki_v_per_rad_s", ki_v_per_rad_s, "must be 0 or positive");
  if (!finite_non_negative(integral_limit_v)) return option_error("gains.integral_limit_v", integral_limit_v, "must be 0 or positive");
  if (!finite_non_negative(integral_band_rad)) {
    return option_error("gains.integral_band_rad", integral_band_rad, "must be 0 or positive");
  }
  if (!finite_non_negative(integral_speed_gate_rad_s)) {
    return option_error("gains.integral_speed_gate_rad_s", integral_speed_gate_rad_s, "must be 0 or positive");
  }
  return {};
}

std::string FingertipControllerGains::describe() const {
  char buf[240];
  std::snprintf(buf, sizeof buf,
                "kp %.4g V/rad, kd %.4g mV·s/rad, ki %.4g V/(rad·s) (within %.3g rad and below %.3g rad/s of the "
                "output, at most %.3g V)",
                kp_v_per_rad, kd_v_s_per_rad * 1e3, ki_v_per_rad_s, integral_band_rad, integral_speed_gate_rad_s,
                integral_limit_v);
  return buf;
}

FingertipControllerGains design_fingertip_gains(const FingertipMotorParams& m, double natural_frequency_hz,
                                                double damping_ratio) {
  const double wn = kTwoPi * natural_frequency_hz;
  const double j = m.effective_inertia_kgm2();
  const double r = m.resistance_ohm;
  const double kt = m.torque_constant_nm_per_a;
  FingertipControllerGains g;
  g.kp_v_per_rad = wn * wn * r * j / kt;
  g.kd_v_s_per_rad = std::max(0.0, (2.0 * damping_ratio * wn * j - m.viscous_friction_nms_per_rad - kt * kt / r) * r / kt);
  g.ki_v_per_rad_s = g.kp_v_per_rad * wn / 3.0;
  return g;
}

std::string FingertipStepPrediction::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf, "ωn %.1f rad/s (%.1f Hz), ζ %.3f, overshoot %.2f %%, settling %.1f ms, final %.1f %% of target",
                natural_frequency_rad_s, natural_frequency_rad_s / kTwoPi, damping_ratio, overshoot * 100.0,
                settling_time_s * 1e3, steady_state_fraction * 100.0);
  return buf;
}

FingertipStepPrediction predict_fingertip_step(const FingertipMotorParams& m, const FingertipControllerGains& g,
                                               double load_stiffness_nm_per_rad, double tolerance) {
  FingertipStepPrediction p;
  const double j = m.effective_inertia_kgm2();
  const double r = m.resistance_ohm;
  const double kt = m.torque_constant_nm_per_a;
  const double damping = m.viscous_friction_nms_per_rad + kt * (kt + g.kd_v_s_per_rad) / r;
  const double servo = kt * g.kp_v_per_rad / r;
  const double stiffness = servo + load_stiffness_nm_per_rad / (m.gear_ratio * m.gear_ratio);
  if (!(stiffness > 0.0) || !(tolerance > 0.0)) {
    p.settling_time_s = std::numeric_limits<double>::infinity();
    p.steady_state_fraction = 0.0;
    return p;
  }
  const double wn = std::sqrt(stiffness / j);
  const double zeta = damping / (2.0 * std::sqrt(stiffness * j));
  p.natural_frequency_rad_s = wn;
  p.damping_ratio = zeta;
  p.steady_state_fraction = servo / stiffness;
  if (zeta < 1.0) {
    const double root = std::sqrt(1.0 - zeta * zeta);
    p.overshoot = std::exp(-M_PI * zeta / root);
    // The envelope of the oscillation, e^{-ζωn t}/√(1-ζ²), falls below the tolerance.
    p.settling_time_s = -std::log(tolerance * root) / (zeta * wn);
  } else {
    // Overdamped (or critically, nudged): the slow pole dominates the tail.
    const double s = std::sqrt(std::max(zeta * zeta - 1.0, 1e-12));
    const double slow = wn * (zeta - s);
    const double fast = wn * (zeta + s);
    p.overshoot = 0.0;
    p.settling_time_s = std::log(fast / ((fast - slow) * tolerance)) / slow;
  }
  return p;
}

Status FingertipSafetyOptions::validate() const {
  if (watchdog_ns < kNsPerMillisecond || watchdog_ns > 65535 * kNsPerMillisecond) {
    return option_error("safety.watchdog_ns", static_cast<double>(watchdog_ns),
                        "must be 1 ms to 65.535 s: every device has a watchdog, and the info report carries it in ms");
  }
  if (ramp_ns < 0 || ramp_ns > 65535 * kNsPerMillisecond) {
    return option_error("safety.ramp_ns", static_cast<double>(ramp_ns), "must be 0 to 65.535 s");
  }
  if (!finite_non_negative(max_normal_force_n) || max_normal_force_n > 4e6) {
    return option_error("safety.max_normal_force_n", max_normal_force_n, "must be 0 or positive (N)");
  }
  if (!finite_non_negative(max_shear_force_n) || max_shear_force_n > 4e6) {
    return option_error("safety.max_shear_force_n", max_shear_force_n, "must be 0 or positive (N)");
  }
  if (!std::isfinite(min_angle_rad) || !std::isfinite(max_angle_rad) || min_angle_rad > 0.0 || max_angle_rad < 0.0 ||
      min_angle_rad >= max_angle_rad || min_angle_rad < -2000.0 || max_angle_rad > 2000.0) {
    return option_error("safety.min_angle_rad", min_angle_rad,
                        "the angle limits must enclose the rest angle 0 with min below max, within ±2000 rad");
  }
  if (stall_time_ns <= 0) return option_error("safety.stall_time_ns", static_cast<double>(stall_time_ns), "must be positive");
  return {};
}

std::string FingertipSafetyOptions::describe() const {
  char buf[240];
  std::snprintf(buf, sizeof buf,
                "watchdog %s, ramp %s, max normal %.3g N, max shear %.3g N, angles [%.3g, %.3g] rad, stall after %s",
                emulator_ms(watchdog_ns).c_str(), emulator_ms(ramp_ns).c_str(), max_normal_force_n, max_shear_force_n, min_angle_rad,
                max_angle_rad, emulator_ms(stall_time_ns).c_str());
  return buf;
}

const char* to_string(FingertipInjectedFault fault) noexcept {
  switch (fault) {
    case FingertipInjectedFault::encoder_loss: return "encoder_loss";
    case FingertipInjectedFault::terminal_short: return "terminal_short";
    case FingertipInjectedFault::stuck: return "stuck";
  }
  return "unknown";
}

Status FingertipEmulatorOptions::validate() const {
  const auto kind_byte = static_cast<std::uint8_t>(kind);
  if (kind_byte < 1 || kind_byte > 3) return option_error("kind", kind_byte, "must be band_2dof, platform_3dof or force_vector");
  if (motor_count == 0 || motor_count > kFingertipMaxMotors) return option_error("motor_count", motor_count, "must be 1 to 3");
  if (fsr_count > kFingertipMaxMotors) return option_error("fsr_count", fsr_count, "must be 0 to 3");
  if (control_rate_hz == 0 || control_rate_hz > kFingertipMaxControlRateHz) {
    return option_error("control_rate_hz", control_rate_hz, "must be 1 to 10000 Hz");
  }
  if (feedback_rate_hz == 0 || feedback_rate_hz > control_rate_hz || control_rate_hz % feedback_rate_hz != 0) {
    return option_error("feedback_rate_hz", feedback_rate_hz, "must divide the control rate (feedback every n-th tick)");
  }
  if (physics_substeps == 0 || physics_substeps > 1000) {
    return option_error("physics_substeps", physics_substeps, "must be 1 to 1000 per control period");
  }
  if (auto s = motor.validate(); !s) return s;
  if (auto s = gains.validate(); !s) return s;
  if (auto s = safety.validate(); !s) return s;
  if (!finite_non_negative(fsr_noise_n)) return option_error("fsr_noise_n", fsr_noise_n, "must be 0 or positive (N)");
  if (serial.size() > kFingertipSerialLength ||
      std::any_of(serial.begin(), serial.end(), [](char c) { return c < 0x20 || c > 0x7E; })) {
    return make_error(Errc::invalid_argument, "fingertip emulator option serial = '" + serial +
                                                  "': must be at most 16 printable ASCII characters");
  }
  return {};
}

std::string FingertipEmulatorOptions::describe() const {
  std::string s = devices::describe(info());
  char buf[200];
  std::snprintf(buf, sizeof buf, "; %u physics substeps, force sensor noise %.3g N, seed %llu", physics_substeps,
                fsr_noise_n, static_cast<unsigned long long>(seed));
  s += buf;
  s += "; motor: " + motor.describe() + "; control: " + gains.describe() + "; safety: " + safety.describe();
  return s;
}

FingertipDeviceInfo FingertipEmulatorOptions::info() const {
  FingertipDeviceInfo i;
  i.firmware = firmware;
  i.kind = kind;
  i.motor_count = motor_count;
  i.fsr_count = fsr_count;
  i.hand = hand;
  i.finger = finger;
  i.control_rate_hz = control_rate_hz;
  i.feedback_rate_hz = feedback_rate_hz;
  i.encoder_counts_per_rev = motor.encoder_counts_per_rev;
  i.gear_ratio_milli = saturate_cast<std::uint32_t>(motor.gear_ratio * 1000.0);
  i.watchdog_ms = saturate_cast<std::uint16_t>(static_cast<double>(safety.watchdog_ns) / kNsPerMillisecond);
  i.ramp_ms = saturate_cast<std::uint16_t>(static_cast<double>(safety.ramp_ns) / kNsPerMillisecond);
  i.max_normal_force_mn = saturate_cast<std::uint32_t>(safety.max_normal_force_n * kFingertipMnPerN);
  i.max_shear_force_mn = saturate_cast<std::uint32_t>(safety.max_shear_force_n * kFingertipMnPerN);
  i.min_angle_urad = saturate_cast<std::int32_t>(safety.min_angle_rad * kFingertipUradPerRad);
  i.max_angle_urad = saturate_cast<std::int32_t>(safety.max_angle_rad * kFingertipUradPerRad);
  i.max_current_ma = saturate_cast<std::uint16_t>(motor.current_limit_a * kFingertipMaPerA);
  i.set_serial(serial);
  return i;
}

// ---------------------------------------------------------------------------
// The emulator.

Result<FingertipEmulator> FingertipEmulator::create(FingertipEmulatorOptions options, FingertipPlant plant,
                                                    FingertipForceToAngles force_to_angles) {
  if (auto s = options.validate(); !s) return s.error();
  if (!plant) plant = make_spring_plant();
  if (!force_to_angles) force_to_angles = make_spring_force_to_angles();
  return FingertipEmulator(std::move(options), std::move(plant), std::move(force_to_angles));
}

FingertipEmulator::FingertipEmulator(FingertipEmulatorOptions options, FingertipPlant plant,
                                     FingertipForceToAngles model)
    : options_(std::move(options)),
      plant_(std::move(plant)),
      force_to_angles_(std::move(model)),
      fsr_rng_(mix_seed(options_.seed, 1)) {
  info_bytes_ = encode_fingertip_info(options_.info());
  count_angle_ = kTwoPi / options_.motor.encoder_counts_per_rev;
  feedback_divider_ = options_.control_rate_hz / options_.feedback_rate_hz;
  boot(options_.boot_time_ns);
}

TimeNs FingertipEmulator::tick_offset_ns(std::uint64_t tick) const noexcept {
  const std::uint64_t rate = options_.control_rate_hz;
  // Split so that k x 1e9 cannot overflow, and every tick lands on the same ns grid.
  return static_cast<TimeNs>((tick / rate) * static_cast<std::uint64_t>(kNsPerSecond) +
                             (tick % rate) * static_cast<std::uint64_t>(kNsPerSecond) / rate);
}

std::uint32_t FingertipEmulator::device_time_us(TimeNs t_ns) const noexcept {
  const std::int64_t us = (t_ns - boot_ns_) / 1000;
  return static_cast<std::uint32_t>(static_cast<std::uint64_t>(options_.boot_timestamp_us) + static_cast<std::uint64_t>(us));
}

void FingertipEmulator::boot(TimeNs t_ns) noexcept {
  boot_ns_ = t_ns;
  next_tick_ = 0;
  now_ns_ = t_ns;
  for (Motor& m : motors_) {
    // Injected hardware faults survive a power cycle; everything the firmware knew does not.
    const bool lost = m.encoder_lost, shorted = m.terminal_short, jammed = m.stuck;
    m = Motor{};
    m.encoder_lost = lost;
    m.terminal_short = shorted;
    m.stuck = jammed;
  }
  command_stream_.reset();
  pending_.reset();
  have_active_ = false;
  active_ = FingertipCommand{};
  last_valid_ns_ = -1;
  enabled_ = false;
  enable_ns_ = t_ns;
  watchdog_tripped_ = false;
  clamped_ = false;
  latched_faults_ = 0;
  ramp_ = 0.0;
  mode_ = FingertipMode::idle;
  feedback_sequence_ = 0;
  device_start_pending_ = true;
  rejected_ = 0;
  last_result_ = FingertipCommandResult::none;
  load_ = plant_(output_angles());
  snapshot_ = FingertipEmulatorSnapshot{};
  snapshot_.t_ns = t_ns;
}

void FingertipEmulator::power_cycle(TimeNs t_ns) {
  // A device that has not run yet has nothing to finish; running it up to a
  // CLOCK_MONOTONIC t would simulate every tick since time 0 (hours).
  if (next_tick_ > 0) advance_to(t_ns);
  boot(std::max(t_ns, now_ns_));
}

std::array<double, kFingertipMaxMotors> FingertipEmulator::output_angles() const noexcept {
  std::array<double, kFingertipMaxMotors> a{};
  for (std::size_t i = 0; i < options_.motor_count; ++i) a[i] = motors_[i].theta / options_.motor.gear_ratio;
  return a;
}

void FingertipEmulator::inject_fault(FingertipInjectedFault fault, std::size_t motor, bool active) noexcept {
  if (motor >= options_.motor_count) return;
  Motor& m = motors_[motor];
  switch (fault) {
    case FingertipInjectedFault::encoder_loss: m.encoder_lost = active; break;
    case FingertipInjectedFault::terminal_short: m.terminal_short = active; break;
    case FingertipInjectedFault::stuck:
      m.stuck = active;
      if (active) m.omega = 0.0;
      break;
  }
}

void FingertipEmulator::advance_to(TimeNs t_ns) { run_until(t_ns, nullptr); }

void FingertipEmulator::advance_to(TimeNs t_ns, std::vector<FingertipEmulatedReport>& out) { run_until(t_ns, &out); }

void FingertipEmulator::skip_to(TimeNs t_ns) {
  if (t_ns <= tick_time_ns(next_tick_)) return;
  // The last tick at or before t_ns from the rate (a laptop that slept for an
  // hour is 3.6 million ticks), then the first at or after it.
  const auto since_boot = static_cast<std::uint64_t>(t_ns - boot_ns_);
  const std::uint64_t rate = options_.control_rate_hz;
  const auto ns = static_cast<std::uint64_t>(kNsPerSecond);
  std::uint64_t first = since_boot / ns * rate + since_boot % ns * rate / ns;
  while (tick_time_ns(first) < t_ns) ++first;
  ++stats_.stalls;
  stats_.stalled_ticks += first - next_tick_;
  next_tick_ = first;
  // The next tick integrates one control period from here, not across the gap.
  now_ns_ = tick_time_ns(next_tick_ - 1);
}

void FingertipEmulator::run_until(TimeNs t_ns, std::vector<FingertipEmulatedReport>* out) {
  for (;;) {
    const TimeNs tick_ns = tick_time_ns(next_tick_);
    if (tick_ns > t_ns) break;
    if (next_tick_ > 0) integrate(tick_time_ns(next_tick_ - 1), tick_ns);
    control_tick(tick_ns, out);
    now_ns_ = tick_ns;
    ++next_tick_;
  }
}

FingertipCommandResult FingertipEmulator::handle_command(std::span<const std::uint8_t> report, TimeNs t_ns) {
  const TimeNs arrival = std::max(t_ns, now_ns_);
  FingertipCommand command;
  const FingertipStreamResult r = command_stream_.push(report, command);
  stats_.link = command_stream_.counters();
  FingertipCommandResult result = FingertipCommandResult::ok;
  if (!r.decode) {
    result = FingertipCommandResult::bad_report;
  } else if (!r.sequence.accepted()) {
    result = FingertipCommandResult::stale_sequence;
  } else if (command.mode == FingertipMode::motor_angles && command.count != options_.motor_count) {
    result = FingertipCommandResult::wrong_value_count;
  }
  last_result_ = result;
  if (result != FingertipCommandResult::ok) {
    ++rejected_;
    ++stats_.commands_rejected;
    return result;
  }
  if (pending_) ++stats_.commands_superseded;
  pending_ = command;
  pending_arrival_ns_ = arrival;
  last_valid_ns_ = arrival;
  return result;
}

void FingertipEmulator::apply_command(const FingertipCommand& c, TimeNs t_ns) {
  ++stats_.commands_applied;
  active_ = c;
  have_active_ = true;
  if (c.flags & fingertip_command_flags::clear_faults) {
    // A latched fault whose cause is still there comes straight back at this tick's checks.
    latched_faults_ = 0;
    watchdog_tripped_ = false;
    for (Motor& m : motors_) m.stall_since = -1;
  }
  if (!c.enable()) {
    enabled_ = false;
  } else if (!enabled_ && latched_faults_ == 0) {
    enabled_ = true;
    enable_ns_ = t_ns;
    watchdog_tripped_ = false;
  }
  const FingertipSafetyOptions& limits = options_.safety;
  bool clamped = false;
  if (c.mode == FingertipMode::motor_angles) {
    for (std::size_t i = 0; i < options_.motor_count; ++i) {
      const double a = c.values[i] / kFingertipUradPerRad;
      clamped = clamped || a < limits.min_angle_rad || a > limits.max_angle_rad;
    }
  } else {
    const double normal = c.values[0] / kFingertipMnPerN;
    const double shear = std::hypot(c.values[1] / kFingertipMnPerN, c.values[2] / kFingertipMnPerN);
    clamped = normal < 0.0 || normal > options_.safety.max_normal_force_n || shear > options_.safety.max_shear_force_n;
  }
  clamped_ = clamped;
  if (clamped) ++stats_.clamped_commands;
}


std::array<double, kFingertipMaxMotors> FingertipEmulator::targets(TimeNs t_ns) {
  std::array<double, kFingertipMaxMotors> target{};  // rest
  if (!enabled_ || !have_active_) {
    ramp_ = 0.0;
    mode_ = FingertipMode::idle;
    return target;
  }
  const FingertipSafetyOptions& s = options_.safety;
  ramp_ = s.ramp_ns <= 0 ? 1.0 : std::clamp(static_cast<double>(t_ns - enable_ns_) / static_cast<double>(s.ramp_ns), 0.0, 1.0);
  mode_ = active_.mode;
  if (active_.mode == FingertipMode::motor_angles) {
    for (std::size_t i = 0; i < options_.motor_count; ++i) {
      target[i] = ramp_ * std::clamp(active_.values[i] / kFingertipUradPerRad, s.min_angle_rad, s.max_angle_rad);
    }
    return target;
  }
  // Force: clamp the force itself (normal into [0, max], the shear vector to
  // its maximum length, direction kept), scale by the ramp, then the model.
  const double normal = std::clamp(active_.values[0] / kFingertipMnPerN, 0.0, s.max_normal_force_n);
  double shear_x = active_.values[1] / kFingertipMnPerN;
  double shear_z = active_.values[2] / kFingertipMnPerN;
  const double shear = std::hypot(shear_x, shear_z);
  if (shear > s.max_shear_force_n && shear > 0.0) {
    shear_x *= s.max_shear_force_n / shear;
    shear_z *= s.max_shear_force_n / shear;
  }
  const std::array<double, kFingertipMaxMotors> angle = force_to_angles_(ramp_ * normal, ramp_ * shear_x, ramp_ * shear_z);
  for (std::size_t i = 0; i < options_.motor_count; ++i) {
    if (!std::isfinite(angle[i])) {
      // A model that cannot answer must not move the motor.
      target[i] = 0.0;
      clamped_ = true;
      continue;
    }
    target[i] = std::clamp(angle[i], s.min_angle_rad, s.max_angle_rad);
    if (target[i] != angle[i]) clamped_ = true;
  }
  return target;
}

std::uint16_t FingertipEmulator::status_bits() const noexcept {
  std::uint16_t s = latched_faults_;
  if (enabled_) s |= fingertip_status::enabled;
  if (enabled_ && ramp_ < 1.0) s |= fingertip_status::ramping;
  if (watchdog_tripped_) s |= fingertip_status::watchdog_tripped;
  if (enabled_ && clamped_) s |= fingertip_status::clamped;
  return s;
}

void FingertipEmulator::control_tick(TimeNs t_ns, std::vector<FingertipEmulatedReport>* out) {
  const FingertipMotorParams& mp = options_.motor;
  const FingertipControllerGains& g = options_.gains;
  const std::size_t motors = options_.motor_count;
  const double period_s = ns_to_seconds(control_period_ns());
  const bool first_tick = next_tick_ == 0;
  ++stats_.ticks;

  if (pending_ && pending_arrival_ns_ <= t_ns) {
    apply_command(*pending_, t_ns);
    pending_.reset();
  }

  // Sensing: encoders (frozen when their signal is lost), speed from their differences, currents.
  std::array<double, kFingertipMaxMotors> measured{};
  std::array<double, kFingertipMaxMotors> speed{};
  for (std::size_t i = 0; i < motors; ++i) {
    Motor& m = motors_[i];
    if (!m.encoder_lost) m.counts = quantise_counts(m.theta, count_angle_);
    measured[i] = m.counts * count_angle_;
    speed[i] = first_tick ? 0.0 : (measured[i] - m.prev_measured) / period_s;
    m.prev_measured = measured[i];
  }

  // Faults latch and switch every bridge off: a device that lost one motor
  // cannot render the force it was asked for.
  const std::uint16_t faults_before = latched_faults_;
  for (std::size_t i = 0; i < motors; ++i) {
    Motor& m = motors_[i];
    if (m.encoder_lost) latched_faults_ |= fingertip_status::fault_encoder;
    if (std::abs(m.sense_current) > mp.overcurrent_trip_a) latched_faults_ |= fingertip_status::fault_overcurrent;
    if (std::abs(m.sense_current) >= 0.9 * mp.current_limit_a) {
      if (m.stall_since < 0 || m.counts != m.stall_counts) {
        m.stall_since = t_ns;
        m.stall_counts = m.counts;
      } else if (t_ns - m.stall_since >= options_.safety.stall_time_ns) {
        latched_faults_ |= fingertip_status::fault_stall;
      }
    } else {
      m.stall_since = -1;
    }
  }
  if (latched_faults_ != faults_before) ++stats_.faults_latched;
  if (latched_faults_ != 0) enabled_ = false;

  if (enabled_ && last_valid_ns_ >= 0 && t_ns - last_valid_ns_ >= options_.safety.watchdog_ns) {
    enabled_ = false;
    watchdog_tripped_ = true;
    ++stats_.watchdog_trips;
    snapshot_.watchdog_trip_ns = t_ns;
  }

  const std::array<double, kFingertipMaxMotors> target = targets(t_ns);

  // Position control on the motor shaft; the voltage is bounded so that the
  // current (from the speed the encoder sees) stays within the limit, then by the supply.
  const bool bridges_on = latched_faults_ == 0;
  for (std::size_t i = 0; i < motors; ++i) {
    Motor& m = motors_[i];
    if (!bridges_on) {
      m.voltage = 0.0;
      m.integral_v = 0.0;
      continue;
    }
    const double error = mp.gear_ratio * target[i] - measured[i];
    const double before = m.integral_v;
    if (std::abs(error) < g.integral_band_rad * mp.gear_ratio &&
        std::abs(speed[i]) < g.integral_speed_gate_rad_s * mp.gear_ratio) {
      m.integral_v = std::clamp(m.integral_v + g.ki_v_per_rad_s * error * period_s, -g.integral_limit_v, g.integral_limit_v);
    }
    const double raw = g.kp_v_per_rad * error + m.integral_v - g.kd_v_s_per_rad * speed[i];
    const double emf = mp.torque_constant_nm_per_a * speed[i];
    const double headroom = mp.resistance_ohm * mp.current_limit_a;
    double u = std::clamp(raw, emf - headroom, emf + headroom);
    u = std::clamp(u, -mp.supply_voltage_v, mp.supply_voltage_v);
    if (u != raw) m.integral_v = before;  // saturated: integrating further would only wind up
    m.voltage = u;
  }

  // What the device reports for this tick.
  const bool send = next_tick_ % feedback_divider_ == 0;
  if (send) {
    FingertipFeedback f;
    f.sequence = feedback_sequence_++;
    f.applied_sequence = have_active_ ? active_.sequence : 0;
    f.device_time_us = device_time_us(t_ns);
    f.status = status_bits();
    if (device_start_pending_) f.status |= fingertip_status::device_start;
    device_start_pending_ = false;
    f.motor_count = options_.motor_count;
    f.fsr_count = options_.fsr_count;
    f.mode = mode_;
    f.command_result = last_result_;
    for (std::size_t i = 0; i < motors; ++i) {
      f.encoder_counts[i] = motors_[i].counts;
      f.current_ma[i] = saturate_cast<std::int16_t>(motors_[i].sense_current * kFingertipMaPerA);
    }
    for (std::size_t i = 0; i < options_.fsr_count; ++i) {
      const double noise = options_.fsr_noise_n > 0.0 ? fsr_rng_.normal(0.0, options_.fsr_noise_n) : 0.0;
      f.fsr_force_mn[i] = saturate_cast<std::int32_t>((load_.fsr_force_n[i] + noise) * kFingertipMnPerN);
    }
    f.rejected_commands = rejected_;
    f.applied_host_time_ns = have_active_ ? active_.host_time_ns : 0;
    f.ramp_permille = static_cast<std::uint16_t>(std::lround(ramp_ * 1000.0));
    last_feedback_ = f;
    ++stats_.feedback_sent;
    if (out) {
      FingertipEmulatedReport r;
      r.send_ns = t_ns;
      r.bytes = encode_fingertip_feedback(f);
      out->push_back(r);
    }
  }

  snapshot_.t_ns = t_ns;
  snapshot_.tick = next_tick_;
  for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) {
    const Motor& m = motors_[i];
    FingertipMotorTruth& truth = snapshot_.motors[i];
    truth.output_angle_rad = m.theta / mp.gear_ratio;
    truth.output_velocity_rad_s = m.omega / mp.gear_ratio;
    truth.current_a = m.sense_current;
    truth.voltage_v = m.voltage;
    truth.target_output_rad = target[i];
    truth.encoder_counts = m.counts;
    truth.bridge_on = bridges_on && i < motors;
  }
  snapshot_.fsr_force_n = load_.fsr_force_n;
  snapshot_.status = status_bits();
  snapshot_.mode = mode_;
  snapshot_.ramp = ramp_;
  snapshot_.last_valid_command_ns = last_valid_ns_;
}

void FingertipEmulator::integrate(TimeNs from_ns, TimeNs to_ns) {
  const FingertipMotorParams& mp = options_.motor;
  const std::uint32_t steps = options_.physics_substeps;
  const double h = ns_to_seconds(to_ns - from_ns) / steps;
  const double j = mp.effective_inertia_kgm2();
  const double kt = mp.torque_constant_nm_per_a;
  const double b = mp.viscous_friction_nms_per_rad;
  const bool bridges_on = latched_faults_ == 0;
  const double current_decay = mp.inductance_h > 0.0 ? std::exp(-mp.resistance_ohm * h / mp.inductance_h) : 0.0;
  for (std::uint32_t step = 0; step < steps; ++step) {
    if (step > 0) load_ = plant_(output_angles());
    for (std::size_t i = 0; i < options_.motor_count; ++i) {
      Motor& m = motors_[i];
      const double r = mp.resistance_ohm;
      const double load_torque = load_.load_torque_nm[i] / mp.gear_ratio;  // at the motor shaft
      // With its terminals shorted the motor sees 0 V whatever the bridge does.
      const bool driven = bridges_on && !m.terminal_short;
      const double u = driven ? m.voltage : 0.0;
      if (!bridges_on) {
        // The bridge is open: no current flows, the motor coasts and the mechanism may back-drive it.
        m.current = 0.0;
      } else if (mp.inductance_h > 0.0) {
        // Exact for the step's speed: the current relaxes to (u - e)/R with time constant L/R.
        const double steady = (u - kt * m.omega) / r;
        m.current = steady + (m.current - steady) * current_decay;
      }
      if (m.stuck) {
        m.omega = 0.0;
        if (bridges_on && mp.inductance_h <= 0.0) m.current = u / r;
      } else if (bridges_on && mp.inductance_h <= 0.0) {
        // No inductance: i = (u - kt ω)/R at every instant, so the back-EMF's damping is taken implicitly.
        m.omega = (m.omega + h / j * (kt * u / r - load_torque)) / (1.0 + h * (b + kt * kt / r) / j);
        m.current = (u - kt * m.omega) / r;
        m.theta += h * m.omega;
      } else {
        m.omega = (m.omega + h / j * (kt * m.current - load_torque)) / (1.0 + h * b / j);
        m.theta += h * m.omega;
      }
      m.sense_current = m.terminal_short && bridges_on ? m.voltage / kTerminalShortOhm : m.current;
      // An idle motor's current and speed decay geometrically and would go
      // subnormal, where x86 arithmetic runs about 100x slower (perf: 5% of a
      // simulated peg-in-hole trial). Nothing physical is below these.
      if (std::abs(m.current) < 1e-30) m.current = 0.0;
      if (std::abs(m.omega) < 1e-30) m.omega = 0.0;
    }
  }
  load_ = plant_(output_angles());
}

// ---------------------------------------------------------------------------
// Server.

std::string FingertipServeOptions::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "latency %.3g ms + up to %.3g ms jitter, pump every %.3g ms, stall when %.3g ms behind, seed %llu",
                static_cast<double>(latency_min_ns) / kNsPerMillisecond,
                static_cast<double>(latency_jitter_ns) / kNsPerMillisecond,
                static_cast<double>(pump_interval_ns) / kNsPerMillisecond,
                static_cast<double>(max_lag_ns) / kNsPerMillisecond, static_cast<unsigned long long>(seed));
  return buf;
}

void FingertipEmulatorServerTraits::advance(FingertipEmulator& emulator, const FingertipServeOptions& options,
                                            TimeNs now, std::vector<FingertipEmulatedReport>& out) {
  const DurationNs behind = now - emulator.now_ns();
  if (options.max_lag_ns > 0 && behind > options.max_lag_ns) {
    if (emulator.stats().stalls == 0) {
      logger().warn("emulated fingertip device: {:.0f} ms behind real time (the host is too busy to run it); it "
                    "stalls instead of catching up",
                    static_cast<double>(behind) / kNsPerMillisecond);
    }
    emulator.skip_to(now);
  }
  emulator.advance_to(now, out);
}

void FingertipEmulatorServerTraits::handle_command(FingertipEmulator& emulator, std::span<const std::uint8_t> bytes,
                                                   TimeNs now_ns) {
  emulator.handle_command(bytes, now_ns);
}

std::size_t FingertipEmulatorServerTraits::feature(FingertipEmulator& emulator, std::uint8_t report_id, TimeNs,
                                                   std::span<std::uint8_t> out) {
  if (report_id != static_cast<std::uint8_t>(FingertipReportId::device_info) || out.size() < kFingertipReportSize) {
    return 0;
  }
  const auto info = emulator.info_report();
  std::copy(info.begin(), info.end(), out.begin());
  return info.size();
}

}  // namespace proprio::devices
