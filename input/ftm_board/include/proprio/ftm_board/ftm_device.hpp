#pragma once
// FtmBoardDevice: one FTM read-out board, live, on the HID kit's link thread
// (hid::LinkThread: open, reconnect with backoff, read in bursts, state
// reports). It decodes reports (FtmStreamDecoder), maps device time to
// CLOCK_MONOTONIC (hid::ClockSync) and hands timestamped samples in the
// contract's units (ftm::FtmEvent inside FtmBoardSample) to one consumer
// through a bounded SPSC ring (or a callback). A board that goes away is
// waited for and resumes; a restarted board begins a new epoch and the clock
// re-locks. The design is the stretch board's (stretch_device.hpp); what
// differs is said here.
//
// Clocks are aligned on each report's last tick (the board sends a report
// right after it); each sample then gets its own time from its device time.
// A backlog is observed whole before any of it is mapped (max_burst), and
// the samples of one burst are delivered in time order (ties: IMUs first).
// Times strictly increase per sensor; across bursts, a late bend report may
// deliver samples older than an IMU sample already delivered.
//
// Flagged samples (stale, saturated, sensor error, compass overflow) are
// delivered with their status: the tracker decides what a flag costs (a
// compass overflow spoils only the compass), so nothing is dropped here.
#include <array>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm_board/ftm_protocol.hpp"
#include "proprio/ftm_board/ftm_stream.hpp"
#include "proprio/hid/board_link.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/command_queue.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_thread.hpp"
#include "proprio/hid/sample_outlet.hpp"

namespace proprio::devices {

using FtmLinkState = hid::LinkState;

// Reports the reader takes in one go before it maps and delivers.
inline constexpr std::size_t kFtmMaxBurst = 32;

// An FTM board's HID interface, for hid::HidapiTransport.
hid::HidDeviceSelector ftm_board_selector();

struct FtmDeviceOptions {
  hid::ClockSyncOptions clock;
  DurationNs read_timeout_ns = 100 * kNsPerMillisecond;
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  // Send START when connected but silent this long (another program may have
  // stopped the board). 0: never. A streaming board is left alone.
  DurationNs restart_after_silence_ns = kNsPerSecond;
  bool query_info = true;  // read the device-info feature report after each connect
  std::size_t queue_capacity = 16384;  // samples; about 4 s at 4 x 200 + 3 x 1000 per second

  Status validate() const;
  std::string describe() const;
};

struct FtmDeviceStats : hid::LinkStats {
  FtmStreamStats stream;
  std::uint64_t restart_commands = 0;
  std::uint64_t samples_delivered = 0;
  std::uint64_t queue_overruns = 0;  // the consumer fell behind: samples dropped at a full ring
  // Samples whose mapped time would not have come after the same sensor's
  // previous one (only just after a lock): placed 1 µs after it instead.
  std::uint64_t time_clamps = 0;
  bool have_info = false;
  FtmDeviceInfo info;
};

class FtmBoardDevice final : hid::LinkHandler {
 public:
  using SampleCallback = hid::SampleOutlet<FtmBoardSample>::Callback;
  using StateCallback = hid::LinkThread::StateCallback;

  explicit FtmBoardDevice(std::unique_ptr<hid::HidTransport> transport, FtmDeviceOptions options = {},
                          const Clock& clock = MonotonicClock::instance());
  ~FtmBoardDevice() override;  // stop()s
  FtmBoardDevice(const FtmBoardDevice&) = delete;
  FtmBoardDevice& operator=(const FtmBoardDevice&) = delete;

  // Set before start(). With a sample callback, samples go to it (on the reader thread) instead of the ring.
  void set_sample_callback(SampleCallback callback) { outlet_.set_callback(std::move(callback)); }
  // Set before start(): called on the reader thread after each delivery of a burst.
  void set_burst_callback(std::function<void()> callback) { burst_callback_ = std::move(callback); }
  void set_state_callback(StateCallback callback) { link_.set_state_callback(std::move(callback)); }

  // Starts the reader thread (Errc::invalid_argument if running or without a transport).
  Status start();
  void stop() { link_.stop(); }
  bool running() const noexcept { return link_.running(); }
  FtmLinkState state() const noexcept { return link_.state(); }

  // Consumer thread (one): the next sample.
  bool pop(FtmBoardSample& out) { return outlet_.pop(out); }
  // Consumer thread: the newest statistics the reader published.
  FtmDeviceStats stats() { return published_.newest(); }
  // Any thread: queue a command for the reader thread to send.
  void send_command(const FtmCommand& command) { commands_.push(command); }

 private:
  Result<std::string> on_open(hid::HidTransport& transport) override;
  bool before_read() override;
  void on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) override;
  void end_burst(bool link_lost) override;
  void on_silence(TimeNs now_ns) override;
  void on_link_lost() override { stats_.stream = stream_.stats(); }
  void publish() override { published_.publish(stats_, clock_sync_); }
  void deliver_pending();

  FtmDeviceOptions options_;
  const Clock& clock_;

  // Reader thread only.
  FtmStreamDecoder stream_;
  hid::ClockSync clock_sync_;
  FtmDeviceStats stats_;
  hid::SilenceRestart restart_;
  // Newest delivered time per sensor: IMUs 0-3, then bend sensors 0-2.
  std::array<TimeNs, ftm::kFtmImuCount + ftm::kFtmBendCount> last_time_ns_{};
  std::vector<FtmBoardSample> pending_;  // capacity reserved once
  std::function<void()> burst_callback_;

  hid::SampleOutlet<FtmBoardSample> outlet_;
  hid::CommandQueue<FtmCommand> commands_;
  hid::PublishedStats<FtmDeviceStats> published_;
  hid::LinkThread link_;  // last: its thread uses everything above
};

// A live board as an ftm::FtmSampleFeed, for whatever consumes feeds (the
// tracker, recordings): the consumer thread's side of FtmBoardDevice::pop.
// advance(t) delivers every sample with host time <= t in time order (ties:
// IMUs, then bend sensors). A sample that arrives after a later one was
// already delivered (a bend report that came late) is dropped and counted,
// since a feed never goes back in time; a caller that lags its t a few
// milliseconds behind now (a report's length plus the link's latency) loses
// none. Not thread-safe: one consumer, as for pop().
class FtmBoardFeed final : public ftm::FtmSampleFeed {
 public:
  explicit FtmBoardFeed(FtmBoardDevice& device) : device_(device) {}
  void advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) override;
  std::uint64_t delivered() const noexcept { return delivered_; }
  std::uint64_t dropped_out_of_order() const noexcept { return dropped_; }

 private:
  FtmBoardDevice& device_;
  std::vector<ftm::FtmEvent> held_;  // popped, not yet due
  TimeNs last_ns_ = 0;
  std::uint64_t delivered_ = 0;
  std::uint64_t dropped_ = 0;
};

}  // namespace proprio::devices
