#pragma once
// GloveDevice: one IMU glove, live. A reader thread opens the transport, reads
// reports, decodes them (GloveStreamDecoder), maps device timestamps to
// CLOCK_MONOTONIC (ClockSync) and hands timestamped samples to one consumer
// through a bounded SPSC ring (or a callback). When the glove goes away it
// reports the state change, retries with exponential backoff and resumes when
// the glove is back; a restarted glove begins a new epoch and the clock
// re-locks.
//
// Samples the device or the host flagged (stale, saturated, sensor error) are
// rejected and counted per IMU unless deliver_flagged is set: a filter must
// not integrate a clipped or repeated reading as if it were a measurement.
#include <array>
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
#include "proprio/devices/glove_protocol.hpp"
#include "proprio/devices/glove_stream.hpp"
#include "proprio/devices/hid_transport.hpp"
#include "proprio/devices/spsc_ring.hpp"

namespace proprio::devices {

enum class GloveLinkState : std::uint8_t {
  stopped,       // start() not called, or stop()ped
  connecting,    // trying to open the transport
  streaming,     // open and reading
  disconnected,  // lost or not found; retrying after a backoff
};
const char* to_string(GloveLinkState state) noexcept;

struct GloveDeviceOptions {
  GloveStreamOptions stream;
  ClockSyncOptions clock;
  // How long one read waits; also bounds how long stop() takes.
  DurationNs read_timeout_ns = 100 * kNsPerMillisecond;
  // Reconnect attempts back off from min to max, doubling.
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  // Send START when connected but silent this long (another program may have
  // stopped the glove). 0: never. START restarts the stream, so it is not sent
  // on every connect: a streaming glove is left alone.
  DurationNs restart_after_silence_ns = kNsPerSecond;
  // Read the device-info feature report after each connect (firmware, rate, ranges).
  bool query_info = true;
  // Deliver flagged samples too (with their status bits) instead of rejecting them.
  bool deliver_flagged = false;
  std::size_t queue_capacity = 4096;  // samples; about 5 s of a 7-IMU glove at 100 Hz
};

struct GloveDeviceStats {
  GloveLinkState state = GloveLinkState::stopped;
  GloveStreamStats stream;
  std::uint64_t connects = 0;
  std::uint64_t disconnects = 0;    // a connected glove lost (read failed)
  std::uint64_t open_failures = 0;
  std::uint64_t reports_read = 0;
  std::uint64_t restart_commands = 0;  // STARTs sent after silence
  std::uint64_t write_failures = 0;
  std::uint64_t samples_delivered = 0;
  std::uint64_t samples_rejected = 0;  // flagged, not delivered
  std::uint64_t queue_overruns = 0;    // the consumer fell behind: samples dropped at a full ring
  // Ticks whose mapped time would not have come after the previous tick's (the
  // clock estimate improved by more than a period, which happens only just
  // after a lock): their time was set 1 µs after the previous one instead, so
  // every IMU's sample times strictly increase.
  std::uint64_t time_clamps = 0;
  // Clock alignment.
  bool clock_locked = false;
  double clock_skew_ppm = 0.0;
  DurationNs clock_span_ns = 0;
  std::uint64_t clock_relocks = 0;
  // Receive latency above the link's floor (ClockSync::last_excess_latency_ns), over all data reports.
  DurationNs excess_latency_max_ns = 0;
  double excess_latency_sum_ns = 0.0;
  std::uint64_t excess_latency_count = 0;
  // The last device-info report read, if any.
  bool have_info = false;
  GloveDeviceInfo info;
};

class GloveDevice {
 public:
  // Called on the reader thread (the state callback also once on the thread
  // that calls stop()); must be quick and must not call stop().
  using SampleCallback = std::function<void(const GloveSample&)>;
  using StateCallback = std::function<void(GloveLinkState, std::string_view detail)>;

  explicit GloveDevice(std::unique_ptr<HidTransport> transport, GloveDeviceOptions options = {},
                       const Clock& clock = MonotonicClock::instance());
  ~GloveDevice();  // stop()s
  GloveDevice(const GloveDevice&) = delete;
  GloveDevice& operator=(const GloveDevice&) = delete;

  // Set before start(). With a sample callback, samples go to it instead of the ring.
  void set_sample_callback(SampleCallback callback);
  void set_state_callback(StateCallback callback);

  // Starts the reader thread; it connects on its own (a glove that is not
  // there yet is waited for). Errc::invalid_argument if already running.
  Status start();
  // Stops and joins the reader thread and closes the transport.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  GloveLinkState state() const noexcept { return state_.load(std::memory_order_acquire); }

  // Consumer thread (one): the next sample, in arrival order.
  bool pop(GloveSample& out) { return ring_.try_pop(out); }
  // Consumer thread: the newest statistics the reader published.
  GloveDeviceStats stats();

  // Any thread: queue a command for the reader thread to send.
  void send_command(const GloveCommand& command);

 private:
  void run();
  bool connect();
  void handle_report(std::span<const std::uint8_t> report, TimeNs receive_ns);
  void set_state(GloveLinkState state, std::string_view detail);
  void send_pending_commands();
  bool wait_for_stop(DurationNs duration);  // true when stop was requested
  void publish_stats();

  std::unique_ptr<HidTransport> transport_;
  GloveDeviceOptions options_;
  const Clock& clock_;
  SampleCallback sample_callback_;
  StateCallback state_callback_;

  // Reader thread only.
  GloveStreamDecoder stream_;
  ClockSync clock_sync_;
  GloveDeviceStats stats_;
  TimeNs last_data_ns_ = 0;
  std::uint8_t next_token_ = 1;
  std::array<TimeNs, kGloveMaxReportsPerTick> last_part_time_ns_{};  // newest delivered time per part
  std::array<bool, kGloveMaxReportsPerTick> part_delivered_{};

  SpscRing<GloveSample> ring_;
  Mailbox<GloveDeviceStats> published_;
  GloveDeviceStats consumer_stats_;  // consumer's copy of the newest published

  std::atomic<bool> running_{false};
  std::atomic<bool> stop_requested_{false};
  std::atomic<GloveLinkState> state_{GloveLinkState::stopped};
  std::mutex mutex_;  // guards pending_commands_ and the stop wait
  std::condition_variable stop_cv_;
  std::vector<GloveCommand> pending_commands_;
  std::atomic<bool> commands_pending_{false};  // lets the reader skip the lock on every report
  std::thread thread_;
};

}  // namespace proprio::devices
