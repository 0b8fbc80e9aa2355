#include "proprio/haptics/emulated_fingertip.hpp"

#include <sstream>
#include <utility>

namespace proprio::haptics {

namespace {

devices::FingertipDeviceKind kind_of(const FingertipDeviceModel& model) {
  const std::string_view k = model.kind();
  if (k == "band_2dof") return devices::FingertipDeviceKind::band_2dof;
  if (k == "platform_3dof") return devices::FingertipDeviceKind::platform_3dof;
  return devices::FingertipDeviceKind::force_vector;
}

}  // namespace

devices::FingertipEmulatorOptions emulator_options_for(const FingertipDeviceModel& model) {
  devices::FingertipEmulatorOptions o;
  o.kind = kind_of(model);
  o.motor_count = static_cast<std::uint8_t>(model.motor_count());
  // Its three force sensors read the rendered normal, shear_x and shear_z.
  o.fsr_count = 3;
  o.safety.max_normal_force_n = model.limits().max_normal_n;
  o.safety.max_shear_force_n = model.limits().max_shear_n;
  return o;
}

Result<std::unique_ptr<EmulatedFingertip>> EmulatedFingertip::create(std::shared_ptr<const FingertipDeviceModel> model) {
  if (!model) return make_error(Errc::invalid_argument, "an emulated fingertip needs a device model");
  return create(model, emulator_options_for(*model));
}

Result<devices::FingertipEmulator> make_device_emulator(std::shared_ptr<const FingertipDeviceModel> model,
                                                        devices::FingertipEmulatorOptions options) {
  if (!model) return make_error(Errc::invalid_argument, "an emulated fingertip needs a device model");
  devices::FingertipPlant plant = [model](const std::array<double, devices::kFingertipMaxMotors>& q) {
    MotorAngles angles;
    for (std::size_t i = 0; i < kMaxDeviceMotors; ++i) angles.rad[i] = q[i];
    const FingertipDeviceModel::Plant at_q = model->plant(angles);
    devices::FingertipPlantLoad load;
    load.load_torque_nm = at_q.load_torques_nm;
    const FingertipForce& f = at_q.force;
    load.fsr_force_n = {f.normal_n, f.shear_x_n, f.shear_z_n};
    return load;
  };
  devices::FingertipForceToAngles force_to_angles = [model](double n, double sx, double sz) {
    return model->inverse(model->renderable(FingertipForce{n, sx, sz})).rad;
  };
  auto emulator = devices::FingertipEmulator::create(std::move(options), std::move(plant), std::move(force_to_angles));
  if (!emulator) return emulator.error().with_context("emulating a " + std::string(model->kind()) + " device");
  return std::move(*emulator);
}

Result<std::unique_ptr<EmulatedFingertip>> EmulatedFingertip::create(std::shared_ptr<const FingertipDeviceModel> model,
                                                                     devices::FingertipEmulatorOptions options) {
  auto emulator = make_device_emulator(model, std::move(options));
  if (!emulator) return emulator.error();
  return std::unique_ptr<EmulatedFingertip>(new EmulatedFingertip(std::move(model), std::move(*emulator)));
}

EmulatedFingertip::EmulatedFingertip(std::shared_ptr<const FingertipDeviceModel> model,
                                     devices::FingertipEmulator emulator)
    : model_(std::move(model)), emulator_(std::move(emulator)) {}

void EmulatedFingertip::send(const MotorAngles& motors, const FingertipForce&, bool enabled, TimeNs now) noexcept {
  // The emulator's time starts at its boot: boot it at the first command, or
  // a CLOCK_MONOTONIC `now` would make it simulate every tick since time 0.
  if (!booted_) {
    emulator_.power_cycle(now);
    booted_ = true;
  }
  devices::FingertipCommand c;
  c.sequence = ++sequence_;
  c.mode = devices::FingertipMode::motor_angles;
  c.flags = enabled ? devices::fingertip_command_flags::enable : 0;
  c.count = static_cast<std::uint8_t>(model_->motor_count());
  // The driver's encoder, so the emulated path sends the bytes a real device would get.
  (void)devices::set_fingertip_command_values(c, motors.rad);
  c.host_time_ns = now;
  const auto bytes = devices::encode_fingertip_command(c);
  // The device runs up to now on what it had, then this command arrives and
  // applies at its next control tick, as over USB. The other order would
  // leave a command that arrives a hair after a tick pending until the next
  // send supersedes it: with the loop's clock off the device's 1 ms grid by
  // any amount, no command would ever be applied.
  emulator_.advance_to(now);
  emulator_.handle_command(bytes, now);
  const auto& truth = emulator_.snapshot().fsr_force_n;
  measured_ = FingertipForce{truth[0], truth[1], truth[2]};
}

std::string EmulatedFingertip::describe() const {
  std::ostringstream s;
  s << "emulated " << model_->kind() << " device (motor dynamics, PD at 1 kHz): " << emulator_.stats().commands_applied
    << " commands applied, " << emulator_.stats().watchdog_trips << " watchdog trips, "
    << emulator_.stats().clamped_commands << " clamped";
  return s.str();
}

void HidFingertip::send(const MotorAngles& motors, const FingertipForce&, bool enabled, TimeNs) noexcept {
  if (enabled) {
    device_->command_angles(motors.rad);
  } else {
    device_->disable();
  }
  devices::FingertipFeedbackSample fb;
  if (device_->latest_feedback(fb)) measured_ = FingertipForce{fb.fsr_force_n[0], fb.fsr_force_n[1], fb.fsr_force_n[2]};
}

bool HidFingertip::connected() const noexcept { return device_->state() == devices::FingertipLinkState::streaming; }

std::string HidFingertip::describe() const { return "USB HID fingertip device"; }

}  // namespace proprio::haptics
