#pragma once
// Fingertip sinks: where the servo loop's per-finger commands go.
//
// EmulatedFingertip runs a device emulator (haptics/fingertip_device/fingertip_emulator:
// DC motors, gearbox, PD control at 1 kHz, device-side watchdog) in process,
// stepped by the servo loop itself, with the device model (haptics) as its
// mechanics: the motors wind against model.load_torques() and the force
// sensors read model.forward() of where the motors really are. Commands go
// through the real wire encoding, so a simulated run exercises the same bytes
// as hardware. This is what `./dev demo` and `proprio haptics sim` show.
//
// HidFingertip forwards to a FingertipDevice (the USB HID driver) and reads
// its force sensors back.
#include <memory>
#include <string>

#include "proprio/fingertip_device/fingertip_device.hpp"
#include "proprio/fingertip_device/fingertip_emulator.hpp"
#include "proprio/haptics/servo_loop.hpp"

namespace proprio::haptics {

// The emulator options that match a device model (kind, motor count, limits).
devices::FingertipEmulatorOptions emulator_options_for(const FingertipDeviceModel& model);
// A device emulator whose mechanics are the model's: the motors wind against
// model.load_torques(); its three force sensors read model.forward()'s
// normal, shear_x and shear_z at the motors' actual angles.
Result<devices::FingertipEmulator> make_device_emulator(std::shared_ptr<const FingertipDeviceModel> model,
                                                        devices::FingertipEmulatorOptions options);

class EmulatedFingertip final : public FingertipSink {
 public:
  static Result<std::unique_ptr<EmulatedFingertip>> create(std::shared_ptr<const FingertipDeviceModel> model);
  static Result<std::unique_ptr<EmulatedFingertip>> create(std::shared_ptr<const FingertipDeviceModel> model,
                                                           devices::FingertipEmulatorOptions options);

  void send(const MotorAngles& motors, const FingertipForce& force, bool enabled, TimeNs now) noexcept override;
  // The emulated force sensors (true forces of the motors' actual angles).
  FingertipForce measured() const noexcept override { return measured_; }
  bool connected() const noexcept override { return true; }
  std::string describe() const override;
  const devices::FingertipEmulator& emulator() const noexcept { return emulator_; }

 private:
  EmulatedFingertip(std::shared_ptr<const FingertipDeviceModel> model, devices::FingertipEmulator emulator);
  std::shared_ptr<const FingertipDeviceModel> model_;
  devices::FingertipEmulator emulator_;
  std::uint16_t sequence_ = 0;
  bool booted_ = false;
  FingertipForce measured_;
};

class HidFingertip final : public FingertipSink {
 public:
  // The device must be started (FingertipDevice::start) and outlive the sink.
  explicit HidFingertip(std::shared_ptr<devices::FingertipDevice> device) : device_(std::move(device)) {}
  void send(const MotorAngles& motors, const FingertipForce& force, bool enabled, TimeNs now) noexcept override;
  FingertipForce measured() const noexcept override { return measured_; }
  bool connected() const noexcept override;
  std::string describe() const override;

 private:
  std::shared_ptr<devices::FingertipDevice> device_;
  FingertipForce measured_;
};

}  // namespace proprio::haptics
