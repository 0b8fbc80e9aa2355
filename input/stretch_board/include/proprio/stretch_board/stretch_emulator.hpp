#pragma once
// StretchEmulator: the stretch glove read-out board's firmware without the
// board. A caller-supplied provider says what capacitance (pF, after the
// board's parasitic subtraction) combination c reads at time t; the emulator
// measures the combinations in turn at the configured rate, quantises each
// reading to 1 fF against its full scale (flagging saturated, below-zero and
// non-finite readings as the board does), batches them into the exact HID
// reports the board sends, with a measurement counter and a µs timestamp from
// a crystal that runs clock_error_ppm off and wraps at 2^32. It answers host
// commands and device-info requests as the firmware does, and injects the
// faults a real link and board show: lost, duplicated, corrupted and
// reordered reports, saturated readings, reports the board itself discards
// (overrun) and unplugging (the board loses power and boots again: counter,
// sequence and configuration restart).
//
// The provider keeps proprio::devices independent of the simulator: whoever
// links proprio::sim wires its capacitance model in (tests and the CLI use
// synthetic ones). Deterministic for a given seed and provider. Not
// thread-safe; StretchEmulatorServer serves one over a hid::FakeHidLink in real time.
#include <array>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <thread>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/emulator_faults.hpp"
#include "proprio/hid/emulator_server.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"

namespace proprio::devices {

// Capacitance in pF that combination c reads when measured at t_ns (the
// emulator's time base): c = t * bottom_strips + b for a pair, n k + s for
// single strip s with single_strips on (stretch_sources()). May return anything: negative
// values read below zero, non-finite ones no signal, large ones saturate.
using StretchCapacitanceProvider = std::function<double(std::size_t combination, TimeNs t_ns)>;

struct StretchOutage {
  TimeNs at_ns = 0;            // the cable comes out (emulator time)
  DurationNs duration_ns = 0;  // and goes back in this much later; the board then boots
};

struct StretchEmulatorFaults {
  // Each report independently, from its own seeded stream (switching one
  // fault off leaves the others' draws unchanged).
  double drop_probability = 0.0;
  double duplicate_probability = 0.0;
  double corrupt_probability = 0.0;  // one random bit of one random byte flipped after the CRC
  double reorder_probability = 0.0;  // the report is held back and sent after the next one
  // The board's transmit queue is full (the host is not reading): it discards
  // the report, whose measurements still used up sequence numbers, and flags
  // the next one overrun.
  double device_overrun_probability = 0.0;
  // Each measurement: the layers touch or the counter overflows, so the board
  // reports full scale flagged saturated.
  double saturate_probability = 0.0;
  std::vector<StretchOutage> unplugs;

  bool any() const noexcept;
  Status validate() const;
};

struct StretchEmulatorOptions {
  std::uint8_t top_strips = 13;  // the thesis glove: 13 + 14 leads, 182 combinations
  std::uint8_t bottom_strips = 14;
  // Protocol 1.1: measure the n + k single strips too, after the n k pairs
  // (an array's M^II rows; StretchArrayPlan makes options for a layout).
  // n k + n + k must fit the 10-bit combination field.
  bool single_strips = false;
  std::uint16_t rate_hz = kStretchDefaultRateHz;  // measurements per second
  // The board's full scale (reported in the info report; readings at or above
  // it saturate) and the parasitic capacitance it measures and subtracts (only
  // reported: the provider gives values after subtraction).
  double full_scale_pf = 1000.0;
  double parasitic_pf = 15.0;
  // The µs counter runs at (1 + clock_error_ppm·1e-6) µs per true µs, and the
  // measurement timer with it.
  double clock_error_ppm = 0.0;
  // Counter value at each boot. Real firmware starts at 0; a value near 2^32
  // makes the counter wrap early, which is what tests want.
  std::uint32_t boot_timestamp_us = 0;
  TimeNs boot_time_ns = 0;  // time (emulator time base) the board first powers up
  std::array<std::uint8_t, 3> firmware{1, 0, 0};
  // A report leaves when it holds this many measurements (1-12), or when the
  // next measurement would make it span more than max_report_age_ns (so that
  // slow rates do not add latency).
  std::uint8_t measurements_per_report = kStretchMeasurementsPerReport;
  DurationNs max_report_age_ns = 20 * kNsPerMillisecond;
  bool stream_on_boot = true;  // the firmware streams from power-up without waiting for START
  std::uint64_t seed = 1;
  StretchEmulatorFaults faults;

  // Rows measured in turn: the pairs, then the single strips if on.
  std::size_t combination_count() const noexcept { return stretch_row_count(top_strips, bottom_strips, single_strips); }
  Status validate() const;
};

// One report as it leaves the board.
struct StretchEmulatedReport {
  TimeNs send_ns = 0;  // emulator time base: right after its last measurement
  std::array<std::uint8_t, kStretchDataReportSize> bytes{};
};

struct StretchEmulatorStats {
  std::uint64_t measurements = 0;  // made while powered and streaming
  std::uint64_t reports_sent = 0;  // reports that left the board, duplicates included
  std::uint64_t dropped = 0;
  std::uint64_t duplicated = 0;
  std::uint64_t corrupted = 0;
  std::uint64_t reordered = 0;
  std::uint64_t device_overruns = 0;  // reports the board discarded itself
  std::uint64_t saturated = 0;        // readings at full scale, injected ones included
  std::uint64_t injected_saturations = 0;
  std::uint64_t below_zero = 0;
  std::uint64_t no_signal = 0;
  std::uint64_t boots = 0;              // power-ups, the first included
  std::uint64_t discarded_partial = 0;  // measurements in a report that power loss, STOP or a restart cut short
};

class StretchEmulator {
 public:
  static Result<StretchEmulator> create(StretchEmulatorOptions options, StretchCapacitanceProvider provider);

  // Makes every measurement due up to t_ns (emulator time; a t_ns before the
  // last one is a no-op) and appends the reports that left the board by
  // then, in send order (none while unplugged or stopped; a report held back
  // for reordering comes out with a later one).
  void advance_to(TimeNs t_ns, std::vector<StretchEmulatedReport>& out);
  // Sends a report still held back for reordering (end of a session).
  void flush(std::vector<StretchEmulatedReport>& out);

  // Host -> board: a command output report received at t_ns (applied at the
  // emulator's current time if that is later). Applies it as the firmware
  // does and records the outcome in the next info report. Bad bytes are
  // answered with StretchCommandResult::bad_report, never an exception.
  StretchCommandResult handle_command(std::span<const std::uint8_t> report, TimeNs t_ns);
  // The device-info feature report as the firmware builds it at t_ns.
  std::array<std::uint8_t, kStretchInfoReportSize> info_report(TimeNs t_ns) const;

  // The board's µs counter at true time t_ns (wrapped, as sent).
  std::uint32_t device_timestamp_us(TimeNs t_ns) const noexcept;
  bool powered_at(TimeNs t_ns) const noexcept;
  bool streaming() const noexcept { return streaming_; }
  std::uint16_t rate_hz() const noexcept { return rate_hz_; }
  // When measurement `sequence` of the current run is (was) taken, emulator time.
  TimeNs measurement_time_ns(std::uint64_t sequence) const noexcept;
  TimeNs now_ns() const noexcept { return now_ns_; }  // how far advance_to has gone
  std::uint32_t full_scale_ff() const noexcept { return full_scale_ff_; }
  const StretchEmulatorOptions& options() const noexcept { return options_; }
  const StretchEmulatorStats& stats() const noexcept { return stats_; }

 private:
  StretchEmulator(StretchEmulatorOptions options, StretchCapacitanceProvider provider);
  void boot(TimeNs t_ns) noexcept;
  void restart_run(TimeNs t_ns) noexcept;
  TimeNs next_power_event_after(TimeNs t_ns) const noexcept;
  void measure(TimeNs t_ns, std::vector<StretchEmulatedReport>& out);
  void emit(TimeNs send_ns, std::vector<StretchEmulatedReport>& out);
  void send(const StretchEmulatedReport& report, std::vector<StretchEmulatedReport>& out);
  void discard_batch() noexcept;

  StretchEmulatorOptions options_;
  StretchCapacitanceProvider provider_;
  hid::EmulatorLinkFaults<StretchEmulatedReport> link_faults_;  // drop, duplicate, corrupt, reorder
  Rng overrun_rng_, saturate_rng_;
  std::uint32_t full_scale_ff_ = 0;
  std::uint32_t parasitic_ff_ = 0;
  TimeNs now_ns_ = 0;
  bool powered_ = false;
  TimeNs last_boot_ns_ = 0;
  bool streaming_ = true;
  std::uint16_t rate_hz_ = kStretchDefaultRateHz;
  double period_ns_ = 0.0;  // true time between measurements
  TimeNs run_start_ns_ = 0;
  std::uint64_t next_seq_ = 0;
  std::uint8_t pending_flags_ = 0;  // stretch_flags for the next report the board queues
  std::uint8_t last_token_ = 0;
  StretchCommandResult last_result_ = StretchCommandResult::none;
  StretchDataReport batch_;  // measurements so far of the report being filled
  TimeNs batch_first_ns_ = 0;
  StretchEmulatorStats stats_;
};

// ---------------------------------------------------------------------------
// Serving the emulator over a fake cable, in real time.

struct StretchServeOptions {
  // Each report reaches the host this long after it left the board: a floor
  // (USB polling, host controller, kernel) plus a uniform extra up to jitter.
  DurationNs latency_min_ns = 200'000;
  DurationNs latency_jitter_ns = 800'000;
  // The pumping thread's period, and how far ahead of the clock it runs the
  // emulator (so that each report is queued before it falls due and arrives
  // on time; commands take effect up to this much late).
  DurationNs pump_interval_ns = 2 * kNsPerMillisecond;
  DurationNs lookahead_ns = 5 * kNsPerMillisecond;
  std::uint64_t seed = 1;  // latency draws
};

// The board's end of a hid::FakeHidLink (hid::EmulatorServer): a thread runs
// the emulator in step with the link's clock, lookahead_ns ahead, and queues
// its reports on the link. What `proprio stretch-board emulate` and the
// StretchDevice tests use.
struct StretchEmulatorServerTraits {
  using Emulator = StretchEmulator;
  using Options = StretchServeOptions;
  using Report = StretchEmulatedReport;
  static void advance(StretchEmulator& emulator, const StretchServeOptions& options, TimeNs now_ns,
                      std::vector<StretchEmulatedReport>& out);
  static void handle_command(StretchEmulator& emulator, std::span<const std::uint8_t> bytes, TimeNs now_ns);
  static std::size_t feature(StretchEmulator& emulator, std::uint8_t report_id, TimeNs now_ns,
                             std::span<std::uint8_t> out);
};
using StretchEmulatorServer = hid::EmulatorServer<StretchEmulatorServerTraits>;

}  // namespace proprio::devices
