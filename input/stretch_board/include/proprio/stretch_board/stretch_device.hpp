#pragma once
// StretchDevice: one stretch glove read-out board, live. A reader thread opens
// the transport, reads reports, decodes them (StretchStreamDecoder), maps
// device time to CLOCK_MONOTONIC (hid::ClockSync) and hands timestamped
// measurements to one consumer through a bounded SPSC ring (or a callback).
// When the board goes away it reports the state change, retries with
// exponential backoff and resumes when the board is back; a restarted board
// begins a new epoch and the clock re-locks. The same design as ImuGloveDevice
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
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"
#include "proprio/hid/board_link.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/command_queue.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_thread.hpp"
#include "proprio/hid/sample_outlet.hpp"

namespace proprio::devices {

// connecting, streaming, disconnected, stopped: the same for every board.
using StretchLinkState = hid::LinkState;

// Reports the reader takes in one go before it maps and delivers (the backlog
// a reconnect or a stall leaves is rarely more than a few).
inline constexpr std::size_t kStretchMaxBurst = 32;

// A stretch board's HID interface: the selector StretchDevice's callers pass
// to hid::HidapiTransport (the selector's default product ID is 0: any).
hid::HidDeviceSelector stretch_board_selector();

struct StretchDeviceOptions {
  StretchStreamOptions stream;
  hid::ClockSyncOptions clock;
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

// The link's counters and clock (hid::LinkStats) plus the board's own.
struct StretchDeviceStats : hid::LinkStats {
  StretchStreamStats stream;
  std::uint64_t restart_commands = 0;  // STARTs sent after silence
  std::uint64_t samples_delivered = 0;
  std::uint64_t samples_rejected = 0;  // flagged, not delivered
  std::uint64_t queue_overruns = 0;    // the consumer fell behind: measurements dropped at a full ring
  // Measurements whose mapped time would not have come after the previous
  // one's (the clock estimate improved by more than a period, which happens
  // only just after a lock): placed 1 µs after the previous one instead.
  std::uint64_t time_clamps = 0;
  // The last device-info report read, if any.
  bool have_info = false;
  StretchDeviceInfo info;
};

class StretchDevice final : hid::LinkHandler {
 public:
  // Called on the reader thread (the state callback also once on the thread
  // that calls stop()); must be quick and must not call stop().
  using SampleCallback = hid::SampleOutlet<StretchSample>::Callback;
  using StateCallback = hid::LinkThread::StateCallback;

  explicit StretchDevice(std::unique_ptr<hid::HidTransport> transport, StretchDeviceOptions options = {},
                         const Clock& clock = MonotonicClock::instance());
  ~StretchDevice() override;  // stop()s
  StretchDevice(const StretchDevice&) = delete;
  StretchDevice& operator=(const StretchDevice&) = delete;

  // Set before start(). With a sample callback, measurements go to it instead of the ring.
  void set_sample_callback(SampleCallback callback) { outlet_.set_callback(std::move(callback)); }
  // Set before start(). Called on the reader thread after each delivery of
  // measurements (what the reader took in one go: a report, or a backlog of
  // them), so that a consumer that works on batches acts once the whole
  // report is in rather than partway through it.
  void set_burst_callback(std::function<void()> callback) { burst_callback_ = std::move(callback); }
  void set_state_callback(StateCallback callback) { link_.set_state_callback(std::move(callback)); }

  // Starts the reader thread; it connects on its own (a board that is not
  // there yet is waited for). Errc::invalid_argument if already running.
  Status start();
  // Stops and joins the reader thread and closes the transport.
  void stop() { link_.stop(); }
  bool running() const noexcept { return link_.running(); }
  StretchLinkState state() const noexcept { return link_.state(); }

  // Consumer thread (one): the next measurement, in arrival (and time) order.
  bool pop(StretchSample& out) { return outlet_.pop(out); }
  // Consumer thread: the newest statistics the reader published.
  StretchDeviceStats stats() { return published_.newest(); }

  // Any thread: queue a command for the reader thread to send.
  void send_command(const StretchCommand& command) { commands_.push(command); }

 private:
  // hid::LinkHandler, on the reader thread.
  Result<std::string> on_open(hid::HidTransport& transport) override;
  bool before_read() override;
  // Decodes and observes one report; its accepted measurements wait in pending_ for deliver_pending().
  void on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) override;
  void end_burst(bool link_lost) override;
  void on_silence(TimeNs now_ns) override;
  void on_link_lost() override { stats_.stream = stream_.stats(); }
  void publish() override { published_.publish(stats_, clock_sync_); }
  void deliver_pending();

  StretchDeviceOptions options_;
  const Clock& clock_;

  // Reader thread only.
  StretchStreamDecoder stream_;
  hid::ClockSync clock_sync_;
  StretchDeviceStats stats_;
  hid::SilenceRestart restart_;
  hid::StrictlyIncreasing delivered_times_;
  bool layout_warned_ = false;
  std::vector<StretchSample> pending_;  // capacity reserved once: kStretchMaxBurst reports
  std::function<void()> burst_callback_;

  hid::SampleOutlet<StretchSample> outlet_;
  hid::CommandQueue<StretchCommand> commands_;
  hid::PublishedStats<StretchDeviceStats> published_;
  hid::LinkThread link_;               // last: its thread uses everything above
};

}  // namespace proprio::devices
