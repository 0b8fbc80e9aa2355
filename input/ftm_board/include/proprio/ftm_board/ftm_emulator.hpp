#pragma once
// FtmBoardEmulator: the FTM read-out board's firmware without the board. An
// ftm::FtmSampleFeed (the simulated wearer, or a synthetic feed in tests)
// says what the sensors measure; the emulator samples it as the board does -
// the four IMUs at each IMU tick (200 Hz by default), the three bend sensors
// at each bend tick (1 kHz) - holding the newest sample of each sensor and
// flagging stale when the feed had nothing new since the last tick. It
// quantises as the firmware does (quantise_imu, quantise_bend: saturation,
// compass overflow, sensor errors), builds the exact HID reports the board
// sends with sequence numbers and a µs timestamp from a crystal that runs
// clock_error_ppm off and wraps at 2^32, answers host commands and
// device-info requests, and injects the faults a real link and board show
// (hid::EmulatorLinkFaults: lost, duplicated, corrupted and reordered reports;
// plus reports the board discards itself and unplugging, after which the
// board boots again: counter, sequences and configuration restart).
//
// The feed's time base is the emulator's. Deterministic for a given seed and
// feed. Not thread-safe; FtmBoardEmulatorServer serves one over a
// hid::FakeHidLink in real time.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_glove.hpp"
#include "proprio/ftm_board/ftm_protocol.hpp"
#include "proprio/hid/emulator_faults.hpp"
#include "proprio/hid/emulator_server.hpp"
#include "proprio/hid/hid_transport.hpp"

namespace proprio::devices {

struct FtmOutage {
  TimeNs at_ns = 0;            // the cable comes out (emulator time)
  DurationNs duration_ns = 0;  // and goes back in this much later; the board then boots
};

struct FtmEmulatorFaults {
  // Each report independently, from its own seeded stream.
  double drop_probability = 0.0;
  double duplicate_probability = 0.0;
  double corrupt_probability = 0.0;  // one random bit of one random byte flipped after the CRC
  double reorder_probability = 0.0;  // held back and sent after the next report
  // The board's transmit queue is full: it discards the report (its ticks
  // still used up sequence numbers) and flags the next one of its channel overrun.
  double device_overrun_probability = 0.0;
  std::vector<FtmOutage> unplugs;

  bool any() const noexcept;
  Status validate() const;
};

struct FtmEmulatorOptions {
  std::uint16_t imu_rate_hz = kFtmDefaultImuRateHz;
  std::uint16_t bend_rate_hz = kFtmDefaultBendRateHz;
  FtmAccelRange accel_range = kFtmDefaultAccelRange;
  FtmGyroRange gyro_range = kFtmDefaultGyroRange;
  // The µs counter and the sampling timers run at (1 + clock_error_ppm·1e-6) per true µs.
  double clock_error_ppm = 0.0;
  // Counter value at each boot (firmware starts at 0; near 2^32 makes tests wrap early).
  std::uint32_t boot_timestamp_us = 0;
  TimeNs boot_time_ns = 0;  // emulator time the board first powers up
  std::array<std::uint8_t, 3> firmware{1, 0, 0};
  std::uint8_t bend_samples_per_report = kFtmBendSamplesPerReport;  // 1-5
  bool stream_on_boot = true;
  std::uint64_t seed = 1;
  FtmEmulatorFaults faults;

  Status validate() const;
};

// One report as it leaves the board.
struct FtmEmulatedReport {
  TimeNs send_ns = 0;  // emulator time: right after its last tick
  std::array<std::uint8_t, kFtmDataReportSize> bytes{};
};

struct FtmEmulatorStats {
  std::uint64_t imu_ticks = 0;   // made while powered and streaming
  std::uint64_t bend_ticks = 0;
  std::uint64_t reports_sent = 0;  // that left the board, duplicates included
  std::uint64_t dropped = 0;
  std::uint64_t duplicated = 0;
  std::uint64_t corrupted = 0;
  std::uint64_t reordered = 0;
  std::uint64_t device_overruns = 0;
  std::uint64_t imu_stale = 0;  // IMU samples sent stale (the feed had nothing new)
  std::uint64_t bend_stale = 0;
  std::uint64_t imu_flagged = 0;   // sent with saturation, overflow or sensor error
  std::uint64_t bend_flagged = 0;  // sent over range or with sensor error
  std::uint64_t boots = 0;
  std::uint64_t discarded_partial = 0;  // bend ticks in a report that power loss or STOP cut short
};

class FtmBoardEmulator {
 public:
  // The feed must not be null; it is advanced in emulator time.
  static Result<FtmBoardEmulator> create(FtmEmulatorOptions options, std::unique_ptr<ftm::FtmSampleFeed> feed);

  // Makes every tick due up to t_ns and appends the reports that left the
  // board by then, in send order (none while unplugged or stopped).
  void advance_to(TimeNs t_ns, std::vector<FtmEmulatedReport>& out);
  // Sends a report still held back for reordering (end of a session).
  void flush(std::vector<FtmEmulatedReport>& out);

  // Host -> board: a command output report received at t_ns. Applies it as
  // the firmware does; bad bytes are answered with bad_report, never thrown.
  FtmCommandResult handle_command(std::span<const std::uint8_t> report, TimeNs t_ns);
  std::array<std::uint8_t, kFtmInfoReportSize> info_report(TimeNs t_ns) const;

  std::uint32_t device_timestamp_us(TimeNs t_ns) const noexcept;
  bool powered_at(TimeNs t_ns) const noexcept;
  bool streaming() const noexcept { return streaming_; }
  // When IMU tick / bend tick `n` of the current run is (was) sampled, emulator time.
  TimeNs imu_tick_time_ns(std::uint64_t n) const noexcept;
  TimeNs bend_tick_time_ns(std::uint64_t n) const noexcept;
  TimeNs now_ns() const noexcept { return now_ns_; }
  const FtmEmulatorOptions& options() const noexcept { return options_; }
  const FtmEmulatorStats& stats() const noexcept { return stats_; }

 private:
  FtmBoardEmulator(FtmEmulatorOptions options, std::unique_ptr<ftm::FtmSampleFeed> feed);
  void boot(TimeNs t_ns) noexcept;
  void restart_run(TimeNs t_ns) noexcept;
  TimeNs next_power_event_after(TimeNs t_ns) const noexcept;
  void pull_feed(TimeNs t_ns);
  void imu_tick(TimeNs t_ns, std::vector<FtmEmulatedReport>& out);
  void bend_tick(TimeNs t_ns, std::vector<FtmEmulatedReport>& out);
  void send(std::size_t channel, TimeNs send_ns, const std::array<std::uint8_t, kFtmDataReportSize>& bytes,
            std::vector<FtmEmulatedReport>& out);
  void discard_batch() noexcept;

  FtmEmulatorOptions options_;
  std::unique_ptr<ftm::FtmSampleFeed> feed_;
  std::vector<ftm::FtmEvent> events_;  // the feed's output, reused
  hid::EmulatorLinkFaults<FtmEmulatedReport> link_faults_;
  Rng overrun_rng_;
  // The newest sample of each sensor from the feed, and whether it is new
  // since the last tick; the compass keeps its newest fresh reading.
  std::array<ftm::FtmImuSample, ftm::kFtmImuCount> imu_latest_{};
  std::array<bool, ftm::kFtmImuCount> imu_new_{};
  std::array<bool, ftm::kFtmImuCount> mag_new_{};
  std::array<Vec3, ftm::kFtmImuCount> mag_latest_{};
  std::array<std::uint8_t, ftm::kFtmImuCount> mag_overflow_{};
  std::array<ftm::FtmBendSample, ftm::kFtmBendCount> bend_latest_{};
  std::array<bool, ftm::kFtmBendCount> bend_new_{};
  TimeNs fed_to_ns_ = -1;

  TimeNs now_ns_ = 0;
  bool powered_ = false;
  bool streaming_ = true;
  std::uint16_t imu_rate_hz_ = kFtmDefaultImuRateHz;
  std::uint16_t bend_rate_hz_ = kFtmDefaultBendRateHz;
  FtmAccelRange accel_range_ = kFtmDefaultAccelRange;
  FtmGyroRange gyro_range_ = kFtmDefaultGyroRange;
  double imu_period_ns_ = 0.0;  // true time between ticks
  double bend_period_ns_ = 0.0;
  TimeNs run_start_ns_ = 0;
  std::uint64_t next_imu_ = 0;
  std::uint64_t next_bend_ = 0;
  std::array<std::uint8_t, 3> pending_flags_{};  // per channel: IMUs 0-1, IMUs 2-3, bend
  std::uint8_t last_token_ = 0;
  FtmCommandResult last_result_ = FtmCommandResult::none;
  FtmBendReport batch_;  // bend ticks so far of the report being filled
  FtmEmulatorStats stats_;
};

// ---------------------------------------------------------------------------
// Serving the emulator over a fake cable, in real time.

struct FtmServeOptions {
  // Each report reaches the host this long after it left the board: a floor
  // plus a uniform extra up to jitter.
  DurationNs latency_min_ns = 200'000;
  DurationNs latency_jitter_ns = 800'000;
  // The pumping thread's period, and how far ahead of the clock it runs the
  // emulator (so each report is queued before it falls due).
  DurationNs pump_interval_ns = 2 * kNsPerMillisecond;
  DurationNs lookahead_ns = 5 * kNsPerMillisecond;
  std::uint64_t seed = 1;  // latency draws
};

// The board's end of a hid::FakeHidLink (hid::EmulatorServer): what
// `proprio ftm-board emulate` and the FtmBoardDevice tests use.
struct FtmEmulatorServerTraits {
  using Emulator = FtmBoardEmulator;
  using Options = FtmServeOptions;
  using Report = FtmEmulatedReport;
  static void advance(FtmBoardEmulator& emulator, const FtmServeOptions& options, TimeNs now_ns,
                      std::vector<FtmEmulatedReport>& out);
  static void handle_command(FtmBoardEmulator& emulator, std::span<const std::uint8_t> bytes, TimeNs now_ns);
  static std::size_t feature(FtmBoardEmulator& emulator, std::uint8_t report_id, TimeNs now_ns,
                             std::span<std::uint8_t> out);
};
using FtmBoardEmulatorServer = hid::EmulatorServer<FtmEmulatorServerTraits>;

}  // namespace proprio::devices
