#include "proprio/stretch_board/stretch_stream.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::devices {

namespace {

// Sequence and timestamp may disagree by this many measurements (plus 0.1 %
// of the distance) before the decoder decides the board restarted. The board
// stamps measurement 0 of each report from the same timer that paces the
// measurements, so they agree to a µs; 4 leaves room for a period measured
// over a single report and for firmware that stamps a little late.
constexpr double kResetToleranceMeasurements = 4.0;
constexpr double kResetToleranceFraction = 1e-3;
// A gap longer than this (in device µs) may hide wraps of the 32-bit µs
// counter (71.6 min): the sequence, which wraps only after weeks, then says
// how many.
constexpr double kTimestampHalfRangeUs = 1073741824.0;  // 2^30 µs, 17.9 min
// How long after a report its duplicate may still turn up, in measurements
// (16 full reports).
constexpr double kDuplicateHorizonMeasurements = 16.0 * kStretchMeasurementsPerReport;
// Reports this far apart (in measurements) or nearer measure the period; a
// longer gap is fine too, but a short one keeps a clock jump from polluting it.
constexpr std::int64_t kPeriodMaxGap = 4 * static_cast<std::int64_t>(kStretchMeasurementsPerReport);

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

}  // namespace

const char* to_string(StretchReportVerdict verdict) noexcept {
  switch (verdict) {
    case StretchReportVerdict::accepted: return "accepted";
    case StretchReportVerdict::duplicate: return "duplicate";
    case StretchReportVerdict::late: return "late";
    case StretchReportVerdict::decode_error: return "decode_error";
    case StretchReportVerdict::other_report: return "other_report";
    case StretchReportVerdict::wrong_layout: return "wrong_layout";
  }
  return "unknown";
}

StretchStreamDecoder::StretchStreamDecoder(StretchStreamOptions options) noexcept : options_(options) {
  if (!(options_.nominal_rate_hz > 0.0) || !std::isfinite(options_.nominal_rate_hz)) {
    options_.nominal_rate_hz = kStretchDefaultRateHz;
  }
  period_us_ = 1e6 / options_.nominal_rate_hz;
  stats_.measurement_period_us = period_us_;
}

bool StretchStreamDecoder::seen(std::int64_t seq) const noexcept {
  const std::int64_t bit = ((seq % kWindow) + kWindow) % kWindow;
  return (window_[static_cast<std::size_t>(bit / 64)] >> (bit % 64) & 1) != 0;
}

void StretchStreamDecoder::mark(std::int64_t seq) noexcept {
  const std::int64_t bit = ((seq % kWindow) + kWindow) % kWindow;
  window_[static_cast<std::size_t>(bit / 64)] |= std::uint64_t{1} << (bit % 64);
}

void StretchStreamDecoder::advance(std::int64_t new_end) noexcept {
  if (new_end - newest_end_ >= kWindow) {
    window_ = {};
  } else {
    // Slots that now enter the window held measurements a whole window older: forget them.
    for (std::int64_t s = newest_end_; s < new_end; ++s) {
      const std::int64_t bit = ((s % kWindow) + kWindow) % kWindow;
      window_[static_cast<std::size_t>(bit / 64)] &= ~(std::uint64_t{1} << (bit % 64));
    }
  }
  newest_end_ = new_end;
}

void StretchStreamDecoder::begin_epoch(const StretchDataReport& r, bool is_reset, TimeNs receive_ns) noexcept {
  if (is_reset) {
    ++stats_.device_resets;
    ++epoch_;
  }
  locked_ = true;
  any_accepted_ = false;
  top_strips_ = r.top_strips;
  bottom_strips_ = r.bottom_strips;
  single_strips_ = r.single_strips();
  stats_.top_strips = r.top_strips;
  stats_.bottom_strips = r.bottom_strips;
  stats_.single_strips = single_strips_;
  // The first lap of the unwrapped values equals the wire values, which keeps
  // them recognisable in logs and makes the unwrapped time equal the wire's modulo 2^32.
  newest_seq_ = r.sequence;
  newest_device_us_ = r.timestamp_us;
  newest_end_ = r.sequence;
  newest_count_ = 0;
  epoch_start_seq_ = r.sequence;
  epoch_start_ts_ = r.timestamp_us;
  epoch_start_receive_ns_ = receive_ns;
  // A restart may come with a new rate (SET_RATE restarts the stream): measure the period again.
  period_measured_ = false;
  period_us_ = 1e6 / options_.nominal_rate_hz;
  stats_.measurement_period_us = period_us_;
  window_ = {};
}

StretchPushResult StretchStreamDecoder::push(std::span<const std::uint8_t> report, std::span<StretchSample> out,
                                             TimeNs receive_ns) noexcept {
  ++stats_.reports;
  StretchPushResult result;

  StretchDataReport r;
  StretchDecodeStatus status;
  if (!report.empty() && report[0] == static_cast<std::uint8_t>(StretchReportId::device_info)) {
    StretchDeviceInfo info;
    status = decode_stretch_info_report(report, info);
    if (status) {
      ++stats_.other_reports;
      result.verdict = StretchReportVerdict::other_report;
      return result;
    }
  } else {
    status = decode_stretch_data_report(report, r);
  }
  if (!status) {
    ++stats_.decode_errors;
    ++stats_.decode_errors_by_code[static_cast<std::size_t>(status.code) % kStretchDecodeErrcCount];
    stats_.last_decode_error = status;
    result.decode = status;
    return result;
  }
  if ((options_.expected_top_strips != 0 && r.top_strips != options_.expected_top_strips) ||
      (options_.expected_bottom_strips != 0 && r.bottom_strips != options_.expected_bottom_strips) ||
      (options_.require_single_strips && !r.single_strips())) {
    ++stats_.wrong_layout;
    stats_.top_strips = r.top_strips;
    stats_.bottom_strips = r.bottom_strips;
    stats_.single_strips = r.single_strips();
    result.verdict = StretchReportVerdict::wrong_layout;
    result.count = r.count;
    return result;
  }

  // Place the report in time: unwrap sequence and timestamp against the newest report.
  const bool flagged_start = (r.flags & stretch_flags::stream_start) != 0;
  // A flagged report stamped like the epoch's first is a duplicate of it or -
  // firmware being deterministic - the first report of the next boot. A
  // duplicate arrives within a few reports of the original (in host time, or
  // in sequence when there are no host times); anything later is a restart.
  bool repeats_epoch_start = locked_ && r.sequence == epoch_start_seq_ && r.timestamp_us == epoch_start_ts_ &&
                             r.top_strips == top_strips_ && r.bottom_strips == bottom_strips_ &&
                             r.single_strips() == single_strips_;
  if (repeats_epoch_start) {
    repeats_epoch_start =
        (receive_ns != 0 && epoch_start_receive_ns_ != 0)
            ? static_cast<double>(receive_ns) - static_cast<double>(epoch_start_receive_ns_) <
                  kDuplicateHorizonMeasurements * period_us_ * 1000.0
            : newest_end_ - static_cast<std::int64_t>(epoch_start_seq_) < kWindow;
  }
  bool new_epoch = !locked_ || r.top_strips != top_strips_ || r.bottom_strips != bottom_strips_ ||
                   r.single_strips() != single_strips_ ||
                   (flagged_start && !repeats_epoch_start);
  std::int64_t seq = r.sequence;
  std::int64_t device_us = r.timestamp_us;
  if (!new_epoch) {
    const std::int64_t d_seq =
        static_cast<std::int32_t>(r.sequence - static_cast<std::uint32_t>(newest_seq_));
    std::int64_t d_ts = static_cast<std::int32_t>(r.timestamp_us - static_cast<std::uint32_t>(newest_device_us_));
    const double expected_us = static_cast<double>(d_seq) * period_us_;
    const bool long_silence = d_seq > 0 && expected_us >= kTimestampHalfRangeUs;
    if (long_silence) {
      // The µs counter may have wrapped during the silence: take the lap the
      // sequence points at, and the exact time within it from the counter.
      const std::int64_t expected = std::llround(expected_us);
      d_ts = expected + static_cast<std::int32_t>(r.timestamp_us -
                                                   static_cast<std::uint32_t>(newest_device_us_ + expected));
    }
    seq = newest_seq_ + d_seq;
    device_us = newest_device_us_ + d_ts;
    const double k_time = static_cast<double>(d_ts) / period_us_;
    const double disagreement = std::fabs(static_cast<double>(d_seq) - k_time);
    if (period_measured_ &&
        disagreement > kResetToleranceMeasurements + kResetToleranceFraction * std::fabs(k_time)) {
      new_epoch = true;  // sequence and clock no longer agree: the board restarted unflagged
    } else if (any_accepted_ && d_seq >= newest_count_ && d_seq > 0 && d_seq <= kPeriodMaxGap && d_ts > 0 &&
               !long_silence) {
      // Consecutive reports measure the period in device µs, so crystal error does not enter.
      const double sample = static_cast<double>(d_ts) / static_cast<double>(d_seq);
      period_us_ = period_measured_ ? period_us_ + (sample - period_us_) / 64.0 : sample;
      period_measured_ = true;
      stats_.measurement_period_us = period_us_;
    }
  }
  if (new_epoch) {
    const bool is_reset = locked_;
    begin_epoch(r, is_reset, receive_ns);
    result.device_reset = is_reset;
    seq = r.sequence;
    device_us = r.timestamp_us;
  }

  result.count = r.count;
  result.timestamp_us = r.timestamp_us;
  result.device_time_us = device_us;
  result.last_device_time_us = device_us + std::llround(static_cast<double>(r.count - 1) * period_us_);
  result.sequence = seq;
  result.epoch = epoch_;

  // Classify against the measurements already seen.
  const std::int64_t end = seq + r.count;
  if (!any_accepted_ || seq >= newest_end_) {
    if (any_accepted_ && seq > newest_end_) {
      stats_.lost += static_cast<std::uint64_t>(seq - newest_end_);
      ++stats_.gaps;
    }
    result.verdict = StretchReportVerdict::accepted;
  } else if (newest_end_ - seq > kWindow) {
    result.verdict = StretchReportVerdict::late;  // too old to tell whether it was seen: loss count left as is
  } else {
    std::uint64_t unseen = 0;
    const std::int64_t stop = std::min(end, newest_end_);
    for (std::int64_t s = seq; s < stop; ++s) {
      if (!seen(s)) {
        ++unseen;
        mark(s);
      }
    }
    if (unseen == 0) {
      result.verdict = StretchReportVerdict::duplicate;
    } else {
      result.verdict = StretchReportVerdict::late;
      // They were counted lost when the gap opened.
      stats_.lost -= std::min(stats_.lost, unseen);
    }
  }
  if (result.verdict == StretchReportVerdict::duplicate) {
    ++stats_.duplicates;
    return result;
  }
  if (result.verdict == StretchReportVerdict::late) {
    ++stats_.late;
    return result;
  }

  ++stats_.accepted;
  if (any_accepted_) {
    stats_.sequence_wraps +=
        static_cast<std::uint64_t>(std::max<std::int64_t>(0, floor_div(seq, std::int64_t{1} << 32) -
                                                                 floor_div(newest_seq_, std::int64_t{1} << 32)));
    stats_.timestamp_wraps += static_cast<std::uint64_t>(std::max<std::int64_t>(
        0, floor_div(device_us, std::int64_t{1} << 32) - floor_div(newest_device_us_, std::int64_t{1} << 32)));
  }
  advance(std::max(newest_end_, end));
  for (std::int64_t s = seq; s < end; ++s) mark(s);
  newest_seq_ = seq;
  newest_device_us_ = device_us;
  newest_count_ = r.count;
  any_accepted_ = true;
  if (r.flags & stretch_flags::overrun) ++stats_.device_overruns;

  for (std::size_t i = 0; i < r.count; ++i) {
    const StretchMeasurementRaw& m = r.measurements[i];
    const StretchMeasurementStatus st = host_status(m);
    ++stats_.measurements;
    ++stats_.by_status[static_cast<std::size_t>(st) % kStretchMeasurementStatusCount];
    if (st != StretchMeasurementStatus::ok) ++stats_.flagged_by_combination[m.combination % kStretchMaxCombinations];
    if (i >= out.size()) continue;
    StretchSample& o = out[i];
    o.capacitance_pf = stretch_count_to_pf(m.value);
    o.combination = m.combination;
    const StretchSources sources = stretch_sources(m.combination, r.top_strips, r.bottom_strips);
    o.top_strip = sources.top_strip;
    o.bottom_strip = sources.bottom_strip;
    o.status = st;
    o.time_ns = 0;
    o.receive_ns = receive_ns;
    o.device_time_us = device_us + std::llround(static_cast<double>(i) * period_us_);
    o.sequence = seq + static_cast<std::int64_t>(i);
    o.epoch = epoch_;
    ++result.sample_count;
  }
  return result;
}

}  // namespace proprio::devices
