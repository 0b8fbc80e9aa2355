// Fuzzes the fingertip device's HID protocol: the three report decoders, the
// sequence-keeping streams of both ends, and the emulated firmware's command
// handling. Whatever the bytes, nothing may crash, hang or invoke undefined
// behaviour (the fuzz and ASan builds check), and the decoders' own promises
// must hold. Seeds: corpus/fingertip_protocol/ (regenerate with
// PROPRIO_REGEN_CORPUS=1, see tests/unit/test_fingertip_emulator.cpp).
//
// The input is read three ways:
//  1. as one report, handed to every decoder;
//  2. as 64-byte frames (the last one short), fed to the host's feedback
//     stream, the device's command stream and the emulator as commands, one
//     control tick apart;
//  3. as 2., with every full frame's CRC recomputed, so that mutations get
//     past the CRC to the field checks, the sequence logic and the firmware.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <vector>

#include "proprio/devices/fingertip_emulator.hpp"
#include "proprio/devices/fingertip_protocol.hpp"

using namespace proprio;
using namespace proprio::devices;

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

void check_single(std::span<const std::uint8_t> bytes) {
  FingertipCommand c;
  const FingertipDecodeStatus cs = decode_fingertip_command(bytes, c);
  if (cs) {
    FingertipCommand again;
    require(decode_fingertip_command(encode_fingertip_command(c), again).ok() && again == c);
    require(c.count >= 1 && c.count <= kFingertipMaxMotors);
    require(c.mode == FingertipMode::motor_angles || c.mode == FingertipMode::force);
    for (std::size_t i = c.count; i < kFingertipMaxMotors; ++i) require(c.values[i] == 0);
  } else {
    require(!describe(cs).empty() && !to_error(cs).message.empty());
  }
  FingertipFeedback f;
  const FingertipDecodeStatus fs = decode_fingertip_feedback(bytes, f);
  if (fs) {
    FingertipFeedback again;
    require(decode_fingertip_feedback(encode_fingertip_feedback(f), again).ok() && again == f);
    require(f.motor_count >= 1 && f.motor_count <= kFingertipMaxMotors && f.fsr_count <= kFingertipMaxMotors);
    require(f.ramp_permille <= 1000);
    require((f.status & ~fingertip_status::defined) == 0);
    for (std::size_t i = f.motor_count; i < kFingertipMaxMotors; ++i) require(f.encoder_counts[i] == 0 && f.current_ma[i] == 0);
    for (std::size_t i = f.fsr_count; i < kFingertipMaxMotors; ++i) require(f.fsr_force_mn[i] == 0);
  } else {
    require(!describe(fs).empty());
  }
  FingertipDeviceInfo info;
  const FingertipDecodeStatus is = decode_fingertip_info(bytes, info);
  if (is) {
    FingertipDeviceInfo again;
    require(decode_fingertip_info(encode_fingertip_info(info), again).ok() && again == info);
    require(info.min_angle_urad < info.max_angle_urad);
    require(info.feedback_rate_hz >= 1 && info.feedback_rate_hz <= info.control_rate_hz);
    require(std::isfinite(info.output_angle_rad(std::numeric_limits<std::int32_t>::max())));
    require(info.serial_view().size() <= kFingertipSerialLength);
    require(!describe(info).empty());
  } else {
    require(!describe(is).empty());
  }
}

void fix_crc(std::vector<std::uint8_t>& frame) {
  if (frame.size() != kFingertipReportSize) return;
  const std::uint16_t crc = crc16_ccitt(std::span<const std::uint8_t>(frame).first(62));
  frame[62] = static_cast<std::uint8_t>(crc);
  frame[63] = static_cast<std::uint8_t>(crc >> 8);
}

void check_counters(const FingertipLinkCounters& c) {
  std::uint64_t errors = 0;
  for (std::size_t i = 1; i < c.by_error.size(); ++i) errors += c.by_error[i];
  require(c.by_error[0] + errors == c.received);
  require(c.accepted + c.stale == c.by_error[0]);
  require(c.crc_failures + c.bad_versions + c.malformed == errors);
  require(c.sequence_gaps <= c.accepted && c.restarts <= c.accepted);
}

void check_stream(const std::vector<std::vector<std::uint8_t>>& frames) {
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

  // The firmware: any command bytes, one tick apart, and it still keeps its limits.
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

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);
  check_single(bytes);
  // Frames: at most 48 (the firmware check steps a tick per frame).
  std::vector<std::vector<std::uint8_t>> frames;
  for (std::size_t at = 0; at < size && frames.size() < 48; at += kFingertipReportSize) {
    const std::size_t n = std::min(kFingertipReportSize, size - at);
    frames.emplace_back(data + at, data + at + n);
  }
  check_stream(frames);
  for (auto& frame : frames) {
    fix_crc(frame);
    check_single(frame);
  }
  check_stream(frames);
  return 0;
}
