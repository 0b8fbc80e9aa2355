#include "proprio/ftm_board/ftm_emulator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace proprio::devices {

namespace {

// Sub-stream numbers under the emulator's seed (mix_seed) for the board's own random effects.
enum Stream : std::uint64_t { kOverrunStream = hid::kFirstDeviceFaultStream };

constexpr TimeNs kNever = std::numeric_limits<TimeNs>::max();
constexpr const char* kWho = "FTM board emulator";

Status bad_option(const std::string& what) {
  return make_error(Errc::invalid_argument, std::string(kWho) + ": " + what);
}

bool powered(const FtmEmulatorOptions& o, TimeNs t_ns) noexcept {
  if (t_ns < o.boot_time_ns) return false;
  for (const FtmOutage& u : o.faults.unplugs) {
    if (t_ns >= u.at_ns && t_ns < u.at_ns + u.duration_ns) return false;
  }
  return true;
}

// The power-up before t: the first boot, or the end of the latest outage
// before t after which the power really was back (outages may overlap).
TimeNs boot_before(const FtmEmulatorOptions& o, TimeNs t_ns) noexcept {
  TimeNs boot = o.boot_time_ns;
  for (const FtmOutage& u : o.faults.unplugs) {
    const TimeNs end = u.at_ns + u.duration_ns;
    if (end <= t_ns && end > boot && u.at_ns >= o.boot_time_ns && powered(o, end)) boot = end;
  }
  return boot;
}

// The firmware paces ticks with a timer of whole device µs.
std::uint16_t period_us_of(std::uint16_t rate_hz) noexcept {
  return static_cast<std::uint16_t>(std::lround(1e6 / static_cast<double>(std::max<std::uint16_t>(rate_hz, 1))));
}

}  // namespace

bool FtmEmulatorFaults::any() const noexcept {
  return drop_probability > 0 || duplicate_probability > 0 || corrupt_probability > 0 || reorder_probability > 0 ||
         device_overrun_probability > 0 || !unplugs.empty();
}

Status FtmEmulatorFaults::validate() const {
  for (const auto& [p, name] : {std::pair{drop_probability, "drop_probability"},
                                {duplicate_probability, "duplicate_probability"},
                                {corrupt_probability, "corrupt_probability"},
                                {reorder_probability, "reorder_probability"},
                                {device_overrun_probability, "device_overrun_probability"}}) {
    if (auto s = hid::check_fault_probability(kWho, name, p); !s) return s;
  }
  return hid::check_fault_outages(kWho, unplugs);
}

Status FtmEmulatorOptions::validate() const {
  if (imu_rate_hz < kFtmMinImuRateHz || imu_rate_hz > kFtmMaxImuRateHz) {
    return bad_option("imu_rate_hz = " + std::to_string(imu_rate_hz) + "; the protocol allows " +
                      std::to_string(kFtmMinImuRateHz) + " to " + std::to_string(kFtmMaxImuRateHz) + " Hz");
  }
  if (bend_rate_hz < kFtmMinBendRateHz || bend_rate_hz > kFtmMaxBendRateHz) {
    return bad_option("bend_rate_hz = " + std::to_string(bend_rate_hz) + "; the protocol allows " +
                      std::to_string(kFtmMinBendRateHz) + " to " + std::to_string(kFtmMaxBendRateHz) + " Hz");
  }
  if (ftm_reports_per_second(imu_rate_hz, bend_rate_hz) > kFtmMaxReportsPerSecond) {
    return bad_option("imu_rate_hz = " + std::to_string(imu_rate_hz) + " with bend_rate_hz = " +
                      std::to_string(bend_rate_hz) + " needs more than 1000 reports/s (2 x IMU rate + bend rate / 5), "
                      "more than a full-speed interrupt endpoint carries");
  }
  if (static_cast<unsigned>(accel_range) > 3 || static_cast<unsigned>(gyro_range) > 3) {
    return bad_option("accel_range / gyro_range must be one of the MPU-9250's four codes (0-3)");
  }
  if (!(std::fabs(clock_error_ppm) <= 1000.0)) {
    return bad_option("clock_error_ppm = " + std::to_string(clock_error_ppm) +
                      "; use a value within ±1000 (a crystal is within ±100)");
  }
  if (bend_samples_per_report == 0 || bend_samples_per_report > kFtmBendSamplesPerReport) {
    return bad_option("bend_samples_per_report = " + std::to_string(bend_samples_per_report) + "; use 1 to " +
                      std::to_string(kFtmBendSamplesPerReport));
  }
  return faults.validate();
}

Result<FtmBoardEmulator> FtmBoardEmulator::create(FtmEmulatorOptions options,
                                                  std::unique_ptr<ftm::FtmSampleFeed> feed) {
  if (auto s = options.validate(); !s) return s.error();
  if (!feed) return bad_option("no sample feed; pass an ftm::FtmSampleFeed (the simulated wearer)").error();
  return FtmBoardEmulator(std::move(options), std::move(feed));
}

FtmBoardEmulator::FtmBoardEmulator(FtmEmulatorOptions options, std::unique_ptr<ftm::FtmSampleFeed> feed)
    : options_(std::move(options)),
      feed_(std::move(feed)),
      link_faults_(options_.seed),
      overrun_rng_(mix_seed(options_.seed, kOverrunStream)),
      now_ns_(options_.boot_time_ns) {
  for (auto& m : mag_latest_) m = Vec3::Zero();
  // Powered from boot_time_ns on, so that commands sent before the first advance reach a running board.
  if (powered(options_, now_ns_)) boot(now_ns_);
}

bool FtmBoardEmulator::powered_at(TimeNs t_ns) const noexcept { return powered(options_, t_ns); }

std::uint32_t FtmBoardEmulator::device_timestamp_us(TimeNs t_ns) const noexcept {
  return hid::emulated_counter_us(boot_before(options_, t_ns), t_ns, options_.boot_timestamp_us,
                                  options_.clock_error_ppm);
}

TimeNs FtmBoardEmulator::imu_tick_time_ns(std::uint64_t n) const noexcept {
  return run_start_ns_ + std::llround(static_cast<double>(n) * imu_period_ns_);
}
TimeNs FtmBoardEmulator::bend_tick_time_ns(std::uint64_t n) const noexcept {
  return run_start_ns_ + std::llround(static_cast<double>(n) * bend_period_ns_);
}

void FtmBoardEmulator::boot(TimeNs t_ns) noexcept {
  powered_ = true;
  ++stats_.boots;
  // Volatile configuration: a power cycle restores the defaults.
  streaming_ = options_.stream_on_boot;
  imu_rate_hz_ = options_.imu_rate_hz;
  bend_rate_hz_ = options_.bend_rate_hz;
  accel_range_ = options_.accel_range;
  gyro_range_ = options_.gyro_range;
  last_token_ = 0;
  last_result_ = FtmCommandResult::none;
  link_faults_.discard_held();
  restart_run(t_ns);
}

void FtmBoardEmulator::restart_run(TimeNs t_ns) noexcept {
  discard_batch();
  // Ticks are whole device µs apart; in true time off by the crystal's error.
  const double scale = 1000.0 / (1.0 + options_.clock_error_ppm * 1e-6);
  imu_period_ns_ = period_us_of(imu_rate_hz_) * scale;
  bend_period_ns_ = period_us_of(bend_rate_hz_) * scale;
  run_start_ns_ = t_ns;
  next_imu_ = 0;
  next_bend_ = 0;
  // An overrun before the restart means nothing to sequences that start again.
  pending_flags_.fill(ftm_flags::stream_start);
}

void FtmBoardEmulator::discard_batch() noexcept {
  stats_.discarded_partial += batch_.count;
  batch_.count = 0;
  batch_.samples = {};
}

TimeNs FtmBoardEmulator::next_power_event_after(TimeNs t_ns) const noexcept {
  TimeNs next = options_.boot_time_ns > t_ns ? options_.boot_time_ns : kNever;
  for (const FtmOutage& u : options_.faults.unplugs) {
    if (u.at_ns > t_ns) next = std::min(next, u.at_ns);
    const TimeNs end = u.at_ns + u.duration_ns;
    if (end > t_ns) next = std::min(next, end);
  }
  return next;
}

void FtmBoardEmulator::advance_to(TimeNs t_ns, std::vector<FtmEmulatedReport>& out) {
  if (t_ns < now_ns_) return;
  for (;;) {
    const bool on = powered_ && streaming_;
    const TimeNs ti = on ? imu_tick_time_ns(next_imu_) : kNever;
    const TimeNs tb = on ? bend_tick_time_ns(next_bend_) : kNever;
    const TimeNs tm = std::min(ti, tb);
    const TimeNs ev = next_power_event_after(now_ns_);
    if (std::min(tm, ev) > t_ns) break;
    if (ev <= tm) {
      now_ns_ = ev;
      const bool power = powered(options_, ev);
      if (powered_ && !power) {
        // Whatever sat in the board's buffers dies with the power.
        discard_batch();
        link_faults_.discard_held();
        powered_ = false;
      } else if (!powered_ && power) {
        boot(ev);
      }
      continue;
    }
    now_ns_ = tm;
    pull_feed(tm);
    // Ties: the IMUs first, as a feed orders them.
    if (ti <= tb) {
      imu_tick(tm, out);
    } else {
      bend_tick(tm, out);
    }
  }
  now_ns_ = t_ns;
}

void FtmBoardEmulator::pull_feed(TimeNs t_ns) {
  if (t_ns <= fed_to_ns_) return;
  fed_to_ns_ = t_ns;
  events_.clear();
  feed_->advance(t_ns, events_);
  for (const ftm::FtmEvent& e : events_) {
    if (e.kind == ftm::FtmEvent::Kind::imu && e.index < ftm::kFtmImuCount) {
      imu_latest_[e.index] = e.imu;
      imu_new_[e.index] = true;
      if (e.imu.mag_fresh) {
        mag_latest_[e.index] = e.imu.mag_uT;
        mag_overflow_[e.index] = e.imu.status & ftm::sample_status::mag_overflow;
        mag_new_[e.index] = true;
      }
    } else if (e.kind == ftm::FtmEvent::Kind::bend && e.index < ftm::kFtmBendCount) {
      bend_latest_[e.index] = e.bend;
      bend_new_[e.index] = true;
    }
  }
}

void FtmBoardEmulator::imu_tick(TimeNs t_ns, std::vector<FtmEmulatedReport>& out) {
  namespace st = ftm::sample_status;
  const std::uint64_t tick = next_imu_++;
  ++stats_.imu_ticks;
  FtmImuReport r;
  r.sequence = static_cast<std::uint32_t>(tick);  // wraps like the firmware's counter
  r.timestamp_us = device_timestamp_us(t_ns);
  r.accel_range = accel_range_;
  r.gyro_range = gyro_range_;
  r.period_us = period_us_of(imu_rate_hz_);
  for (std::size_t pair = 0; pair < ftm::kFtmImuCount / kFtmImusPerReport; ++pair) {
    r.first_imu = static_cast<std::uint8_t>(pair * kFtmImusPerReport);
    for (std::size_t j = 0; j < kFtmImusPerReport; ++j) {
      const std::size_t i = pair * kFtmImusPerReport + j;
      ftm::FtmImuSample s = imu_latest_[i];
      s.status = static_cast<std::uint8_t>((s.status & ~st::mag_overflow) | mag_overflow_[i]);
      if (!imu_new_[i]) s.status |= st::stale;
      s.mag_uT = mag_latest_[i];
      s.mag_fresh = mag_new_[i];
      imu_new_[i] = false;
      mag_new_[i] = false;
      r.imus[j] = quantise_imu(s, accel_range_, gyro_range_);
      if (r.imus[j].status & st::stale) ++stats_.imu_stale;
      if (r.imus[j].status & (st::accel_saturated | st::gyro_saturated | st::sensor_error | st::mag_overflow)) {
        ++stats_.imu_flagged;
      }
    }
    r.flags = pending_flags_[pair];
    send(pair, t_ns, encode_ftm_imu_report(r), out);
  }
}

void FtmBoardEmulator::bend_tick(TimeNs t_ns, std::vector<FtmEmulatedReport>& out) {
  namespace st = ftm::sample_status;
  const std::uint64_t tick = next_bend_++;
  ++stats_.bend_ticks;
  if (batch_.count == 0) {
    batch_.sequence = static_cast<std::uint32_t>(tick);
    batch_.timestamp_us = device_timestamp_us(t_ns);
  }
  auto& row = batch_.samples[batch_.count];
  for (std::size_t k = 0; k < ftm::kFtmBendCount; ++k) {
    const ftm::FtmBendSample& s = bend_latest_[k];
    const auto status = static_cast<std::uint8_t>(s.status | (bend_new_[k] ? 0 : st::stale));
    bend_new_[k] = false;
    row[k] = quantise_bend(s.capacitance_pF, status);
    if (row[k].status & st::stale) ++stats_.bend_stale;
    if (row[k].status & (st::sensor_error | ftm_wire_status::over_range)) ++stats_.bend_flagged;
  }
  ++batch_.count;
  if (batch_.count < options_.bend_samples_per_report) return;
  FtmBendReport r = batch_;
  r.version = kFtmProtocolVersion;
  r.period_us = period_us_of(bend_rate_hz_);
  r.flags = pending_flags_[2];
  batch_.count = 0;
  batch_.samples = {};
  send(2, t_ns, encode_ftm_bend_report(r), out);
}

void FtmBoardEmulator::send(std::size_t channel, TimeNs send_ns,
                            const std::array<std::uint8_t, kFtmDataReportSize>& bytes,
                            std::vector<FtmEmulatedReport>& out) {
  // One draw per report, whatever the outcome, so the draws do not depend on the data.
  if (overrun_rng_.uniform01() < options_.faults.device_overrun_probability) {
    ++stats_.device_overruns;
    pending_flags_[channel] |= ftm_flags::overrun;
    return;
  }
  pending_flags_[channel] = 0;
  FtmEmulatedReport e;
  e.send_ns = send_ns;
  e.bytes = bytes;
  link_faults_.send(e, options_.faults, stats_, out);
}

void FtmBoardEmulator::flush(std::vector<FtmEmulatedReport>& out) { link_faults_.flush(stats_, out); }

FtmCommandResult FtmBoardEmulator::handle_command(std::span<const std::uint8_t> bytes, TimeNs t_ns) {
  const TimeNs at = std::max(t_ns, now_ns_);
  FtmCommand c;
  const FtmDecodeStatus s = decode_ftm_command(bytes, c);
  if (!s) {
    last_result_ = s.code == FtmDecodeErrc::unknown_command ? FtmCommandResult::unknown_command
                                                            : FtmCommandResult::bad_report;
    return last_result_;
  }
  FtmCommandResult result = FtmCommandResult::ok;
  switch (c.op) {
    case FtmCommandOp::start_streaming:
      streaming_ = true;
      restart_run(at);
      break;
    case FtmCommandOp::stop_streaming:
      streaming_ = false;
      discard_batch();
      break;
    case FtmCommandOp::set_rates:
      if (c.imu_rate_hz < kFtmMinImuRateHz || c.imu_rate_hz > kFtmMaxImuRateHz ||
          c.bend_rate_hz < kFtmMinBendRateHz || c.bend_rate_hz > kFtmMaxBendRateHz ||
          ftm_reports_per_second(c.imu_rate_hz, c.bend_rate_hz) > kFtmMaxReportsPerSecond) {
        result = FtmCommandResult::bad_argument;
      } else {
        imu_rate_hz_ = c.imu_rate_hz;
        bend_rate_hz_ = c.bend_rate_hz;
        restart_run(at);
      }
      break;
    case FtmCommandOp::set_ranges:
      accel_range_ = c.accel_range;
      gyro_range_ = c.gyro_range;
      break;
  }
  last_token_ = c.token;
  last_result_ = result;
  return result;
}

std::array<std::uint8_t, kFtmInfoReportSize> FtmBoardEmulator::info_report(TimeNs t_ns) const {
  FtmDeviceInfo info;
  info.firmware = options_.firmware;
  info.streaming = streaming_ && powered_at(t_ns);
  info.imu_rate_hz = imu_rate_hz_;
  info.bend_rate_hz = bend_rate_hz_;
  info.mag_rate_hz = static_cast<std::uint8_t>(std::min<double>(kFtmMaxMagRateHz, imu_rate_hz_));
  info.accel_range = accel_range_;
  info.gyro_range = gyro_range_;
  info.last_command_token = last_token_;
  info.last_command_result = last_result_;
  info.timestamp_us = device_timestamp_us(t_ns);
  return encode_ftm_info_report(info);
}

// ---------------------------------------------------------------------------
// FtmBoardEmulatorServer

void FtmEmulatorServerTraits::advance(FtmBoardEmulator& emulator, const FtmServeOptions& options, TimeNs now_ns,
                                      std::vector<FtmEmulatedReport>& out) {
  emulator.advance_to(now_ns + options.lookahead_ns, out);
}

void FtmEmulatorServerTraits::handle_command(FtmBoardEmulator& emulator, std::span<const std::uint8_t> bytes,
                                             TimeNs now_ns) {
  emulator.handle_command(bytes, now_ns);
}

std::size_t FtmEmulatorServerTraits::feature(FtmBoardEmulator& emulator, std::uint8_t report_id, TimeNs now_ns,
                                             std::span<std::uint8_t> out) {
  if (report_id != static_cast<std::uint8_t>(FtmReportId::device_info) || out.size() < kFtmInfoReportSize) return 0;
  const auto info = emulator.info_report(now_ns);
  std::copy(info.begin(), info.end(), out.begin());
  return info.size();
}

}  // namespace proprio::devices
