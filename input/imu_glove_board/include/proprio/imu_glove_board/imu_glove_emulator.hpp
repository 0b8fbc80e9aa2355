#pragma once
// ImuGloveEmulator: the glove's firmware without the glove. Fed one tick of IMU
// readings in SI units (from proprio::sim's ImuSimulator, a recording, or a
// test), it produces the exact HID reports the device would send: counts
// quantised with the configured full scale and clamped at the rail (flagged
// saturated), non-finite readings flagged as sensor errors, a sequence number
// per tick and a µs timestamp from a crystal that runs off by clock_error_ppm
// and wraps at 2^32. It answers host commands and device-info requests as the
// firmware does, and injects the faults a real link shows: lost, duplicated,
// corrupted and reordered reports, stale samples, and unplugging (the glove
// loses power and boots again: counter and sequence restart).
//
// It depends on core and hid only; whoever links proprio::sim does the wiring (see
// tools/proprio/cmd_glove.cpp and tests/unit/input/imu_glove_board/test_glove_emulator.cpp).
// Deterministic for a given seed. Not thread-safe; ImuGloveEmulatorServer
// (below) serves one over a hid::FakeHidLink in real time.
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/emulator_faults.hpp"
#include "proprio/hid/emulator_server.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"

namespace proprio::devices {

struct ImuGloveOutage {
  TimeNs at_ns = 0;            // the cable comes out (emulator time, the readings' time base)
  DurationNs duration_ns = 0;  // and goes back in this much later; the glove then boots
};

struct ImuGloveEmulatorFaults {
  // Each report independently, from its own seeded stream (switching one
  // fault off leaves the others' draws unchanged).
  double drop_probability = 0.0;
  double duplicate_probability = 0.0;
  double corrupt_probability = 0.0;  // one random bit of one random byte flipped after the CRC
  double reorder_probability = 0.0;  // the report is held back and sent after the next one
  // Each IMU each tick: no data-ready in time, so the firmware repeats the
  // previous values flagged stale.
  double stale_probability = 0.0;
  std::vector<ImuGloveOutage> unplugs;

  bool any() const noexcept;
  Status validate() const;
};

struct ImuGloveEmulatorOptions {
  std::uint8_t imu_count = 7;
  std::uint16_t rate_hz = 100;
  AccelRange accel_range = AccelRange::g16;
  GyroRange gyro_range = GyroRange::dps2000;
  // The µs counter runs at (1 + clock_error_ppm·1e-6) µs per true µs.
  double clock_error_ppm = 0.0;
  // Counter value at each boot. Real firmware starts at 0; a value near 2^32
  // makes the counter wrap early, which is what tests want.
  std::uint32_t boot_timestamp_us = 0;
  // Time (emulator time base) the glove first powers up.
  TimeNs boot_time_ns = 0;
  std::array<std::uint8_t, 3> firmware{1, 0, 0};
  // The two reports of a tick leave in consecutive 1 ms USB frames.
  DurationNs report_spacing_ns = kNsPerMillisecond;
  bool stream_on_boot = true;  // the firmware streams from power-up without waiting for START
  std::uint64_t seed = 1;
  ImuGloveEmulatorFaults faults;

  Status validate() const;
};

// One report as it leaves the device.
struct ImuGloveEmulatedReport {
  TimeNs send_ns = 0;  // emulator time base: tick time + part * report_spacing_ns
  std::array<std::uint8_t, kImuGloveDataReportSize> bytes{};
};

struct ImuGloveEmulatorStats {
  std::uint64_t ticks = 0;          // ticks the glove was powered and streaming for
  std::uint64_t reports_sent = 0;   // reports that left the device, duplicates included
  std::uint64_t dropped = 0;
  std::uint64_t duplicated = 0;
  std::uint64_t corrupted = 0;
  std::uint64_t reordered = 0;
  std::uint64_t stale_samples = 0;
  std::uint64_t saturated_samples = 0;  // accel or gyro at the rail
  std::uint64_t error_samples = 0;      // non-finite input
  std::uint64_t boots = 0;              // power-ups, the first included
  std::uint64_t ticks_unpowered = 0;    // ticks that fell into an outage
};

class ImuGloveEmulator {
 public:
  static Result<ImuGloveEmulator> create(ImuGloveEmulatorOptions options);

  // One tick measured at t_ns (emulator time; ticks in increasing time):
  // samples holds the readings of IMUs 0..imu_count-1 in sensor_id order.
  // Appends the reports the device sends for it (none while unplugged or
  // stopped; a report held back for reordering comes out with a later tick).
  // Errc::invalid_argument if the sample count or sensor IDs do not match.
  Status tick(TimeNs t_ns, std::span<const ImuSample> samples, std::vector<ImuGloveEmulatedReport>& out);
  // Sends a report still held back for reordering (end of a session).
  void flush(std::vector<ImuGloveEmulatedReport>& out);

  // Host -> device: a command output report. Applies it as the firmware does
  // and records the outcome in the next info report. Bad bytes are answered
  // with ImuGloveCommandResult::bad_report, never an exception.
  ImuGloveCommandResult handle_command(std::span<const std::uint8_t> report);
  // The device-info feature report as the firmware builds it at t_ns.
  std::array<std::uint8_t, kImuGloveInfoReportSize> info_report(TimeNs t_ns) const;

  // The device's µs counter at true time t_ns (wrapped, as sent).
  std::uint32_t device_timestamp_us(TimeNs t_ns) const noexcept;
  bool powered_at(TimeNs t_ns) const noexcept;
  bool streaming() const noexcept { return streaming_; }
  std::uint16_t rate_hz() const noexcept { return rate_hz_; }
  AccelRange accel_range() const noexcept { return accel_range_; }
  GyroRange gyro_range() const noexcept { return gyro_range_; }
  const ImuGloveEmulatorOptions& options() const noexcept { return options_; }
  const ImuGloveEmulatorStats& stats() const noexcept { return stats_; }

 private:
  explicit ImuGloveEmulator(ImuGloveEmulatorOptions options);
  void boot(TimeNs t_ns) noexcept;
  void send(const ImuGloveEmulatedReport& report, std::vector<ImuGloveEmulatedReport>& out);

  ImuGloveEmulatorOptions options_;
  hid::EmulatorLinkFaults<ImuGloveEmulatedReport> link_faults_;  // drop, duplicate, corrupt, reorder
  Rng stale_rng_;
  bool powered_ = false;
  TimeNs last_boot_ns_ = 0;
  bool streaming_ = true;
  bool restart_pending_ = true;  // next tick: sequence 0, flagged stream_start
  std::uint16_t sequence_ = 0;
  bool overrun_pending_ = false;
  TimeNs last_tick_ns_ = 0;
  bool has_ticked_ = false;
  std::uint16_t rate_hz_ = 100;
  AccelRange accel_range_ = AccelRange::g16;
  GyroRange gyro_range_ = GyroRange::dps2000;
  std::uint8_t last_token_ = 0;
  ImuGloveCommandResult last_result_ = ImuGloveCommandResult::none;
  std::vector<ImuGloveImuRaw> last_raw_;  // the last fresh values, which a stale sample repeats
  std::vector<ImuGloveImuRaw> tick_raw_;  // this tick's, per IMU
  ImuGloveEmulatorStats stats_;
};

// ---------------------------------------------------------------------------
// Serving the emulator over a fake cable, in real time.

// What the IMUs read at one tick: fills `out` (already sized to imu_count,
// sensor_id set in order) for tick number `tick` (from 0, counting across
// reboots) measured at emulator time t_ns. Called on the server's thread, one
// call per tick in time order, so a stateful source (proprio::sim's
// ImuSimulator, whose bias walk runs tick by tick) can be read directly.
using ImuGloveReadingProvider = std::function<void(std::int64_t tick, TimeNs t_ns, std::span<ImuSample> out)>;

// The emulator with what drives it: the firmware runs on ticks of readings,
// not on time, so the server ticks it at its current rate (which a host
// command may change) with the provider's readings.
struct ImuGloveTicker {
  ImuGloveTicker(ImuGloveEmulator e, ImuGloveReadingProvider r) : emulator(std::move(e)), readings(std::move(r)) {}
  ImuGloveEmulator emulator;
  ImuGloveReadingProvider readings;
  TimeNs next_tick_ns = 0;
  std::int64_t ticks = 0;
  // Ticks the emulator refused (the provider filled wrong sensor IDs): nothing
  // was sent for them. A correct provider leaves this at 0.
  std::uint64_t refused_ticks = 0;
  std::vector<ImuSample> scratch;
  const ImuGloveEmulatorStats& stats() const noexcept { return emulator.stats(); }
};

struct ImuGloveServeOptions {
  // Each report reaches the host this long after it left the board: a floor
  // (USB polling, host controller, kernel) plus a uniform extra up to jitter.
  DurationNs latency_min_ns = 200'000;
  DurationNs latency_jitter_ns = 800'000;
  DurationNs pump_interval_ns = 2 * kNsPerMillisecond;  // the pumping thread's period
  std::uint64_t seed = 1;                               // latency draws
};

// The board's end of a hid::FakeHidLink (hid::EmulatorServer): what the
// emulated VIST rig (proprio::vist_eval) and the HID conformance tests use.
struct ImuGloveEmulatorServerTraits {
  using Emulator = ImuGloveTicker;
  using Options = ImuGloveServeOptions;
  using Report = ImuGloveEmulatedReport;
  static void advance(ImuGloveTicker& glove, const ImuGloveServeOptions& options, TimeNs now_ns,
                      std::vector<ImuGloveEmulatedReport>& out);
  static void handle_command(ImuGloveTicker& glove, std::span<const std::uint8_t> bytes, TimeNs now_ns);
  static std::size_t feature(ImuGloveTicker& glove, std::uint8_t report_id, TimeNs now_ns, std::span<std::uint8_t> out);
};
using ImuGloveEmulatorServer = hid::EmulatorServer<ImuGloveEmulatorServerTraits>;

}  // namespace proprio::devices
