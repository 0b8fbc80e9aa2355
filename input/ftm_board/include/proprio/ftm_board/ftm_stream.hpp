#pragma once
// FtmStreamDecoder: the host side of one FTM read-out board's report stream.
// It decodes each report, places it in its channel's sequence (lost,
// duplicate, late, board restarted), unwraps the 32-bit sequence and µs
// timestamp, gives every sample its own device time (sample i of a bend
// report was taken i periods after sample 0; the board states the period in
// device µs in every report, so nothing is estimated) and converts counts to
// the contract's units (ftm::FtmImuSample, ftm::FtmBendSample).
//
// Three channels, each with its own sequence: IMUs 0-1, IMUs 2-3 (two
// reports per tick, see ftm_protocol.hpp) and the bend sensors. Accounting is
// per sample: a gap of n ticks in an IMU channel loses 2n IMU samples, a gap
// of n in the bend channel 3n bend samples.
//
// A restart is board-wide: the first report of a channel after power-up,
// START or a rate change is flagged stream_start, but it can be the one lost,
// so a sequence that disagrees with the timestamp (by more than 4 periods
// plus 0.1 % of the distance) also starts a new epoch. The channel that sees
// the restart first begins the epoch; the others lock afresh on their next
// report without counting another.
//
// Not thread-safe; one owner (the reader thread) pushes. No allocation.
#include <array>
#include <cstdint>
#include <span>

#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/ftm_board/ftm_protocol.hpp"

namespace proprio::devices {

// One decoded sample with its place in the stream.
struct FtmBoardSample {
  // kind imu or bend, index, the sample in the contract's units. Its time_ns
  // is the host CLOCK_MONOTONIC time from hid::ClockSync (FtmBoardDevice
  // fills it; 0 from the stream decoder alone).
  ftm::FtmEvent event;
  TimeNs receive_ns = 0;           // when the host read the report
  std::int64_t device_time_us = 0;  // unwrapped; equals the wire's counter modulo 2^32
  std::int64_t sequence = 0;        // tick (IMU) or sample (bend) number within the epoch
  std::uint32_t epoch = 0;          // board restarts seen before this sample
};

// The most samples one report yields (a bend report: 5 ticks x 3 sensors).
inline constexpr std::size_t kFtmMaxSamplesPerReport = kFtmBendSamplesPerReport * ftm::kFtmBendCount;

enum class FtmReportVerdict : std::uint8_t {
  accepted,      // newer than every report of its channel: its samples were written
  duplicate,     // every tick in it already seen: dropped
  late,          // older than its channel's newest (reordered): dropped so times never go back; off the loss count
  decode_error,  // not a valid report: dropped, counted by reason
  other_report,  // a valid report of another type (device info): no samples
};
inline constexpr std::size_t kFtmReportVerdictCount = 5;
const char* to_string(FtmReportVerdict verdict) noexcept;

struct FtmPushResult {
  FtmReportVerdict verdict = FtmReportVerdict::decode_error;
  FtmDecodeStatus decode;        // why, for decode_error
  std::size_t sample_count = 0;  // samples written (accepted only)
  bool device_reset = false;     // this report began a new epoch after an earlier one
  bool imu = false;              // an IMU report (else a bend report), for data verdicts
  std::uint8_t ticks = 0;        // ticks the report carries (1 for IMU, count for bend)
  std::uint32_t timestamp_us = 0;   // of tick 0, as on the wire
  std::int64_t device_time_us = 0;  // the same, unwrapped
  // The last tick's device time: the board sends a report right after it, so
  // this is the instant to align clocks on.
  std::int64_t last_device_time_us = 0;
  std::int64_t sequence = 0;  // of tick 0, unwrapped within the epoch
  std::uint32_t epoch = 0;
};

struct FtmStreamStats {
  std::uint64_t reports = 0;
  std::uint64_t accepted = 0;
  std::uint64_t duplicates = 0;
  std::uint64_t late = 0;
  std::uint64_t decode_errors = 0;
  std::array<std::uint64_t, kFtmDecodeErrcCount> decode_errors_by_code{};
  std::uint64_t other_reports = 0;
  std::uint64_t imu_reports = 0;   // accepted
  std::uint64_t bend_reports = 0;  // accepted
  // Samples never seen (gaps less late arrivals that filled them); samples
  // across a restart are not counted (the board did not make them).
  std::uint64_t lost_imu_samples = 0;
  std::uint64_t lost_bend_samples = 0;
  std::uint64_t gaps = 0;
  std::uint64_t imu_samples = 0;
  std::uint64_t bend_samples = 0;
  std::uint64_t imu_unusable = 0;   // status other than mag_overflow (stale, saturated, sensor error)
  std::uint64_t mag_overflows = 0;
  std::uint64_t mag_fresh = 0;
  std::uint64_t bend_unusable = 0;  // stale, sensor error, over range
  std::uint64_t device_resets = 0;
  std::uint64_t device_overruns = 0;
  std::uint64_t sequence_wraps = 0;
  std::uint64_t timestamp_wraps = 0;
  FtmAccelRange accel_range = kFtmDefaultAccelRange;  // as the board last said
  FtmGyroRange gyro_range = kFtmDefaultGyroRange;
  std::uint16_t imu_period_us = 0;   // as the board last said (0: none yet)
  std::uint16_t bend_period_us = 0;
  FtmDecodeStatus last_decode_error;
};

class FtmStreamDecoder {
 public:
  FtmStreamDecoder() noexcept = default;

  // Decodes one report (report ID first) received at receive_ns and writes
  // the samples of an accepted report to out, which should hold
  // kFtmMaxSamplesPerReport (those that do not fit are counted, not written).
  // Flagged samples are written too, with their status.
  FtmPushResult push(std::span<const std::uint8_t> report, std::span<FtmBoardSample> out,
                     TimeNs receive_ns = 0) noexcept;

  const FtmStreamStats& stats() const noexcept { return stats_; }
  std::uint32_t epoch() const noexcept { return epoch_; }

 private:
  static constexpr std::int64_t kWindow = 256;  // ticks remembered behind the newest, per channel
  struct Channel {
    bool locked = false;
    bool any_accepted = false;
    std::uint32_t locked_epoch = 0;
    std::int64_t newest_seq = 0;
    std::int64_t newest_device_us = 0;
    std::int64_t newest_end = 0;
    std::uint32_t start_seq = 0;
    std::uint32_t start_ts = 0;
    TimeNs start_receive_ns = 0;
    std::array<std::uint64_t, kWindow / 64> window{};
  };
  struct Placed {
    std::int64_t seq = 0;
    std::int64_t device_us = 0;
    bool reset = false;
  };
  Placed place(Channel& ch, std::uint32_t sequence, std::uint32_t timestamp_us, std::uint8_t flags, double period_us,
               TimeNs receive_ns) noexcept;
  void lock(Channel& ch, std::uint32_t sequence, std::uint32_t timestamp_us, TimeNs receive_ns) noexcept;
  FtmReportVerdict classify(Channel& ch, std::int64_t seq, std::int64_t count, std::uint64_t& lost,
                            std::uint64_t samples_per_tick) noexcept;

  FtmStreamStats stats_;
  std::uint32_t epoch_ = 0;
  std::array<Channel, 3> channels_{};  // IMUs 0-1, IMUs 2-3, bend
};

}  // namespace proprio::devices
