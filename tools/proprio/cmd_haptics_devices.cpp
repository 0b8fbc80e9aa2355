// proprio haptics devices | test: real (USB HID) or emulated fingertip devices.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>

#include "commands.hpp"
#include "proprio/core/data_dir.hpp"
#include "proprio/core/log.hpp"
#include "proprio/fingertip_device/fingertip_device.hpp"
#include "proprio/fingertip_device/fingertip_emulator.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/safety.hpp"

namespace proprio::cli {
namespace {

using namespace proprio::haptics;

int run_devices() {
  auto list = devices::enumerate_fingertip_devices();
  if (!list) return report_error(list.error());
  if (list->empty()) {
    std::printf(
        "No fingertip haptic devices found (USB VID 0x%04x, PID 0x%04x).\n"
        "Plugged in but not listed? Check permissions on /dev/hidraw* (docs/fingertip-hid-protocol.md).\n"
        "To try without hardware: proprio haptics test --device emulated --force 1.0\n",
        devices::kFingertipUsbVendorId, devices::kFingertipUsbProductId);
    return 0;
  }
  std::printf("%-20s %-18s %-10s %s\n", "path", "serial", "release", "product");
  for (const auto& d : *list) {
    std::printf("%-20s %-18s 0x%04x     %s %s\n", d.path.c_str(), d.serial.c_str(), d.release, d.manufacturer.c_str(),
                d.product.c_str());
  }
  std::printf("Use --device <serial or path> with 'proprio haptics test'.\n");
  return 0;
}

struct TestArgs {
  std::string device = "emulated";
  std::string model;  // default: by the device's kind
  double force_n = 1.0;
  double shear_n = 0.3;
  double seconds = 4.0;
};

std::string default_model_for(devices::FingertipDeviceKind kind) {
  const std::string dir = data_path("haptics") + "/";
  switch (kind) {
    case devices::FingertipDeviceKind::band_2dof: return dir + "band_2dof.toml";
    case devices::FingertipDeviceKind::platform_3dof: return dir + "platform_3dof.toml";
    default: return dir + "force_vector.toml";
  }
}

// The safe test pattern: after the gate's ramp-in, hold `force` normal, then
// sweep the shear (both directions, within the friction cone), then release.
FingertipForce pattern(double t, double duration, double force, double shear) {
  FingertipForce f;
  const double u = t / duration;
  if (u < 0.9) f.normal_n = force;
  if (u >= 0.4 && u < 0.8) {
    const double phase = (u - 0.4) / 0.4 * 2.0 * M_PI;
    f.shear_z_n = shear * std::sin(phase);
    f.shear_x_n = shear * std::sin(2.0 * phase);
  }
  return f;
}

int run_test(const TestArgs& a) {
  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<devices::FingertipEmulatorServer> server;
  std::unique_ptr<hid::HidTransport> transport;
  std::shared_ptr<const FingertipDeviceModel> model;
  if (a.device == "emulated") {
    auto loaded = load_device_model(a.model.empty() ? default_model_for(devices::FingertipDeviceKind::platform_3dof) : a.model);
    if (!loaded) return report_error(loaded.error());
    model = std::shared_ptr<const FingertipDeviceModel>(std::move(*loaded));
    // The emulated device speaks the same bytes over an in-memory link.
    auto emulator = make_device_emulator(model, emulator_options_for(*model));
    if (!emulator) return report_error(emulator.error());
    link = std::make_shared<hid::FakeHidLink>();
    server = std::make_unique<devices::FingertipEmulatorServer>(std::move(*emulator), link);
    server->start();
    transport = std::make_unique<hid::FakeHidTransport>(link);
  } else {
    const bool is_path = a.device.rfind("/dev/", 0) == 0;
    if (is_path) {
      if (auto s = hid::check_hidraw_node(a.device); !s) return report_error(s.error());
    }
    transport = std::make_unique<hid::HidapiTransport>(
        devices::fingertip_device_selector(is_path ? std::string() : a.device, is_path ? a.device : std::string()));
  }
  auto device = std::make_shared<devices::FingertipDevice>(std::move(transport));
  if (auto s = device->start(); !s) return report_error(s.error());
  // Wait for the device and its info report.
  const auto connect_deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (device->state() != devices::FingertipLinkState::streaming && std::chrono::steady_clock::now() < connect_deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (device->state() != devices::FingertipLinkState::streaming) {
    return report_error(make_error(Errc::not_found, "fingertip device '" + a.device +
                                                        "' did not come up within 5 s; list devices with "
                                                        "'proprio haptics devices'"));
  }
  if (!model) {
    auto loaded = load_device_model(a.model.empty() ? default_model_for(devices::FingertipDeviceKind::force_vector) : a.model);
    if (!loaded) return report_error(loaded.error());
    model = std::shared_ptr<const FingertipDeviceModel>(std::move(*loaded));
  }
  std::printf("Device %s, model %s\n%s\n", a.device.c_str(), std::string(model->kind()).c_str(), model->describe().c_str());

  SafetyGate gate(*model);
  const auto start = std::chrono::steady_clock::now();
  gate.engage(MonotonicClock::instance().now_ns());
  double max_err = 0.0;
  int lines = 0;
  for (;;) {
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (t >= a.seconds) break;
    const TimeNs now = MonotonicClock::instance().now_ns();
    gate.command(pattern(t, a.seconds, a.force_n, a.shear_n), now);
    const FingertipForce out = gate.output(now);
    const MotorAngles q = model->inverse(out);
    if (device->command_angles(q.rad) == devices::FingertipCommandStatus::not_connected) {
      return report_error(make_error(Errc::unavailable, "the device went away during the test; it was left at rest"));
    }
    devices::FingertipFeedbackSample fb;
    if (device->latest_feedback(fb) && t > 0.2 * a.seconds && t < 0.35 * a.seconds) {
      max_err = std::max(max_err, std::abs(fb.fsr_force_n[0] - out.normal_n));
    }
    if (t * 4 >= lines) {
      ++lines;
      std::printf("t %4.2f s  commanded n %5.2f sx %5.2f sz %5.2f N  device sensors %5.2f %5.2f %5.2f N  gate %s\n", t,
                  out.normal_n, out.shear_x_n, out.shear_z_n, fb.fsr_force_n[0], fb.fsr_force_n[1], fb.fsr_force_n[2],
                  std::string(to_string(gate.state())).c_str());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  gate.disengage();
  device->disable();
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  device->stop();
  if (server) server->stop();
  std::printf("Done; the device was sent to rest. %s\nLargest normal-force difference while holding: %.3f N\n",
              gate.stats().describe().c_str(), max_err);
  // A gate that refused commands (non-finite forces) kept the device safe, but
  // the test did not run as asked: that is a failure, not a pass.
  if (gate.stats().nan_commands > 0) {
    return report_error(make_error(Errc::invalid_argument,
                                   "the safety gate refused " + std::to_string(gate.stats().nan_commands) +
                                       " non-finite force command(s) and output zero instead; the pattern did not "
                                       "run as asked"));
  }
  return 0;
}

}  // namespace

void add_haptics_device_commands(CLI::App& haptics, int& exit_code) {
  auto* d = haptics.add_subcommand("devices", "List fingertip haptic devices on USB HID");
  d->callback([&exit_code] { exit_code = run_devices(); });

  auto args = std::make_shared<TestArgs>();
  auto* t = haptics.add_subcommand(
      "test",
      "Run a safe test pattern on one device: ramp in, hold a normal force, sweep the shear inside the\n"
      "friction cone, release; everything through the safety gate (clamp, rate limit, watchdog).");
  t->add_option("--device", args->device, "serial number, /dev/hidrawN, or 'emulated' (no hardware)")
      ->capture_default_str();
  t->add_option("--model", args->model, "device model TOML (default: config/haptics/<kind>.toml)");
  t->add_option("--force", args->force_n, "normal force to hold (N); the model's limit clamps it")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  t->add_option("--shear", args->shear_n, "shear amplitude (N)")->check(CLI::Range(0.0, 5.0))->capture_default_str();
  t->add_option("--seconds", args->seconds, "pattern length")->check(CLI::Range(1.0, 60.0))->capture_default_str();
  t->callback([args, &exit_code] { exit_code = run_test(*args); });
}

}  // namespace proprio::cli
