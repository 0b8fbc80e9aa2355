#include "proprio/imu_glove_board/imu_glove_stream.hpp"

#include <cmath>

namespace proprio::devices {

namespace {

// Sequence and timestamp may disagree by this many ticks (plus 0.1 % of the
// gap) before the decoder decides the device restarted. Firmware stamps each
// tick within a fraction of a period; 2.5 leaves room for that and for a
// period measured over a single tick.
constexpr double kResetToleranceTicks = 2.5;
constexpr double kResetToleranceFraction = 1e-3;
// Below this many ticks the 16-bit sequence difference is unambiguous; above
// it the timestamp decides how many times the sequence wrapped.
constexpr double kSequenceHalfRange = 16384.0;
constexpr int kWindowBits = 64;
// How long after a report its duplicate may still turn up, in ticks.
constexpr double kDuplicateHorizonTicks = 16.0;

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

}  // namespace

const char* to_string(ImuGloveReportVerdict verdict) noexcept {
  switch (verdict) {
    case ImuGloveReportVerdict::accepted: return "accepted";
    case ImuGloveReportVerdict::duplicate: return "duplicate";
    case ImuGloveReportVerdict::late: return "late";
    case ImuGloveReportVerdict::decode_error: return "decode_error";
    case ImuGloveReportVerdict::other_report: return "other_report";
  }
  return "unknown";
}

std::uint64_t ImuGloveStreamStats::samples_good() const noexcept {
  std::uint64_t n = 0;
  for (const auto& i : imus) n += i.good;
  return n;
}
std::uint64_t ImuGloveStreamStats::samples_rejected() const noexcept {
  std::uint64_t n = 0;
  for (const auto& i : imus) n += i.rejected;
  return n;
}

ImuGloveStreamDecoder::ImuGloveStreamDecoder(ImuGloveStreamOptions options) noexcept : options_(options) {
  if (!(options_.nominal_rate_hz > 0.0) || !std::isfinite(options_.nominal_rate_hz)) options_.nominal_rate_hz = 100.0;
  period_us_ = 1e6 / options_.nominal_rate_hz;
  stats_.tick_period_us = period_us_;
}

void ImuGloveStreamDecoder::begin_epoch(const ImuGloveDataReport& r, bool is_reset) noexcept {
  if (is_reset) {
    ++stats_.device_resets;
    ++epoch_;
  }
  locked_ = true;
  imu_total_ = r.imu_total;
  stats_.imu_total = r.imu_total;
  // The first lap of the unwrapped values equals the wire values, which keeps them recognisable in logs.
  newest_seq_ = r.sequence;
  newest_device_us_ = r.timestamp_us;
  epoch_start_seq_ = r.sequence;
  epoch_start_ts_ = r.timestamp_us;
  epoch_flagged_ = (r.flags & data_flags::stream_start) != 0;
  // A restart may come with a new rate (set_rate restarts the stream): measure the period again.
  period_measured_ = false;
  period_us_ = 1e6 / options_.nominal_rate_hz;
  last_overrun_seq_ = -1;
  parts_ = {};
}

void ImuGloveStreamDecoder::advance_newest(std::int64_t seq, std::int64_t device_us) noexcept {
  if (seq <= newest_seq_) return;
  stats_.sequence_wraps += static_cast<std::uint64_t>(floor_div(seq, 65536) - floor_div(newest_seq_, 65536));
  const std::int64_t lap = std::int64_t{1} << 32;
  const std::int64_t laps = floor_div(device_us, lap) - floor_div(newest_device_us_, lap);
  if (laps > 0) stats_.timestamp_wraps += static_cast<std::uint64_t>(laps);
  newest_seq_ = seq;
  newest_device_us_ = device_us;
}

ImuGlovePushResult ImuGloveStreamDecoder::push(std::span<const std::uint8_t> report, std::span<ImuGloveSample> out,
                                         TimeNs receive_ns) noexcept {
  ++stats_.reports;
  ImuGlovePushResult result;

  ImuGloveDataReport r;
  ImuGloveDecodeStatus status;
  if (report_id_of(report) == static_cast<std::uint8_t>(ImuGloveReportId::device_info)) {
    ImuGloveDeviceInfo info;
    status = decode_info_report(report, info);
    if (status) {
      ++stats_.other_reports;
      result.verdict = ImuGloveReportVerdict::other_report;
      return result;
    }
  } else {
    status = decode_data_report(report, r);
  }
  if (!status) {
    ++stats_.decode_errors;
    ++stats_.decode_errors_by_code[static_cast<std::size_t>(status.code) % kImuGloveDecodeErrcCount];
    stats_.last_decode_error = status;
    result.decode = status;
    return result;
  }

  // Place the report in time: unwrap sequence and timestamp against the newest tick.
  std::int64_t seq = r.sequence;
  std::int64_t device_us = r.timestamp_us;
  const bool flagged_start = (r.flags & data_flags::stream_start) != 0;
  // A flagged report stamped like the epoch's first tick is that tick's other
  // part, or a duplicate of it, or - firmware being deterministic - the first
  // tick of the next boot. A part not yet seen this epoch is the first case; a
  // duplicate arrives within a few ticks of the original (in host time, or in
  // sequence when there are no host times); anything later is a restart.
  bool is_epoch_start_tick = locked_ && r.sequence == static_cast<std::uint16_t>(epoch_start_seq_) &&
                             r.timestamp_us == epoch_start_ts_;
  if (is_epoch_start_tick && parts_[r.part() % kImuGloveMaxReportsPerTick].seen) {
    is_epoch_start_tick = (receive_ns != 0 && epoch_start_receive_ns_ != 0)
                              ? static_cast<double>(receive_ns) - static_cast<double>(epoch_start_receive_ns_) <
                                    kDuplicateHorizonTicks * period_us_ * 1000.0
                              : newest_seq_ - epoch_start_seq_ < kWindowBits;
  }
  bool new_epoch = !locked_ || r.imu_total != imu_total_ || (flagged_start && !is_epoch_start_tick);
  if (!new_epoch) {
    const auto d_ts = static_cast<std::int32_t>(r.timestamp_us - static_cast<std::uint32_t>(newest_device_us_));
    device_us = newest_device_us_ + d_ts;
    const double k_time = d_ts / period_us_;
    std::int64_t d_seq;
    if (std::fabs(k_time) < kSequenceHalfRange) {
      d_seq = static_cast<std::int16_t>(static_cast<std::uint16_t>(r.sequence - static_cast<std::uint16_t>(newest_seq_)));
    } else {
      // A long silence: the timestamp says roughly how many ticks passed, the
      // sequence number picks the tick within ±half a wrap of that.
      const std::int64_t expected = newest_seq_ + std::llround(k_time);
      d_seq = expected - newest_seq_ +
              static_cast<std::int16_t>(static_cast<std::uint16_t>(r.sequence - static_cast<std::uint16_t>(expected)));
    }
    seq = newest_seq_ + d_seq;
    const double disagreement = std::fabs(static_cast<double>(d_seq) - k_time);
    if (period_measured_ &&
        disagreement > kResetToleranceTicks + kResetToleranceFraction * std::fabs(k_time)) {
      new_epoch = true;  // sequence and clock no longer agree: the device restarted unflagged
    } else if (d_seq == 1 && d_ts > 0) {
      // Consecutive ticks measure the period in device µs, so crystal error does not enter.
      period_us_ = period_measured_ ? period_us_ + (d_ts - period_us_) / 64.0 : static_cast<double>(d_ts);
      period_measured_ = true;
      stats_.tick_period_us = period_us_;
    }
  }
  if (new_epoch) {
    const bool is_reset = locked_;
    begin_epoch(r, is_reset);
    epoch_start_receive_ns_ = receive_ns;
    result.device_reset = is_reset;
    seq = r.sequence;
    device_us = r.timestamp_us;
  }

  result.timestamp_us = r.timestamp_us;
  result.device_time_us = device_us;
  result.sequence = seq;
  result.epoch = epoch_;

  // Classify within the report's part.
  Part& part = parts_[r.part() % kImuGloveMaxReportsPerTick];
  if (!part.seen) {
    part.seen = true;
    part.newest = seq;
    part.window = 1;
    // Reports of this part the epoch should have brought before this one. When
    // the epoch began mid-stream (the host attached late, or inferred a
    // restart), the first tick's other parts may have gone by unseen.
    const std::int64_t missed = seq - epoch_start_seq_ - (epoch_flagged_ ? 0 : 1);
    if (missed > 0) stats_.lost += static_cast<std::uint64_t>(missed);
    result.verdict = ImuGloveReportVerdict::accepted;
  } else {
    const std::int64_t d = seq - part.newest;
    if (d > 0) {
      stats_.lost += static_cast<std::uint64_t>(d - 1);
      part.window = d >= kWindowBits ? 1 : (part.window << d) | 1;
      part.newest = seq;
      result.verdict = ImuGloveReportVerdict::accepted;
    } else if (d == 0) {
      result.verdict = ImuGloveReportVerdict::duplicate;
    } else if (-d < kWindowBits) {
      const std::uint64_t bit = std::uint64_t{1} << (-d);
      if (part.window & bit) {
        result.verdict = ImuGloveReportVerdict::duplicate;
      } else {
        part.window |= bit;
        result.verdict = ImuGloveReportVerdict::late;
        if (stats_.lost > 0) --stats_.lost;  // it was counted lost when the gap opened
      }
    } else {
      result.verdict = ImuGloveReportVerdict::late;  // too old to tell whether it was seen: loss count left as is
    }
  }
  if (result.verdict == ImuGloveReportVerdict::duplicate) {
    ++stats_.duplicates;
    return result;
  }
  if (result.verdict == ImuGloveReportVerdict::late) {
    ++stats_.late;
    return result;
  }

  ++stats_.accepted;
  advance_newest(seq, device_us);
  if ((r.flags & data_flags::overrun) && seq != last_overrun_seq_) {
    ++stats_.device_overruns;  // once per tick, however many parts carry the flag
    last_overrun_seq_ = seq;
  }

  const std::size_t blocks = r.block_count();
  for (std::size_t i = 0; i < blocks; ++i) {
    const ImuGloveImuRaw& raw = r.imus[i];
    const auto sensor = static_cast<std::uint16_t>(r.first_imu + i);
    const std::uint8_t st = host_status(raw);
    ImuGloveImuStats& s = stats_.imus[sensor % kImuGloveMaxImus];
    if (st == 0) {
      ++s.good;
    } else {
      ++s.rejected;
      if (st & imu_status::stale) ++s.stale;
      if (st & imu_status::accel_saturated) ++s.accel_saturated;
      if (st & imu_status::gyro_saturated) ++s.gyro_saturated;
      if (st & imu_status::sensor_error) ++s.sensor_error;
    }
    if (i >= out.size()) continue;
    ImuGloveSample& o = out[i];
    o.imu = to_imu_sample(raw, sensor, r.accel_range, r.gyro_range);
    o.time_ns = 0;
    o.receive_ns = receive_ns;
    o.device_time_us = device_us;
    o.timestamp_us = r.timestamp_us;
    o.epoch = epoch_;
    o.sequence = r.sequence;
    o.status = st;
    ++result.sample_count;
  }
  return result;
}

}  // namespace proprio::devices
