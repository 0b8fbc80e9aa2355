#include "proprio/stretch_board/stretch_emulator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>

namespace proprio::devices {

namespace {

// Sub-stream numbers under the emulator's seed (mix_seed) for the board's own random effects.
enum Stream : std::uint64_t { kOverrunStream = hid::kFirstDeviceFaultStream, kSaturateStream };

constexpr TimeNs kNever = std::numeric_limits<TimeNs>::max();

constexpr const char* kWho = "stretch board emulator";

Status bad_option(const std::string& what) {
  return make_error(Errc::invalid_argument, "stretch board emulator: " + what);
}

bool powered(const StretchEmulatorOptions& o, TimeNs t_ns) noexcept {
  if (t_ns < o.boot_time_ns) return false;
  for (const StretchOutage& u : o.faults.unplugs) {
    if (t_ns >= u.at_ns && t_ns < u.at_ns + u.duration_ns) return false;
  }
  return true;
}

// The power-up before t: the first boot, or the end of the latest outage
// before t after which the power really was back (outages may overlap).
TimeNs boot_before(const StretchEmulatorOptions& o, TimeNs t_ns) noexcept {
  TimeNs boot = o.boot_time_ns;
  for (const StretchOutage& u : o.faults.unplugs) {
    const TimeNs end = u.at_ns + u.duration_ns;
    if (end <= t_ns && end > boot && u.at_ns >= o.boot_time_ns && powered(o, end)) boot = end;
  }
  return boot;
}

std::uint32_t to_ff(double pf) noexcept {
  const double ff = std::nearbyint(pf * 1000.0);
  if (!(ff > 0.0)) return 0;
  if (ff >= 4294967295.0) return 0xFFFFFFFFu;
  return static_cast<std::uint32_t>(ff);
}

}  // namespace

bool StretchEmulatorFaults::any() const noexcept {
  return drop_probability > 0 || duplicate_probability > 0 || corrupt_probability > 0 || reorder_probability > 0 ||
         device_overrun_probability > 0 || saturate_probability > 0 || !unplugs.empty();
}

Status StretchEmulatorFaults::validate() const {
  for (const auto& [p, name] : {std::pair{drop_probability, "drop_probability"},
                                {duplicate_probability, "duplicate_probability"},
                                {corrupt_probability, "corrupt_probability"},
                                {reorder_probability, "reorder_probability"},
                                {device_overrun_probability, "device_overrun_probability"},
                                {saturate_probability, "saturate_probability"}}) {
    if (auto s = hid::check_fault_probability(kWho, name, p); !s) return s;
  }
  return hid::check_fault_outages(kWho, unplugs);
}

Status StretchEmulatorOptions::validate() const {
  for (const auto& [n, name] : {std::pair{top_strips, "top_strips"}, {bottom_strips, "bottom_strips"}}) {
    if (n == 0 || n > kStretchMaxStrips) {
      return bad_option(std::string(name) + " = " + std::to_string(n) + "; the protocol carries 1 to " +
                        std::to_string(kStretchMaxStrips) + " strips per layer");
    }
  }
  if (combination_count() > kStretchMaxCombinations) {
    return bad_option(std::to_string(top_strips) + " x " + std::to_string(bottom_strips) +
                      " strips with single strips make " + std::to_string(combination_count()) +
                      " rows, but the 10-bit combination field holds " + std::to_string(kStretchMaxCombinations) +
                      "; use fewer strips or single_strips = false");
  }
  if (rate_hz == 0 || rate_hz > kStretchMaxRateHz) {
    return bad_option("rate_hz = " + std::to_string(rate_hz) + "; the protocol allows 1 to " +
                      std::to_string(kStretchMaxRateHz) + " measurements per second");
  }
  if (!(full_scale_pf >= 0.001 && full_scale_pf <= kStretchWireFullScalePf)) {
    return bad_option("full_scale_pf = " + std::to_string(full_scale_pf) + "; use 0.001 to " +
                      std::to_string(kStretchWireFullScalePf) + " pF (what 20 bits of fF hold)");
  }
  if (!(parasitic_pf >= 0.0 && parasitic_pf <= 1e6)) {
    return bad_option("parasitic_pf = " + std::to_string(parasitic_pf) + "; use 0 to 1e6 pF");
  }
  // Real crystals are within ±100 ppm; 1000 leaves room for stress tests and keeps the counter sane.
  if (!(std::fabs(clock_error_ppm) <= 1000.0)) {
    return bad_option("clock_error_ppm = " + std::to_string(clock_error_ppm) +
                      "; use a value within ±1000 (a crystal is within ±100)");
  }
  if (measurements_per_report == 0 || measurements_per_report > kStretchMeasurementsPerReport) {
    return bad_option("measurements_per_report = " + std::to_string(measurements_per_report) + "; use 1 to " +
                      std::to_string(kStretchMeasurementsPerReport));
  }
  if (max_report_age_ns <= 0) return bad_option("max_report_age_ns must be positive");
  return faults.validate();
}

Result<StretchEmulator> StretchEmulator::create(StretchEmulatorOptions options, StretchCapacitanceProvider provider) {
  if (auto s = options.validate(); !s) return s.error();
  if (!provider) return bad_option("no capacitance provider; pass a function (combination, t_ns) -> pF").error();
  return StretchEmulator(std::move(options), std::move(provider));
}

StretchEmulator::StretchEmulator(StretchEmulatorOptions options, StretchCapacitanceProvider provider)
    : options_(std::move(options)),
      provider_(std::move(provider)),
      link_faults_(options_.seed),
      overrun_rng_(mix_seed(options_.seed, kOverrunStream)),
      saturate_rng_(mix_seed(options_.seed, kSaturateStream)),
      full_scale_ff_(std::clamp<std::uint32_t>(to_ff(options_.full_scale_pf), 1, kStretchMaxCapacitanceCount)),
      parasitic_ff_(to_ff(options_.parasitic_pf)),
      now_ns_(options_.boot_time_ns) {
  batch_.top_strips = options_.top_strips;
  batch_.bottom_strips = options_.bottom_strips;
  // Powered from boot_time_ns on, so that commands sent before the first advance reach a running board.
  if (powered(options_, now_ns_)) boot(now_ns_);
}

bool StretchEmulator::powered_at(TimeNs t_ns) const noexcept { return powered(options_, t_ns); }

std::uint32_t StretchEmulator::device_timestamp_us(TimeNs t_ns) const noexcept {
  return hid::emulated_counter_us(boot_before(options_, t_ns), t_ns, options_.boot_timestamp_us,
                                  options_.clock_error_ppm);
}

TimeNs StretchEmulator::measurement_time_ns(std::uint64_t sequence) const noexcept {
  return run_start_ns_ + std::llround(static_cast<double>(sequence) * period_ns_);
}

void StretchEmulator::boot(TimeNs t_ns) noexcept {
  powered_ = true;
  last_boot_ns_ = t_ns;
  ++stats_.boots;
  // Volatile configuration: a power cycle restores the defaults.
  streaming_ = options_.stream_on_boot;
  rate_hz_ = options_.rate_hz;
  last_token_ = 0;
  last_result_ = StretchCommandResult::none;
  link_faults_.discard_held();
  restart_run(t_ns);
}

void StretchEmulator::restart_run(TimeNs t_ns) noexcept {
  discard_batch();
  // The board paces measurements with its own crystal, so in true time the period is off by the crystal's error.
  period_ns_ = 1e9 / (static_cast<double>(rate_hz_) * (1.0 + options_.clock_error_ppm * 1e-6));
  run_start_ns_ = t_ns;
  next_seq_ = 0;
  // An overrun before the restart means nothing to a sequence that starts again.
  pending_flags_ = stretch_flags::stream_start;
}

void StretchEmulator::discard_batch() noexcept {
  stats_.discarded_partial += batch_.count;
  batch_.count = 0;
  batch_.measurements = {};
}

TimeNs StretchEmulator::next_power_event_after(TimeNs t_ns) const noexcept {
  TimeNs next = options_.boot_time_ns > t_ns ? options_.boot_time_ns : kNever;
  for (const StretchOutage& u : options_.faults.unplugs) {
    if (u.at_ns > t_ns) next = std::min(next, u.at_ns);
    const TimeNs end = u.at_ns + u.duration_ns;
    if (end > t_ns) next = std::min(next, end);
  }
  return next;
}

void StretchEmulator::advance_to(TimeNs t_ns, std::vector<StretchEmulatedReport>& out) {
  if (t_ns < now_ns_) return;
  for (;;) {
    const TimeNs tm = powered_ && streaming_ ? measurement_time_ns(next_seq_) : kNever;
    const TimeNs ev = next_power_event_after(now_ns_);
    if (std::min(tm, ev) > t_ns) break;
    if (ev <= tm) {
      now_ns_ = ev;
      const bool on = powered(options_, ev);
      if (powered_ && !on) {
        // Whatever sat in the board's buffers dies with the power.
        discard_batch();
        link_faults_.discard_held();
        powered_ = false;
      } else if (!powered_ && on) {
        boot(ev);
      }
      continue;
    }
    now_ns_ = tm;
    measure(tm, out);
  }
  now_ns_ = t_ns;
}

void StretchEmulator::measure(TimeNs t_ns, std::vector<StretchEmulatedReport>& out) {
  const std::uint64_t seq = next_seq_++;
  const auto combination = static_cast<std::uint16_t>(seq % options_.combination_count());
  // One draw per measurement, whatever the reading, so the draws do not depend on the provider.
  const bool inject = saturate_rng_.uniform01() < options_.faults.saturate_probability;
  StretchMeasurementRaw m = quantise_capacitance(combination, provider_(combination, t_ns), full_scale_ff_);
  if (inject) {
    m.status = StretchMeasurementStatus::saturated;
    m.value = full_scale_ff_;
    ++stats_.injected_saturations;
  }
  ++stats_.measurements;
  switch (m.status) {
    case StretchMeasurementStatus::ok: break;
    case StretchMeasurementStatus::saturated: ++stats_.saturated; break;
    case StretchMeasurementStatus::below_zero: ++stats_.below_zero; break;
    case StretchMeasurementStatus::no_signal: ++stats_.no_signal; break;
  }
  if (batch_.count == 0) {
    batch_.sequence = static_cast<std::uint32_t>(seq);  // wraps like the firmware's counter
    batch_.timestamp_us = device_timestamp_us(t_ns);
    batch_first_ns_ = t_ns;
  }
  batch_.measurements[batch_.count] = m;
  ++batch_.count;
  const TimeNs next = measurement_time_ns(next_seq_);
  if (batch_.count >= options_.measurements_per_report || next - batch_first_ns_ > options_.max_report_age_ns) {
    emit(t_ns, out);
  }
}

void StretchEmulator::emit(TimeNs send_ns, std::vector<StretchEmulatedReport>& out) {
  StretchDataReport r = batch_;
  r.version = kStretchProtocolVersion;
  r.flags = static_cast<std::uint8_t>(pending_flags_ | (options_.single_strips ? stretch_flags::single_strips : 0));
  batch_.count = 0;
  batch_.measurements = {};
  if (overrun_rng_.uniform01() < options_.faults.device_overrun_probability) {
    // The transmit queue is full: the board drops the report and says so in the next one.
    ++stats_.device_overruns;
    pending_flags_ |= stretch_flags::overrun;
    return;
  }
  pending_flags_ = 0;
  StretchEmulatedReport e;
  e.send_ns = send_ns;
  e.bytes = encode_stretch_data_report(r);
  send(e, out);
}

void StretchEmulator::send(const StretchEmulatedReport& report, std::vector<StretchEmulatedReport>& out) {
  link_faults_.send(report, options_.faults, stats_, out);
}

void StretchEmulator::flush(std::vector<StretchEmulatedReport>& out) { link_faults_.flush(stats_, out); }

StretchCommandResult StretchEmulator::handle_command(std::span<const std::uint8_t> bytes, TimeNs t_ns) {
  const TimeNs at = std::max(t_ns, now_ns_);
  StretchCommand c;
  const StretchDecodeStatus s = decode_stretch_command(bytes, c);
  if (!s) {
    last_result_ = s.code == StretchDecodeErrc::unknown_command ? StretchCommandResult::unknown_command
                                                                : StretchCommandResult::bad_report;
    return last_result_;
  }
  StretchCommandResult result = StretchCommandResult::ok;
  switch (c.op) {
    case StretchCommandOp::start_streaming:
      streaming_ = true;
      restart_run(at);
      break;
    case StretchCommandOp::stop_streaming:
      streaming_ = false;
      discard_batch();
      break;
    case StretchCommandOp::set_rate:
      if (c.rate_hz == 0 || c.rate_hz > kStretchMaxRateHz) {
        result = StretchCommandResult::bad_argument;
      } else {
        rate_hz_ = c.rate_hz;
        restart_run(at);
      }
      break;
  }
  last_token_ = c.token;
  last_result_ = result;
  return result;
}

std::array<std::uint8_t, kStretchInfoReportSize> StretchEmulator::info_report(TimeNs t_ns) const {
  StretchDeviceInfo info;
  info.firmware = options_.firmware;
  info.top_strips = options_.top_strips;
  info.bottom_strips = options_.bottom_strips;
  info.single_strips = options_.single_strips;
  info.streaming = streaming_ && powered_at(t_ns);
  info.rate_hz = rate_hz_;
  info.full_scale_ff = full_scale_ff_;
  info.parasitic_ff = parasitic_ff_;
  info.last_command_token = last_token_;
  info.last_command_result = last_result_;
  info.timestamp_us = device_timestamp_us(t_ns);
  return encode_stretch_info_report(info);
}

// ---------------------------------------------------------------------------
// StretchEmulatorServer

void StretchEmulatorServerTraits::advance(StretchEmulator& emulator, const StretchServeOptions& options, TimeNs now_ns,
                                          std::vector<StretchEmulatedReport>& out) {
  emulator.advance_to(now_ns + options.lookahead_ns, out);
}

void StretchEmulatorServerTraits::handle_command(StretchEmulator& emulator, std::span<const std::uint8_t> bytes,
                                                 TimeNs now_ns) {
  emulator.handle_command(bytes, now_ns);
}

std::size_t StretchEmulatorServerTraits::feature(StretchEmulator& emulator, std::uint8_t report_id, TimeNs now_ns,
                                                 std::span<std::uint8_t> out) {
  if (report_id != static_cast<std::uint8_t>(StretchReportId::device_info) || out.size() < kStretchInfoReportSize) {
    return 0;
  }
  const auto info = emulator.info_report(now_ns);
  std::copy(info.begin(), info.end(), out.begin());
  return info.size();
}

}  // namespace proprio::devices
