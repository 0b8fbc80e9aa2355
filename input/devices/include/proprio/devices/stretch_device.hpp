#pragma once
// StretchDevice: one stretch glove read-out board, live. A reader thread opens
// the transport, reads reports, decodes them (StretchStreamDecoder), maps
// device time to CLOCK_MONOTONIC (ClockSync) and hands timestamped
// measurements to one consumer through a bounded SPSC ring (or a callback).
// When the board goes away it reports the state change, retries with
// exponential backoff and resumes when the board is back; a restarted board
// begins a new epoch and the clock re-locks. The same design as GloveDevice
// (glove_device.hpp), whose documentation in docs/glove-hid-protocol.md §9
// applies; what differs is said here.
//
// Clocks are aligned on each report's *last* measurement: the board sends a
// report right after completing it, so that instant plus the link's latency
// is the receive time's floor. Each measurement then gets its own time from
// its device time, and the times strictly increase across the stream.
//
// A reader that fell behind (scheduling, a reconnect) finds several reports
// waiting, and the first of them arrived late by the whole backlog; mapped
// through a clock locked on it alone, its measurements would come out late by
// that much. So the reader takes everything already waiting (up to
// kStretchMaxBurst reports), observes all of it, and only then maps times and
// delivers.
//
// Measurements the board or the host flagged (saturated, below zero, no
// signal) are rejected and counted unless deliver_flagged is set: the cell
// solve must not mix a clipped reading into a least-squares fit.
#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string_view>
#include <thread>
#include <vector>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/devices/clock_sync.hpp"
#include "proprio/devices/glove_device.hpp"  // GloveLinkState
#include "proprio/devices/hid_transport.hpp"
#include "proprio/devices/spsc_ring.hpp"
#include "proprio/devices/stretch_protocol.hpp"
#include "proprio/devices/stretch_stream.hpp"

namespace proprio::devices {

// connecting, streaming, disconnected, stopped: the same for every board.
using StretchLinkState = GloveLinkState;

// Reports the reader takes in one go before it maps and delivers (the backlog
// a reconnect or a stall leaves is rarely more than a few).
inline constexpr std::size_t kStretchMaxBurst = 32;

// A stretch board's HID interface: the selector StretchDevice's callers pass
// to HidapiTransport (the transport's defaults are the IMU glove's).
HidDeviceSelector stretch_board_selector();

struct StretchDeviceOptions {
  StretchStreamOptions stream;
  ClockSyncOptions clock;
  // How long one read waits; also bounds how long stop() takes.
  DurationNs read_timeout_ns = 100 * kNsPerMillisecond;
  // Reconnect attempts back off from min to max, doubling.
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  // Send START when connected but silent this long (another program may have
  // stopped the board). 0: never. START restarts the stream, so a streaming
  // board is left alone.
  DurationNs restart_after_silence_ns = kNsPerSecond;
  // Read the device-info feature report after each connect (firmware, strips, rate, full scale).
  bool query_info = true;
  // Deliver flagged measurements too (with their status) instead of rejecting them.
  bool deliver_flagged = false;
  std::size_t queue_capacity = 8192;  // measurements; about 8.5 s at 960 per second
};

struct StretchDeviceStats {
  StretchLinkState state = StretchLinkState::stopped;
  StretchStreamStats stream;
  std::uint64_t connects = 0;
  std::uint64_t disconnects = 0;  // a connected board lost (read failed)
  std::uint64_t open_failures = 0;
  std::uint64_t reports_read = 0;
  std::uint64_t restart_commands = 0;  // STARTs sent after silence
  std::uint64_t write_failures = 0;
  std::uint64_t samples_delivered = 0;
  std::uint64_t samples_rejected = 0;  // flagged, not delivered
  std::uint64_t queue_overruns = 0;    // the consumer fell behind: measurements dropped at a full ring
  // Measurements whose mapped time would not have come after the previous
  // one's (the clock estimate improved by more than a period, which happens
  // only just after a lock): placed 1 µs after the previous one instead.
  std::uint64_t time_clamps = 0;
  // Clock alignment.
  bool clock_locked = false;
  double clock_skew_ppm = 0.0;
  DurationNs clock_span_ns = 0;
  std::uint64_t clock_relocks = 0;
  // Receive latency above the link's floor (ClockSync::last_excess_latency_ns), over all measurement reports.
  DurationNs excess_latency_max_ns = 0;
  double excess_latency_sum_ns = 0.0;
  std::uint64_t excess_latency_count = 0;
  // The last device-info report read, if any.
  bool have_info = false;
  StretchDeviceInfo info;
};

class StretchDevice {
 public:
  // Called on the reader thread (the state callback also once on the thread
  // that calls stop()); must be quick and must not call stop().
  using SampleCallback = std::function<void(const StretchSample&)>;
  using StateCallback = std::function<void(StretchLinkState, std::string_view detail)>;

  explicit StretchDevice(std::unique_ptr<HidTransport> transport, StretchDeviceOptions options = {},
                         const Clock& clock = MonotonicClock::instance());
  ~StretchDevice();  // stop()s
  StretchDevice(const StretchDevice&) = delete;
  StretchDevice& operator=(const StretchDevice&) = delete;

  // Set before start(). With a sample callback, measurements go to it instead of the ring.
  void set_sample_callback(SampleCallback callback);
  void set_state_callback(StateCallback callback);

  // Starts the reader thread; it connects on its own (a board that is not
  // there yet is waited for). Errc::invalid_argument if already running.
  Status start();
  // Stops and joins the reader thread and closes the transport.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  StretchLinkState state() const noexcept { return state_.load(std::memory_order_acquire); }

  // Consumer thread (one): the next measurement, in arrival (and time) order.
  bool pop(StretchSample& out) { return ring_.try_pop(out); }
  // Consumer thread: the newest statistics the reader published.
  StretchDeviceStats stats();

  // Any thread: queue a command for the reader thread to send.
  void send_command(const StretchCommand& command);

 private:
  void run();
  bool connect();
  // Decodes and observes one report; its accepted measurements wait in pending_ for deliver_pending().
  void handle_report(std::span<const std::uint8_t> report, TimeNs receive_ns);
  void deliver_pending();
  void lose_link(std::string_view why);
  void set_state(StretchLinkState state, std::string_view detail);
  void send_pending_commands();
  bool wait_for_stop(DurationNs duration);  // true when stop was requested
  void publish_stats();

  std::unique_ptr<HidTransport> transport_;
  StretchDeviceOptions options_;
  const Clock& clock_;
  SampleCallback sample_callback_;
  StateCallback state_callback_;

  // Reader thread only.
  StretchStreamDecoder stream_;
  ClockSync clock_sync_;
  StretchDeviceStats stats_;
  TimeNs last_data_ns_ = 0;
  std::uint8_t next_token_ = 1;
  bool delivered_any_ = false;
  TimeNs last_time_ns_ = 0;  // newest delivered measurement time
  bool layout_warned_ = false;
  std::vector<StretchSample> pending_;  // capacity reserved once: kStretchMaxBurst reports

  SpscRing<StretchSample> ring_;
  Mailbox<StretchDeviceStats> published_;
  StretchDeviceStats consumer_stats_;  // consumer's copy of the newest published

  std::atomic<bool> running_{false};
  std::atomic<bool> stop_requested_{false};
  std::atomic<StretchLinkState> state_{StretchLinkState::stopped};
  std::mutex mutex_;  // guards pending_commands_ and the stop wait
  std::condition_variable stop_cv_;
  std::vector<StretchCommand> pending_commands_;
  std::atomic<bool> commands_pending_{false};  // lets the reader skip the lock on every report
  std::thread thread_;
};

}  // namespace proprio::devices
