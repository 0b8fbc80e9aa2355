// Fuzzes the fingertip device's HID protocol through the harness every
// protocol shares (protocol_fuzz_template.hpp: one report to every decoder,
// the input as a report stream, and again with CRCs recomputed): the three
// report decoders, the sequence-keeping streams of both ends, and the
// emulated firmware's command handling. Seeds: corpus/fingertip_protocol/
// (regenerate with PROPRIO_REGEN_CORPUS=1, see
// tests/unit/haptics/fingertip_device/test_fingertip_emulator.cpp). Every report is 64 bytes; a short
// last frame keeps its bytes as they are.
#include <cmath>
#include <limits>
#include <vector>

#include "proprio/fingertip_device/fingertip_emulator.hpp"
#include "proprio/fingertip_device/fingertip_protocol.hpp"
#include "protocol_fuzz_template.hpp"

namespace {

using namespace proprio;
using namespace proprio::devices;
using fuzz::require;

void check_counters(const FingertipLinkCounters& c) {
  std::uint64_t errors = 0;
  for (std::size_t i = 1; i < c.by_error.size(); ++i) errors += c.by_error[i];
  require(c.by_error[0] + errors == c.received);
  require(c.accepted + c.stale == c.by_error[0]);
  require(c.crc_failures + c.bad_versions + c.malformed == errors);
  require(c.sequence_gaps <= c.accepted && c.restarts <= c.accepted);
}

// The firmware: any command bytes, one tick apart, and it still keeps its limits.
void check_emulator(const fuzz::Frames& frames) {
  FingertipEmulatorOptions o;
  o.physics_substeps = 2;
  o.safety.ramp_ns = 2 * kNsPerMillisecond;
  auto emulator = FingertipEmulator::create(o);
  require(emulator.ok());
  FingertipEmulator& e = *emulator;
  std::vector<FingertipEmulatedReport> out;
  TimeNs t = 0;
  for (const auto& frame : frames) {
    (void)e.handle_command(frame, t);
    t += kNsPerMillisecond;
    out.clear();
    e.advance_to(t, out);
    const FingertipEmulatorSnapshot& s = e.snapshot();
    for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) {
      const FingertipMotorTruth& m = s.motors[i];
      require(m.target_output_rad >= o.safety.min_angle_rad && m.target_output_rad <= o.safety.max_angle_rad);
      require(std::abs(m.voltage_v) <= o.motor.supply_voltage_v);
      require(std::isfinite(m.output_angle_rad) && std::isfinite(m.current_a));
      require(!(s.status & fingertip_status::faults) || !m.bridge_on);
    }
    require(!((s.status & fingertip_status::enabled) && (s.status & fingertip_status::faults)));
    for (const FingertipEmulatedReport& r : out) {
      FingertipFeedback fb;
      require(decode_fingertip_feedback(r.bytes, fb).ok());
    }
  }
  require(e.stats().commands_applied + e.stats().commands_rejected + e.stats().commands_superseded <= frames.size() + 1);
}

struct FingertipProtocol {
  // At most 48 frames: the firmware check steps a tick per frame.
  static constexpr std::size_t kMaxFrames = 48;
  static constexpr bool kFixCrcOfShortFrames = false;
  static std::size_t frame_size(std::uint8_t) { return kFingertipReportSize; }

  static void check_reports(std::span<const std::uint8_t> bytes) {
    fuzz::check_form<FingertipCommand>(
        bytes, [](auto b, auto& v) { return decode_fingertip_command(b, v); },
        [](const auto& v) { return encode_fingertip_command(v); }, fuzz::OnReject::leaves_untouched,
        [](const FingertipCommand& c) {
          require(c.count >= 1 && c.count <= kFingertipMaxMotors);
          require(c.mode == FingertipMode::motor_angles || c.mode == FingertipMode::force);
          for (std::size_t i = c.count; i < kFingertipMaxMotors; ++i) require(c.values[i] == 0);
        });
    fuzz::check_form<FingertipFeedback>(
        bytes, [](auto b, auto& v) { return decode_fingertip_feedback(b, v); },
        [](const auto& v) { return encode_fingertip_feedback(v); }, fuzz::OnReject::leaves_untouched,
        [](const FingertipFeedback& f) {
          require(f.motor_count >= 1 && f.motor_count <= kFingertipMaxMotors && f.fsr_count <= kFingertipMaxMotors);
          require(f.ramp_permille <= 1000);
          require((f.status & ~fingertip_status::defined) == 0);
          for (std::size_t i = f.motor_count; i < kFingertipMaxMotors; ++i) {
            require(f.encoder_counts[i] == 0 && f.current_ma[i] == 0);
          }
          for (std::size_t i = f.fsr_count; i < kFingertipMaxMotors; ++i) require(f.fsr_force_mn[i] == 0);
        });
    fuzz::check_form<FingertipDeviceInfo>(
        bytes, [](auto b, auto& v) { return decode_fingertip_info(b, v); },
        [](const auto& v) { return encode_fingertip_info(v); }, fuzz::OnReject::leaves_untouched,
        [](const FingertipDeviceInfo& info) {
          require(info.min_angle_urad < info.max_angle_urad);
          require(info.feedback_rate_hz >= 1 && info.feedback_rate_hz <= info.control_rate_hz);
          require(std::isfinite(info.output_angle_rad(std::numeric_limits<std::int32_t>::max())));
          require(info.serial_view().size() <= kFingertipSerialLength);
          require(!describe(info).empty());
        });
  }

  // The host's feedback stream and the device's command stream keep their
  // counters consistent; the firmware keeps its limits.
  static void check_streams(const fuzz::Frames& frames, bool) {
    FingertipFeedbackStream host;
    FingertipCommandStream device;
    FingertipFeedback f;
    FingertipCommand c;
    for (const auto& frame : frames) {
      (void)host.push(frame, f);
      (void)device.push(frame, c);
    }
    check_counters(host.counters());
    check_counters(device.counters());
    check_emulator(frames);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return proprio::fuzz::fuzz_protocol<FingertipProtocol>(data, size);
}
