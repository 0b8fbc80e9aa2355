#include "proprio/imu_glove_board/imu_glove_emulator.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace proprio::devices {

namespace {

// Sub-stream numbers under the emulator's seed (mix_seed) for the glove's own random effects.
enum Stream : std::uint64_t { kStaleStream = hid::kFirstDeviceFaultStream };

constexpr const char* kWho = "glove emulator";

}  // namespace

bool ImuGloveEmulatorFaults::any() const noexcept {
  return drop_probability > 0 || duplicate_probability > 0 || corrupt_probability > 0 || reorder_probability > 0 ||
         stale_probability > 0 || !unplugs.empty();
}

Status ImuGloveEmulatorFaults::validate() const {
  for (const auto& [p, name] : {std::pair{drop_probability, "drop_probability"},
                                {duplicate_probability, "duplicate_probability"},
                                {corrupt_probability, "corrupt_probability"},
                                {reorder_probability, "reorder_probability"},
                                {stale_probability, "stale_probability"}}) {
    if (auto s = hid::check_fault_probability(kWho, name, p); !s) return s;
  }
  return hid::check_fault_outages(kWho, unplugs);
}

Status ImuGloveEmulatorOptions::validate() const {
  if (imu_count == 0 || imu_count > kImuGloveMaxImus) {
    return make_error(Errc::invalid_argument, "glove emulator: imu_count = " + std::to_string(imu_count) +
                                                  "; the protocol carries 1 to " + std::to_string(kImuGloveMaxImus));
  }
  if (rate_hz == 0 || rate_hz > kImuGloveMaxRateHz) {
    return make_error(Errc::invalid_argument, "glove emulator: rate_hz = " + std::to_string(rate_hz) +
                                                  "; the protocol allows 1 to " + std::to_string(kImuGloveMaxRateHz));
  }
  // Real crystals are within ±100 ppm; 1000 leaves room for stress tests and keeps the counter sane.
  if (!(std::fabs(clock_error_ppm) <= 1000.0)) {
    return make_error(Errc::invalid_argument, "glove emulator: clock_error_ppm = " + std::to_string(clock_error_ppm) +
                                                  "; use a value within ±1000 (a crystal is within ±100)");
  }
  if (report_spacing_ns < 0) {
    return make_error(Errc::invalid_argument, "glove emulator: report_spacing_ns must not be negative");
  }
  return faults.validate();
}

Result<ImuGloveEmulator> ImuGloveEmulator::create(ImuGloveEmulatorOptions options) {
  if (auto s = options.validate(); !s) return s.error();
  return ImuGloveEmulator(std::move(options));
}

ImuGloveEmulator::ImuGloveEmulator(ImuGloveEmulatorOptions options)
    : options_(std::move(options)),
      link_faults_(options_.seed),
      stale_rng_(mix_seed(options_.seed, kStaleStream)),
      rate_hz_(options_.rate_hz),
      accel_range_(options_.accel_range),
      gyro_range_(options_.gyro_range),
      last_raw_(options_.imu_count),
      tick_raw_(options_.imu_count) {
  // Powered from boot_time_ns on, so that commands sent before the first tick reach a running glove.
  boot(options_.boot_time_ns);
}

bool ImuGloveEmulator::powered_at(TimeNs t_ns) const noexcept {
  if (t_ns < options_.boot_time_ns) return false;
  for (const ImuGloveOutage& o : options_.faults.unplugs) {
    if (t_ns >= o.at_ns && t_ns < o.at_ns + o.duration_ns) return false;
  }
  return true;
}

namespace {
// The power-up before t: the first boot, or the end of the latest outage before t.
TimeNs boot_before(const ImuGloveEmulatorOptions& o, TimeNs t_ns) noexcept {
  TimeNs boot = o.boot_time_ns;
  for (const ImuGloveOutage& u : o.faults.unplugs) {
    const TimeNs end = u.at_ns + u.duration_ns;
    if (end <= t_ns && end > boot && u.at_ns >= o.boot_time_ns) boot = end;
  }
  return boot;
}
}  // namespace

std::uint32_t ImuGloveEmulator::device_timestamp_us(TimeNs t_ns) const noexcept {
  return hid::emulated_counter_us(boot_before(options_, t_ns), t_ns, options_.boot_timestamp_us,
                                  options_.clock_error_ppm);
}

void ImuGloveEmulator::boot(TimeNs t_ns) noexcept {
  powered_ = true;
  last_boot_ns_ = t_ns;
  ++stats_.boots;
  // Volatile configuration: a power cycle restores the defaults.
  streaming_ = options_.stream_on_boot;
  restart_pending_ = true;
  rate_hz_ = options_.rate_hz;
  accel_range_ = options_.accel_range;
  gyro_range_ = options_.gyro_range;
  last_token_ = 0;
  last_result_ = ImuGloveCommandResult::none;
  has_ticked_ = false;
  overrun_pending_ = false;
  last_raw_.assign(options_.imu_count, ImuGloveImuRaw{});
}

Status ImuGloveEmulator::tick(TimeNs t_ns, std::span<const ImuSample> samples, std::vector<ImuGloveEmulatedReport>& out) {
  if (samples.size() != options_.imu_count) {
    return make_error(Errc::invalid_argument, "glove emulator: tick got " + std::to_string(samples.size()) +
                                                  " IMU readings for a glove with " +
                                                  std::to_string(options_.imu_count));
  }
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (samples[i].sensor_id != i) {
      return make_error(Errc::invalid_argument, "glove emulator: reading " + std::to_string(i) + " has sensor_id " +
                                                    std::to_string(samples[i].sensor_id) +
                                                    "; pass one reading per IMU in sensor_id order");
    }
  }
  if (t_ns < options_.boot_time_ns) {
    ++stats_.ticks_unpowered;  // not plugged in for the first time yet
    return {};
  }
  if (!powered_at(t_ns)) {
    if (powered_) link_faults_.discard_held();  // whatever sat in the transmit buffer dies with the power
    powered_ = false;
    ++stats_.ticks_unpowered;
    return {};
  }
  const TimeNs boot_ns = boot_before(options_, t_ns);
  if (!powered_ || boot_ns != last_boot_ns_) {
    link_faults_.discard_held();
    boot(boot_ns);
  }
  if (!streaming_) return {};

  if (restart_pending_) {
    sequence_ = 0;
  } else if (has_ticked_) {
    // Ticks the caller skipped are ticks the firmware could not sample: they
    // still use up sequence numbers, so the host sees the gap, and the next
    // tick says the device lost them itself.
    const double periods = static_cast<double>(t_ns - last_tick_ns_) * rate_hz_ * 1e-9;
    if (periods > 1.5) {
      sequence_ = static_cast<std::uint16_t>(sequence_ + std::llround(periods) - 1);
      overrun_pending_ = true;
    }
  }

  ImuGloveDataReport report;
  report.imu_total = options_.imu_count;
  report.sequence = sequence_;
  report.timestamp_us = device_timestamp_us(t_ns);
  report.flags = static_cast<std::uint8_t>((restart_pending_ ? data_flags::stream_start : 0) |
                                           (overrun_pending_ ? data_flags::overrun : 0));
  report.accel_range = accel_range_;
  report.gyro_range = gyro_range_;

  // Every IMU draws its stale decision every tick, so the draws do not depend on the other faults.
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const bool stale = stale_rng_.uniform01() < options_.faults.stale_probability;
    if (stale && has_ticked_) {
      tick_raw_[i] = last_raw_[i];
      tick_raw_[i].status |= imu_status::stale;
      ++stats_.stale_samples;
    } else {
      tick_raw_[i] = last_raw_[i] = quantise_imu(samples[i], accel_range_, gyro_range_);
      if (tick_raw_[i].status & (imu_status::accel_saturated | imu_status::gyro_saturated)) {
        ++stats_.saturated_samples;
      }
      if (tick_raw_[i].status & imu_status::sensor_error) ++stats_.error_samples;
    }
  }

  const std::size_t parts = (options_.imu_count + kImuGloveImusPerReport - 1) / kImuGloveImusPerReport;
  for (std::size_t p = 0; p < parts; ++p) {
    report.first_imu = static_cast<std::uint8_t>(p * kImuGloveImusPerReport);
    report.imus = {};
    for (std::size_t b = 0; b < report.block_count(); ++b) {
      const std::size_t i = report.first_imu + b;
      report.imus[b] = tick_raw_[i];
    }
    ImuGloveEmulatedReport r;
    r.send_ns = t_ns + static_cast<DurationNs>(p) * options_.report_spacing_ns;
    r.bytes = encode_data_report(report);
    send(r, out);
  }

  ++stats_.ticks;
  sequence_ = static_cast<std::uint16_t>(sequence_ + 1);
  restart_pending_ = false;
  overrun_pending_ = false;
  last_tick_ns_ = t_ns;
  has_ticked_ = true;
  return {};
}

void ImuGloveEmulator::send(const ImuGloveEmulatedReport& report, std::vector<ImuGloveEmulatedReport>& out) {
  link_faults_.send(report, options_.faults, stats_, out);
}

void ImuGloveEmulator::flush(std::vector<ImuGloveEmulatedReport>& out) { link_faults_.flush(stats_, out); }

ImuGloveCommandResult ImuGloveEmulator::handle_command(std::span<const std::uint8_t> bytes) {
  ImuGloveCommand c;
  const ImuGloveDecodeStatus s = decode_command(bytes, c);
  if (!s) {
    last_result_ = s.code == ImuGloveDecodeErrc::unknown_command ? ImuGloveCommandResult::unknown_command
                                                               : ImuGloveCommandResult::bad_report;
    return last_result_;
  }
  ImuGloveCommandResult result = ImuGloveCommandResult::ok;
  switch (c.op) {
    case ImuGloveCommandOp::start_streaming:
      streaming_ = true;
      restart_pending_ = true;
      break;
    case ImuGloveCommandOp::stop_streaming:
      streaming_ = false;
      break;
    case ImuGloveCommandOp::set_rate:
      if (c.rate_hz == 0 || c.rate_hz > kImuGloveMaxRateHz) {
        result = ImuGloveCommandResult::bad_argument;
      } else {
        rate_hz_ = c.rate_hz;
        restart_pending_ = true;
      }
      break;
    case ImuGloveCommandOp::set_ranges:
      accel_range_ = c.accel_range;
      gyro_range_ = c.gyro_range;
      restart_pending_ = true;
      break;
  }
  last_token_ = c.token;
  last_result_ = result;
  return result;
}

std::array<std::uint8_t, kImuGloveInfoReportSize> ImuGloveEmulator::info_report(TimeNs t_ns) const {
  ImuGloveDeviceInfo info;
  info.firmware = options_.firmware;
  info.imu_count = options_.imu_count;
  info.rate_hz = rate_hz_;
  info.accel_range = accel_range_;
  info.gyro_range = gyro_range_;
  info.streaming = streaming_ && powered_at(t_ns);
  info.last_command_token = last_token_;
  info.last_command_result = last_result_;
  info.timestamp_us = device_timestamp_us(t_ns);
  return encode_info_report(info);
}

// ---------------------------------------------------------------------------

void ImuGloveEmulatorServerTraits::advance(ImuGloveTicker& glove, const ImuGloveServeOptions&, TimeNs now_ns,
                                           std::vector<ImuGloveEmulatedReport>& out) {
  const std::size_t imus = glove.emulator.options().imu_count;
  while (glove.next_tick_ns <= now_ns) {
    glove.scratch.assign(imus, ImuSample{});
    for (std::size_t i = 0; i < imus; ++i) glove.scratch[i].sensor_id = static_cast<std::uint16_t>(i);
    if (glove.readings) glove.readings(glove.ticks, glove.next_tick_ns, glove.scratch);
    if (!glove.emulator.tick(glove.next_tick_ns, glove.scratch, out)) ++glove.refused_ticks;
    ++glove.ticks;
    glove.next_tick_ns += kNsPerSecond / std::max<std::uint16_t>(glove.emulator.rate_hz(), 1);
  }
}

void ImuGloveEmulatorServerTraits::handle_command(ImuGloveTicker& glove, std::span<const std::uint8_t> bytes, TimeNs) {
  (void)glove.emulator.handle_command(bytes);
}

std::size_t ImuGloveEmulatorServerTraits::feature(ImuGloveTicker& glove, std::uint8_t report_id, TimeNs now_ns,
                                                  std::span<std::uint8_t> out) {
  if (report_id != static_cast<std::uint8_t>(ImuGloveReportId::device_info) || out.size() < kImuGloveInfoReportSize) {
    return 0;
  }
  const auto info = glove.emulator.info_report(now_ns);
  std::copy(info.begin(), info.end(), out.begin());
  return info.size();
}

}  // namespace proprio::devices
