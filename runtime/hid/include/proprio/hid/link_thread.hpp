#pragma once
// LinkThread: the one reader/writer thread every HID driver runs (IMU glove
// board, stretch board, fingertip devices). It owns what is the same for all
// of them: open the transport (again after an unplug), back off between
// failed attempts (min to max, doubling; the first retry after a lost link is
// immediate), read a report with a timeout, take the backlog already waiting
// in one burst, report each state change once, count connects, losses and
// failed opens, and stop promptly. What a report means, which commands go out
// and what is published is the device's: it implements LinkHandler, whose
// hooks the thread calls, always on the thread itself (the state callback
// also once on the thread that calls stop()).
//
// A burst exists because a device's clock can only be mapped once every
// report of a backlog has been observed: after a stall, the first report of
// the backlog arrived late and the rest later still, and the lower-envelope
// fit (ClockSync) needs them all before it maps any of them. A handler that
// maps each report as it comes sets max_burst = 1.
#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_state.hpp"

namespace proprio::hid {

// The statistics every driver publishes; a device's stats struct derives from
// it and adds its own (decoder counters, samples, device info).
struct LinkStats {
  LinkState state = LinkState::stopped;
  std::uint64_t connects = 0;
  std::uint64_t disconnects = 0;  // a connected device lost (read or write failed, or silent)
  std::uint64_t open_failures = 0;
  std::uint64_t reports_read = 0;
  std::uint64_t write_failures = 0;
  // Clock alignment (ClockSync), filled by record_clock().
  bool clock_locked = false;
  double clock_skew_ppm = 0.0;
  DurationNs clock_span_ns = 0;
  std::uint64_t clock_relocks = 0;
  // Receive latency above the link's floor (ClockSync::last_excess_latency_ns),
  // over the reports observe_clock() saw.
  DurationNs excess_latency_max_ns = 0;
  double excess_latency_sum_ns = 0.0;
  std::uint64_t excess_latency_count = 0;

  // Copies the estimator's state into the clock fields (before publishing).
  void record_clock(const ClockSync& clock) noexcept;
  // Observes one (device time, receive time) pair and, when it tracked,
  // counts its excess latency.
  ClockSyncEvent observe_clock(ClockSync& clock, std::uint32_t device_time_us, TimeNs receive_ns) noexcept;
};

struct LinkThreadOptions {
  // How long one read waits; also bounds how long stop() takes.
  DurationNs read_timeout_ns = 100 * kNsPerMillisecond;
  // Reconnect attempts back off from min to max, doubling.
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  // Reports read in one go before end_burst() (1: end_burst after every report).
  std::size_t max_burst = 1;
};

class LinkThread;

// The device's side of the thread. Every hook runs on the link thread.
class LinkHandler {
 public:
  virtual ~LinkHandler() = default;
  // The transport just opened: read what the device says about itself and
  // return the detail the streaming state reports, or an error that keeps
  // the link closed (its message is the disconnected state's detail).
  virtual Result<std::string> on_open(HidTransport& transport) = 0;
  // Before each read: send what is queued. False skips the read (the write
  // lost the link and the handler reported it).
  virtual bool before_read() { return true; }
  // One report and the host time the thread read it.
  virtual void on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) = 0;
  // The reports of one burst are in. link_lost: a read in the burst failed;
  // the loss is reported right after this returns.
  virtual void end_burst(bool link_lost) { (void)link_lost; }
  // A read timed out with the link open.
  virtual void on_silence(TimeNs now_ns) { (void)now_ns; publish(); }
  // The link was lost (before the state change is reported).
  virtual void on_link_lost() {}
  // The thread is about to end; the transport may still be open.
  virtual void on_exit() {}
  // Publish the statistics to consumers (after every state change, burst and timeout).
  virtual void publish() = 0;
};

class LinkThread {
 public:
  using StateCallback = std::function<void(LinkState, std::string_view detail)>;

  // handler and stats must outlive the thread; stats is the handler's own
  // stats struct, whose LinkStats part the thread keeps.
  LinkThread(std::unique_ptr<HidTransport> transport, LinkThreadOptions options, const Clock& clock,
             LinkHandler& handler, LinkStats& stats);
  ~LinkThread();  // stop()s
  LinkThread(const LinkThread&) = delete;
  LinkThread& operator=(const LinkThread&) = delete;

  // Set before start().
  void set_state_callback(StateCallback callback) { state_callback_ = std::move(callback); }
  bool has_transport() const noexcept { return transport_ != nullptr; }
  // Starts the thread (the caller checked it is not running and has a transport).
  void start();
  // Stops and joins the thread, closes the transport, reports stopped.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  bool stop_requested() const noexcept { return stop_requested_.load(std::memory_order_acquire); }
  LinkState state() const noexcept { return state_.load(std::memory_order_acquire); }

  // Link thread only (from the handler's hooks).
  HidTransport& transport() noexcept { return *transport_; }
  // Counts the loss, closes the transport, reports disconnected (why) and publishes.
  void lose_link(std::string_view why);

 private:
  void run();
  bool connect();
  void set_state(LinkState state, std::string_view detail);
  bool wait_for_stop(DurationNs duration);  // true when stop was requested

  std::unique_ptr<HidTransport> transport_;
  LinkThreadOptions options_;
  const Clock& clock_;
  LinkHandler& handler_;
  LinkStats& stats_;
  StateCallback state_callback_;

  std::atomic<bool> running_{false};
  std::atomic<bool> stop_requested_{false};
  std::atomic<LinkState> state_{LinkState::stopped};
  std::mutex mutex_;  // only for the stop wait
  std::condition_variable stop_cv_;
  std::thread thread_;
};

}  // namespace proprio::hid
