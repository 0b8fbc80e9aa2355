#pragma once
// ImuGloveStreamDecoder: the host side of one glove's report stream. It decodes
// each report, places it in the sequence (lost, duplicate, late, device
// restarted), unwraps the 16-bit sequence and the 32-bit µs timestamp, turns
// raw counts into SI samples and counts every sample the device flagged
// (stale, saturated, sensor error) or that sits at the int16 rail.
//
// Each tick of a glove with more than four IMUs comes as several reports (a
// "part" per four IMUs), all with the tick's sequence number and timestamp.
// Parts are tracked separately: a part's reports form their own sequence, so
// a lost report costs only its four IMUs, and per-IMU time order holds.
//
// Why a device reset is recognised twice: the firmware flags the first tick
// after power-up or START (data_flags::stream_start), but that very report can
// be the one lost, so a sequence number that disagrees with the timestamp
// (more than 2.5 ticks apart) also starts a new epoch.
//
// Not thread-safe; one owner (the reader thread) pushes. No allocation.
#include <array>
#include <cstdint>
#include <span>

#include "proprio/core/recording.hpp"
#include "proprio/core/time.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"

namespace proprio::devices {

// One IMU reading as the host delivers it.
struct ImuGloveSample {
  ImuSample imu;  // SI units in the IMU's sensor frame; sensor_id 0-15
  // Measurement time on the host's CLOCK_MONOTONIC, from the device timestamp
  // through hid::ClockSync (ImuGloveDevice fills it; 0 from the stream decoder alone).
  TimeNs time_ns = 0;
  TimeNs receive_ns = 0;             // when the host read the report
  std::int64_t device_time_us = 0;   // the device timestamp unwrapped, continuous within an epoch
  std::uint32_t timestamp_us = 0;    // the device timestamp as on the wire
  std::uint32_t epoch = 0;           // device restarts seen before this sample
  std::uint16_t sequence = 0;        // as on the wire
  std::uint8_t status = 0;           // imu_status bits, the device's and the host's own; 0 = usable
};

struct ImuGloveStreamOptions {
  // The tick rate assumed until two consecutive ticks have been seen (each
  // epoch measures its own period in device µs, so a wrong value here only
  // matters for gaps in the first ticks after a restart).
  double nominal_rate_hz = 100.0;
};

enum class ImuGloveReportVerdict : std::uint8_t {
  accepted,      // the newest report of its part: its samples were written
  duplicate,     // a report already seen: dropped
  late,          // older than one already accepted for its part (reordered): dropped, so each IMU's
                 // samples stay in time order
  decode_error,  // not a valid report: dropped, counted by reason
  other_report,  // a valid report of another type (device info): no samples
};
const char* to_string(ImuGloveReportVerdict verdict) noexcept;

struct ImuGlovePushResult {
  ImuGloveReportVerdict verdict = ImuGloveReportVerdict::decode_error;
  ImuGloveDecodeStatus decode;       // why, for decode_error
  std::size_t sample_count = 0;   // samples written (accepted only)
  bool device_reset = false;      // this report began a new epoch after an earlier one
  // For data reports (accepted, duplicate, late): where the report sits in time.
  std::uint32_t timestamp_us = 0;
  std::int64_t device_time_us = 0;
  std::int64_t sequence = 0;  // unwrapped within the epoch
  std::uint32_t epoch = 0;
};

struct ImuGloveImuStats {
  std::uint64_t good = 0;      // delivered samples with no status bit
  std::uint64_t rejected = 0;  // samples with any status bit (each also counted by kind below)
  std::uint64_t stale = 0;
  std::uint64_t accel_saturated = 0;
  std::uint64_t gyro_saturated = 0;
  std::uint64_t sensor_error = 0;  // bus errors, or non-finite values the firmware refused to send
};

struct ImuGloveStreamStats {
  std::uint64_t reports = 0;  // pushed, of any kind
  std::uint64_t accepted = 0;
  // Reports never seen: gaps in each part's sequence, less late arrivals that
  // filled one. Loss across a device restart is not counted (the device did
  // not send those ticks).
  std::uint64_t lost = 0;
  std::uint64_t duplicates = 0;
  std::uint64_t late = 0;
  std::uint64_t decode_errors = 0;
  std::array<std::uint64_t, kImuGloveDecodeErrcCount> decode_errors_by_code{};  // indexed by ImuGloveDecodeErrc
  std::uint64_t other_reports = 0;
  std::uint64_t device_resets = 0;    // epochs begun after the first
  std::uint64_t device_overruns = 0;  // ticks the device flagged as following ticks it skipped itself
  std::uint64_t sequence_wraps = 0;
  std::uint64_t timestamp_wraps = 0;
  std::uint8_t imu_total = 0;      // IMUs per tick, as the device last said
  double tick_period_us = 0.0;     // measured in device µs (nominal until measured)
  std::array<ImuGloveImuStats, kImuGloveMaxImus> imus{};
  ImuGloveDecodeStatus last_decode_error;

  std::uint64_t samples_good() const noexcept;
  std::uint64_t samples_rejected() const noexcept;
};

class ImuGloveStreamDecoder {
 public:
  explicit ImuGloveStreamDecoder(ImuGloveStreamOptions options = {}) noexcept;

  // Decodes one report (as hid_read returned it: report ID first) received at
  // receive_ns and writes the samples of an accepted data report to out, which
  // should hold kImuGloveImusPerReport (samples that do not fit are not written).
  // Flagged samples are written too, with their status bits, and counted.
  ImuGlovePushResult push(std::span<const std::uint8_t> report, std::span<ImuGloveSample> out,
                       TimeNs receive_ns = 0) noexcept;

  const ImuGloveStreamStats& stats() const noexcept { return stats_; }
  bool locked() const noexcept { return locked_; }
  std::uint32_t epoch() const noexcept { return epoch_; }

 private:
  struct Part {
    bool seen = false;
    std::int64_t newest = 0;    // unwrapped sequence of the newest accepted report
    std::uint64_t window = 0;   // bit i: report newest - i was seen
  };
  void begin_epoch(const ImuGloveDataReport& r, bool is_reset) noexcept;
  void advance_newest(std::int64_t seq, std::int64_t device_us) noexcept;

  ImuGloveStreamOptions options_;
  ImuGloveStreamStats stats_;
  bool locked_ = false;
  std::uint32_t epoch_ = 0;
  std::uint8_t imu_total_ = 0;
  std::int64_t newest_seq_ = 0;       // unwrapped, newest tick of any part
  std::int64_t newest_device_us_ = 0; // unwrapped timestamp of that tick
  std::int64_t epoch_start_seq_ = 0;
  std::uint32_t epoch_start_ts_ = 0;
  TimeNs epoch_start_receive_ns_ = 0;
  bool epoch_flagged_ = false;        // the epoch began at a stream_start report
  bool period_measured_ = false;
  double period_us_ = 10000.0;
  std::int64_t last_overrun_seq_ = -1;
  std::array<Part, kImuGloveMaxReportsPerTick> parts_{};
};

}  // namespace proprio::devices
