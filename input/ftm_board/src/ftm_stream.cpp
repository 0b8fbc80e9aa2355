#include "proprio/ftm_board/ftm_stream.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::devices {

namespace {

// Sequence and timestamp may disagree by this many periods (plus 0.1 % of the
// distance) before the decoder decides the board restarted: the board stamps
// each tick from the timer that paces it, so they agree to a µs; 4 leaves
// room for firmware that stamps a little late.
constexpr double kResetTolerancePeriods = 4.0;
constexpr double kResetToleranceFraction = 1e-3;
// A gap longer than this (device µs) may hide wraps of the 32-bit µs counter
// (71.6 min): the sequence then says how many.
constexpr double kTimestampHalfRangeUs = 1073741824.0;  // 2^30 µs
// How long after a channel's first report its duplicate may still turn up, in ticks.
constexpr double kDuplicateHorizonTicks = 64.0;

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

std::size_t bit_of(std::int64_t seq, std::int64_t window) noexcept {
  return static_cast<std::size_t>(((seq % window) + window) % window);
}

}  // namespace

const char* to_string(FtmReportVerdict verdict) noexcept {
  switch (verdict) {
    case FtmReportVerdict::accepted: return "accepted";
    case FtmReportVerdict::duplicate: return "duplicate";
    case FtmReportVerdict::late: return "late";
    case FtmReportVerdict::decode_error: return "decode_error";
    case FtmReportVerdict::other_report: return "other_report";
  }
  return "unknown";
}

void FtmStreamDecoder::lock(Channel& ch, std::uint32_t sequence, std::uint32_t timestamp_us,
                            TimeNs receive_ns) noexcept {
  ch.locked = true;
  ch.any_accepted = false;
  ch.locked_epoch = epoch_;
  // The first lap of the unwrapped values equals the wire values.
  ch.newest_seq = sequence;
  ch.newest_device_us = timestamp_us;
  ch.newest_end = sequence;
  ch.start_seq = sequence;
  ch.start_ts = timestamp_us;
  ch.start_receive_ns = receive_ns;
  ch.window = {};
}

FtmStreamDecoder::Placed FtmStreamDecoder::place(Channel& ch, std::uint32_t sequence, std::uint32_t timestamp_us,
                                                 std::uint8_t flags, double period_us, TimeNs receive_ns) noexcept {
  const bool flagged_start = (flags & ftm_flags::stream_start) != 0;
  bool live = ch.locked && ch.locked_epoch == epoch_;
  // A flagged report stamped like the channel's first is a duplicate of it
  // (within a few ticks) or the first report of the next boot (later).
  bool repeats_start = live && sequence == ch.start_seq && timestamp_us == ch.start_ts;
  if (repeats_start) {
    repeats_start = (receive_ns != 0 && ch.start_receive_ns != 0)
                        ? static_cast<double>(receive_ns - ch.start_receive_ns) <
                              kDuplicateHorizonTicks * period_us * 1000.0
                        : ch.newest_end - static_cast<std::int64_t>(ch.start_seq) < kWindow;
  }
  bool restart = live && flagged_start && !repeats_start;
  Placed p{sequence, timestamp_us, false};
  if (live && !restart) {
    const std::int64_t d_seq = static_cast<std::int32_t>(sequence - static_cast<std::uint32_t>(ch.newest_seq));
    std::int64_t d_ts = static_cast<std::int32_t>(timestamp_us - static_cast<std::uint32_t>(ch.newest_device_us));
    const double expected_us = static_cast<double>(d_seq) * period_us;
    if (d_seq > 0 && expected_us >= kTimestampHalfRangeUs) {
      // The µs counter may have wrapped during the silence: the sequence says which lap.
      const std::int64_t expected = std::llround(expected_us);
      d_ts = expected +
             static_cast<std::int32_t>(timestamp_us - static_cast<std::uint32_t>(ch.newest_device_us + expected));
    }
    const double k_time = static_cast<double>(d_ts) / period_us;
    if (std::fabs(static_cast<double>(d_seq) - k_time) >
        kResetTolerancePeriods + kResetToleranceFraction * std::fabs(k_time)) {
      restart = true;  // sequence and clock no longer agree: the board restarted unflagged
    } else {
      p.seq = ch.newest_seq + d_seq;
      p.device_us = ch.newest_device_us + d_ts;
      return p;
    }
  }
  if (restart) {
    // This channel saw the restart first: a new epoch for the whole board.
    ++epoch_;
    ++stats_.device_resets;
    p.reset = true;
  }
  // Otherwise the first report of the stream, or of a channel that follows
  // an epoch another channel began: it locks without counting a restart.
  lock(ch, sequence, timestamp_us, receive_ns);
  return p;
}

FtmReportVerdict FtmStreamDecoder::classify(Channel& ch, std::int64_t seq, std::int64_t count, std::uint64_t& lost,
                                            std::uint64_t samples_per_tick) noexcept {
  const std::int64_t end = seq + count;
  if (!ch.any_accepted || seq >= ch.newest_end) {
    if (ch.any_accepted && seq > ch.newest_end) {
      lost += static_cast<std::uint64_t>(seq - ch.newest_end) * samples_per_tick;
      ++stats_.gaps;
    }
    // Slots entering the window held ticks a whole window older: forget them.
    if (end - ch.newest_end >= kWindow || !ch.any_accepted) {
      ch.window = {};
    } else {
      for (std::int64_t s = ch.newest_end; s < end; ++s) {
        const std::size_t b = bit_of(s, kWindow);
        ch.window[b / 64] &= ~(std::uint64_t{1} << (b % 64));
      }
    }
    for (std::int64_t s = seq; s < end; ++s) {
      const std::size_t b = bit_of(s, kWindow);
      ch.window[b / 64] |= std::uint64_t{1} << (b % 64);
    }
    ch.newest_end = end;
    return FtmReportVerdict::accepted;
  }
  if (ch.newest_end - seq > kWindow) return FtmReportVerdict::late;  // too old to tell: loss count left as is
  std::uint64_t unseen = 0;
  for (std::int64_t s = seq; s < std::min(end, ch.newest_end); ++s) {
    const std::size_t b = bit_of(s, kWindow);
    if (!(ch.window[b / 64] >> (b % 64) & 1)) {
      ++unseen;
      ch.window[b / 64] |= std::uint64_t{1} << (b % 64);
    }
  }
  if (unseen == 0) return FtmReportVerdict::duplicate;
  lost -= std::min(lost, unseen * samples_per_tick);  // counted lost when the gap opened
  return FtmReportVerdict::late;
}

FtmPushResult FtmStreamDecoder::push(std::span<const std::uint8_t> report, std::span<FtmBoardSample> out,
                                     TimeNs receive_ns) noexcept {
  ++stats_.reports;
  FtmPushResult result;
  const std::uint8_t id = report.empty() ? 0 : report[0];
  FtmImuReport imu;
  FtmBendReport bend;
  FtmDecodeStatus status;
  if (id == static_cast<std::uint8_t>(FtmReportId::device_info)) {
    FtmDeviceInfo info;
    status = decode_ftm_info_report(report, info);
    if (status) {
      ++stats_.other_reports;
      result.verdict = FtmReportVerdict::other_report;
      return result;
    }
  } else if (id == static_cast<std::uint8_t>(FtmReportId::bend)) {
    status = decode_ftm_bend_report(report, bend);
  } else {
    status = decode_ftm_imu_report(report, imu);
  }
  if (!status) {
    ++stats_.decode_errors;
    ++stats_.decode_errors_by_code[static_cast<std::size_t>(status.code) % kFtmDecodeErrcCount];
    stats_.last_decode_error = status;
    result.decode = status;
    return result;
  }

  result.imu = id != static_cast<std::uint8_t>(FtmReportId::bend);
  Channel& ch = channels_[result.imu ? imu.first_imu / 2 : 2];
  const std::uint32_t wire_seq = result.imu ? imu.sequence : bend.sequence;
  const std::uint32_t wire_ts = result.imu ? imu.timestamp_us : bend.timestamp_us;
  const std::uint8_t flags = result.imu ? imu.flags : bend.flags;
  const std::uint16_t period = result.imu ? imu.period_us : bend.period_us;
  result.ticks = result.imu ? 1 : bend.count;
  const std::int64_t prev_seq = ch.newest_seq, prev_us = ch.newest_device_us;
  const bool had_accepted = ch.any_accepted;
  const Placed p = place(ch, wire_seq, wire_ts, flags, period, receive_ns);
  result.device_reset = p.reset;
  result.timestamp_us = wire_ts;
  result.device_time_us = p.device_us;
  result.last_device_time_us = p.device_us + static_cast<std::int64_t>(result.ticks - 1) * period;
  result.sequence = p.seq;
  result.epoch = epoch_;

  std::uint64_t& lost = result.imu ? stats_.lost_imu_samples : stats_.lost_bend_samples;
  result.verdict = classify(ch, p.seq, result.ticks, lost, result.imu ? kFtmImusPerReport : ftm::kFtmBendCount);
  if (result.verdict == FtmReportVerdict::duplicate) {
    ++stats_.duplicates;
    return result;
  }
  if (result.verdict == FtmReportVerdict::late) {
    ++stats_.late;
    return result;
  }
  ++stats_.accepted;
  if (had_accepted && ch.any_accepted && !p.reset) {
    constexpr std::int64_t kLap = std::int64_t{1} << 32;
    stats_.sequence_wraps +=
        static_cast<std::uint64_t>(std::max<std::int64_t>(0, floor_div(p.seq, kLap) - floor_div(prev_seq, kLap)));
    stats_.timestamp_wraps += static_cast<std::uint64_t>(
        std::max<std::int64_t>(0, floor_div(p.device_us, kLap) - floor_div(prev_us, kLap)));
  }
  ch.any_accepted = true;
  ch.newest_seq = p.seq;
  ch.newest_device_us = p.device_us;
  if (flags & ftm_flags::overrun) ++stats_.device_overruns;

  std::size_t n = 0;
  auto emit = [&](const FtmBoardSample& s) {
    if (n < out.size()) {
      out[n] = s;
      ++result.sample_count;
    }
    ++n;
  };
  if (result.imu) {
    ++stats_.imu_reports;
    stats_.accel_range = imu.accel_range;
    stats_.gyro_range = imu.gyro_range;
    stats_.imu_period_us = period;
    for (std::size_t i = 0; i < kFtmImusPerReport; ++i) {
      FtmBoardSample s;
      s.event.kind = ftm::FtmEvent::Kind::imu;
      s.event.index = static_cast<std::uint8_t>(imu.first_imu + i);
      s.event.imu = imu_sample_from_wire(imu.imus[i], imu.accel_range, imu.gyro_range);
      s.receive_ns = receive_ns;
      s.device_time_us = p.device_us;
      s.sequence = p.seq;
      s.epoch = epoch_;
      ++stats_.imu_samples;
      const std::uint8_t st = s.event.imu.status;
      if (st & ~ftm::sample_status::mag_overflow) ++stats_.imu_unusable;
      if (st & ftm::sample_status::mag_overflow) ++stats_.mag_overflows;
      if (s.event.imu.mag_fresh) ++stats_.mag_fresh;
      emit(s);
    }
  } else {
    ++stats_.bend_reports;
    stats_.bend_period_us = period;
    for (std::size_t i = 0; i < bend.count; ++i) {
      for (std::size_t k = 0; k < ftm::kFtmBendCount; ++k) {
        FtmBoardSample s;
        s.event.kind = ftm::FtmEvent::Kind::bend;
        s.event.index = static_cast<std::uint8_t>(k);
        s.event.bend = bend_sample_from_wire(bend.samples[i][k]);
        s.receive_ns = receive_ns;
        s.device_time_us = p.device_us + static_cast<std::int64_t>(i) * period;
        s.sequence = p.seq + static_cast<std::int64_t>(i);
        s.epoch = epoch_;
        ++stats_.bend_samples;
        if (s.event.bend.status) ++stats_.bend_unusable;
        emit(s);
      }
    }
  }
  return result;
}

}  // namespace proprio::devices
