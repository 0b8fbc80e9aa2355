#pragma once
// StretchStreamDecoder: the host side of one stretch read-out board's report
// stream. It decodes each report, places it in the measurement sequence (lost,
// duplicate, late, board restarted), unwraps the 32-bit measurement counter
// and the 32-bit µs timestamp, gives every measurement its own device time
// (measurement i of a report was taken i measurement periods after measurement
// 0, the period measured from the stream itself in device µs), scales the
// capacitances to pF and counts every measurement the board flagged
// (saturated, below zero, no signal) or that sits at the wire's rail.
//
// Accounting is per measurement, not per report: the sequence number is the
// running number of a report's first measurement, so a gap says exactly how
// many measurements never arrived, whatever the batch sizes.
//
// Why a restart is recognised twice: the board flags the first report after
// power-up, START or SET_RATE (stretch_flags::stream_start), but that report
// can be the one lost, so a sequence that disagrees with the timestamp (by
// more than 4 measurements plus 0.1 % of the distance) also starts a new epoch,
// as does a change of strip counts or of the plan (single strips on or off).
//
// Not thread-safe; one owner (the reader thread) pushes. No allocation.
#include <array>
#include <cstdint>
#include <span>

#include "proprio/core/time.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"

namespace proprio::devices {

// One capacitance measurement as the host delivers it.
struct StretchSample {
  double capacitance_pf = 0.0;    // after the board subtracted its parasitic capacitance
  // The row of the measurement matrix: top_strip * bottom_strips + bottom_strip
  // for a pair, n k + strip for a single strip (protocol 1.1; stretch_sources()).
  std::uint16_t combination = 0;
  // The source strips; kStretchNoStrip for the layer a single-strip row leaves out.
  std::uint8_t top_strip = 0;
  std::uint8_t bottom_strip = 0;
  // The board's status, or saturated for a value at the wire's rail; anything
  // but ok must not enter the solve.
  StretchMeasurementStatus status = StretchMeasurementStatus::ok;
  // Measurement time on the host's CLOCK_MONOTONIC, from the device time
  // through hid::ClockSync (StretchDevice fills it; 0 from the stream decoder alone).
  TimeNs time_ns = 0;
  TimeNs receive_ns = 0;  // when the host read the report
  // This measurement's device time, unwrapped: continuous within an epoch,
  // and equal to the wire's µs counter modulo 2^32.
  std::int64_t device_time_us = 0;
  std::int64_t sequence = 0;  // measurement number within the epoch, unwrapped
  std::uint32_t epoch = 0;    // board restarts seen before this measurement
};

struct StretchStreamOptions {
  // The measurement rate assumed until two reports have been seen (each epoch
  // measures its own period in device µs, so a wrong value here only matters
  // for per-measurement times in the first report after a restart).
  double nominal_rate_hz = kStretchDefaultRateHz;
  // The layout the host will solve with (StretchGloveLayout::top_strips and
  // bottom_strips); 0 accepts any. Reports of a board with other strip counts
  // are refused (wrong glove, or wrong layout file), not decoded into wrong cells.
  std::uint8_t expected_top_strips = 0;
  std::uint8_t expected_bottom_strips = 0;
  // Refuse (wrong_layout) reports of a board that does not measure single
  // strips: a layout that needs M^II rows cannot be solved without them.
  bool require_single_strips = false;
};

enum class StretchReportVerdict : std::uint8_t {
  accepted,      // newer than every report so far: its measurements were written
  duplicate,     // every measurement in it already seen: dropped
  late,          // older than the newest (reordered): dropped, so measurement times never go back; it
                 // takes its measurements off the loss count
  decode_error,  // not a valid report: dropped, counted by reason
  other_report,  // a valid report of another type (device info): no measurements
  wrong_layout,  // valid, but the board's strip counts (or plan) are not the expected ones: dropped
};
inline constexpr std::size_t kStretchReportVerdictCount = 6;
const char* to_string(StretchReportVerdict verdict) noexcept;

struct StretchPushResult {
  StretchReportVerdict verdict = StretchReportVerdict::decode_error;
  StretchDecodeStatus decode;    // why, for decode_error
  std::size_t sample_count = 0;  // samples written (accepted only)
  bool device_reset = false;     // this report began a new epoch after an earlier one
  // For measurement reports (accepted, duplicate, late): where the report sits.
  std::uint8_t count = 0;            // measurements it carries
  std::uint32_t timestamp_us = 0;    // of measurement 0, as on the wire
  std::int64_t device_time_us = 0;   // the same, unwrapped
  // The last measurement's device time, unwrapped: the report left the board
  // right after it, so this is the instant to align clocks on (measurement 0
  // is up to a report's length older than the report).
  std::int64_t last_device_time_us = 0;
  std::int64_t sequence = 0;  // of measurement 0, unwrapped within the epoch
  std::uint32_t epoch = 0;
};

struct StretchStreamStats {
  std::uint64_t reports = 0;  // pushed, of any kind
  std::uint64_t accepted = 0;
  std::uint64_t duplicates = 0;
  std::uint64_t late = 0;
  std::uint64_t decode_errors = 0;
  std::array<std::uint64_t, kStretchDecodeErrcCount> decode_errors_by_code{};  // indexed by StretchDecodeErrc
  std::uint64_t other_reports = 0;
  std::uint64_t wrong_layout = 0;
  // Measurements never seen: gaps in the sequence, less late arrivals that
  // filled them. Measurements across a restart are not counted (the board
  // did not make them).
  std::uint64_t lost = 0;
  std::uint64_t gaps = 0;  // times the sequence jumped forward
  // Measurements delivered by accepted reports, by host status (indexed by StretchMeasurementStatus).
  std::uint64_t measurements = 0;
  std::array<std::uint64_t, kStretchMeasurementStatusCount> by_status{};
  std::uint64_t device_resets = 0;    // epochs begun after the first
  std::uint64_t device_overruns = 0;  // reports the board flagged as following measurements it discarded
  std::uint64_t sequence_wraps = 0;
  std::uint64_t timestamp_wraps = 0;
  std::uint8_t top_strips = 0;  // as the board last said
  std::uint8_t bottom_strips = 0;
  bool single_strips = false;
  double measurement_period_us = 0.0;  // measured in device µs (nominal until measured)
  StretchDecodeStatus last_decode_error;
  // Flagged measurements per combination, to find a broken lead or a shorted cell.
  std::array<std::uint32_t, kStretchMaxCombinations> flagged_by_combination{};

  std::uint64_t measurements_good() const noexcept { return by_status[0]; }
  std::uint64_t measurements_flagged() const noexcept { return measurements - by_status[0]; }
};

class StretchStreamDecoder {
 public:
  explicit StretchStreamDecoder(StretchStreamOptions options = {}) noexcept;

  // Decodes one report (as hid_read returned it: report ID first) received at
  // receive_ns and writes the measurements of an accepted report to out, which
  // should hold kStretchMeasurementsPerReport (those that do not fit are
  // counted but not written). Flagged measurements are written too, with their status.
  StretchPushResult push(std::span<const std::uint8_t> report, std::span<StretchSample> out,
                         TimeNs receive_ns = 0) noexcept;

  const StretchStreamStats& stats() const noexcept { return stats_; }
  const StretchStreamOptions& options() const noexcept { return options_; }
  bool locked() const noexcept { return locked_; }
  std::uint32_t epoch() const noexcept { return epoch_; }

 private:
  static constexpr std::int64_t kWindow = 1024;  // measurements remembered behind the newest, for duplicates
  void begin_epoch(const StretchDataReport& r, bool is_reset, TimeNs receive_ns) noexcept;
  bool seen(std::int64_t seq) const noexcept;
  void mark(std::int64_t seq) noexcept;
  void advance(std::int64_t new_end) noexcept;

  StretchStreamOptions options_;
  StretchStreamStats stats_;
  bool locked_ = false;
  bool any_accepted_ = false;  // in this epoch
  std::uint32_t epoch_ = 0;
  std::uint8_t top_strips_ = 0, bottom_strips_ = 0;
  bool single_strips_ = false;
  std::int64_t newest_seq_ = 0;        // unwrapped measurement 0 of the newest accepted report
  std::int64_t newest_device_us_ = 0;  // unwrapped timestamp of that report
  std::int64_t newest_end_ = 0;        // one past its last measurement
  std::uint8_t newest_count_ = 0;
  std::uint32_t epoch_start_seq_ = 0;
  std::uint32_t epoch_start_ts_ = 0;
  TimeNs epoch_start_receive_ns_ = 0;
  bool period_measured_ = false;
  double period_us_ = 1e6 / kStretchDefaultRateHz;
  std::array<std::uint64_t, kWindow / 64> window_{};  // bit (seq mod kWindow): measurement seq was seen
};

}  // namespace proprio::devices
