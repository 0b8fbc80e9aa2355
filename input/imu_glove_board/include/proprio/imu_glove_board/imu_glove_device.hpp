#pragma once
// ImuGloveDevice: one IMU glove, live. A reader thread (hid::LinkThread) opens the transport, reads
// reports, decodes them (ImuGloveStreamDecoder), maps device timestamps to
// CLOCK_MONOTONIC (hid::ClockSync) and hands timestamped samples to one consumer
// through a bounded SPSC ring (or a callback). When the glove goes away it
// reports the state change, retries with exponential backoff and resumes when
// the glove is back; a restarted glove begins a new epoch and the clock
// re-locks.
//
// Samples the device or the host flagged (stale, saturated, sensor error) are
// rejected and counted per IMU unless deliver_flagged is set: a filter must
// not integrate a clipped or repeated reading as if it were a measurement.
#include <array>
#include <memory>
#include <span>
#include <string>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/imu_glove_board/imu_glove_stream.hpp"
#include "proprio/hid/board_link.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/command_queue.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_thread.hpp"
#include "proprio/hid/sample_outlet.hpp"

namespace proprio::devices {

struct ImuGloveDeviceOptions {
  ImuGloveStreamOptions stream;
  hid::ClockSyncOptions clock;
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

// The link's counters and clock (hid::LinkStats: state, connects,
// disconnects, open_failures, reports_read, write_failures, clock_*,
// excess_latency_*) plus the glove's own.
struct ImuGloveDeviceStats : hid::LinkStats {
  ImuGloveStreamStats stream;
  std::uint64_t restart_commands = 0;  // STARTs sent after silence
  std::uint64_t samples_delivered = 0;
  std::uint64_t samples_rejected = 0;  // flagged, not delivered
  std::uint64_t queue_overruns = 0;    // the consumer fell behind: samples dropped at a full ring
  // Ticks whose mapped time would not have come after the previous tick's (the
  // clock estimate improved by more than a period, which happens only just
  // after a lock): their time was set 1 µs after the previous one instead, so
  // every IMU's sample times strictly increase.
  std::uint64_t time_clamps = 0;
  // The last device-info report read, if any.
  bool have_info = false;
  ImuGloveDeviceInfo info;
};

class ImuGloveDevice final : hid::LinkHandler {
 public:
  // Called on the reader thread (the state callback also once on the thread
  // that calls stop()); must be quick and must not call stop().
  using SampleCallback = hid::SampleOutlet<ImuGloveSample>::Callback;
  using StateCallback = hid::LinkThread::StateCallback;

  explicit ImuGloveDevice(std::unique_ptr<hid::HidTransport> transport, ImuGloveDeviceOptions options = {},
                       const Clock& clock = MonotonicClock::instance());
  ~ImuGloveDevice() override;  // stop()s
  ImuGloveDevice(const ImuGloveDevice&) = delete;
  ImuGloveDevice& operator=(const ImuGloveDevice&) = delete;

  // Set before start(). With a sample callback, samples go to it instead of the ring.
  void set_sample_callback(SampleCallback callback) { outlet_.set_callback(std::move(callback)); }
  void set_state_callback(StateCallback callback) { link_.set_state_callback(std::move(callback)); }

  // Starts the reader thread; it connects on its own (a glove that is not
  // there yet is waited for). Errc::invalid_argument if already running.
  Status start();
  // Stops and joins the reader thread and closes the transport.
  void stop() { link_.stop(); }
  bool running() const noexcept { return link_.running(); }
  hid::LinkState state() const noexcept { return link_.state(); }

  // Consumer thread (one): the next sample, in arrival order.
  bool pop(ImuGloveSample& out) { return outlet_.pop(out); }
  // Consumer thread: the newest statistics the reader published.
  ImuGloveDeviceStats stats() { return published_.newest(); }

  // Any thread: queue a command for the reader thread to send.
  void send_command(const ImuGloveCommand& command) { commands_.push(command); }

 private:
  // hid::LinkHandler, on the reader thread.
  Result<std::string> on_open(hid::HidTransport& transport) override;
  bool before_read() override;
  void on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) override;
  void on_silence(TimeNs now_ns) override;
  void publish() override { published_.publish(stats_, clock_sync_); }

  ImuGloveDeviceOptions options_;
  const Clock& clock_;

  // Reader thread only.
  ImuGloveStreamDecoder stream_;
  hid::ClockSync clock_sync_;
  ImuGloveDeviceStats stats_;
  hid::SilenceRestart restart_;
  std::array<hid::StrictlyIncreasing, kImuGloveMaxReportsPerTick> part_times_{};  // delivered times per part

  hid::SampleOutlet<ImuGloveSample> outlet_;
  hid::CommandQueue<ImuGloveCommand> commands_;
  hid::PublishedStats<ImuGloveDeviceStats> published_;
  hid::LinkThread link_;             // last: its thread uses everything above
};

}  // namespace proprio::devices
