#pragma once
// RigBusDevice: the rig device's base on USB, live, on the HID kit's link
// thread (hid::LinkThread: open, reconnect with backoff, read in bursts,
// state reports). Its LinkHandler decodes the base's reports into a
// RigBusHost (the same decoder and topology tracker the benchmark runs) and
// publishes a BusSnapshot after bursts (at most every snapshot_interval_ns)
// and after every read timeout; the CLI
// and the live pipeline poll snapshot() without blocking. A lost USB link
// publishes nothing new until the base is back; a silent bus detaches its
// components after 2 s as the tracker says.
//
// Times are host receive times (CLOCK_MONOTONIC through the Clock given):
// the components' own clocks are only used to order their messages.
#include <functional>
#include <memory>
#include <span>
#include <string>

#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/board_link.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_thread.hpp"
#include "proprio/rig_bus/bus_host.hpp"

namespace proprio::rig_bus {

inline constexpr std::size_t kRigBusMaxBurst = 32;

// The base's HID interface, for hid::HidapiTransport.
hid::HidDeviceSelector rig_bus_selector();

struct RigBusDeviceOptions {
  BusTrackerOptions tracker;
  DurationNs read_timeout_ns = 100 * kNsPerMillisecond;
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  // Snapshots are published after a burst at most this often (the base may
  // send 1000 reports/s; a consumer polls at a frame rate), and after every
  // read timeout and state change.
  DurationNs snapshot_interval_ns = 10 * kNsPerMillisecond;

  Status validate() const;
  std::string describe() const;
};

struct RigBusDeviceStats : hid::LinkStats {
  RigBusHostStats host;
  std::uint64_t snapshots_published = 0;
};

class RigBusDevice final : hid::LinkHandler {
 public:
  using StateCallback = hid::LinkThread::StateCallback;
  // Called on the link thread with each published snapshot (keep it quick).
  using SnapshotCallback = std::function<void(const BusSnapshot&)>;

  explicit RigBusDevice(std::unique_ptr<hid::HidTransport> transport, RigBusDeviceOptions options = {},
                        const Clock& clock = MonotonicClock::instance());
  ~RigBusDevice() override;  // stop()s
  RigBusDevice(const RigBusDevice&) = delete;
  RigBusDevice& operator=(const RigBusDevice&) = delete;

  // Set before start().
  void set_state_callback(StateCallback callback) { link_.set_state_callback(std::move(callback)); }
  void set_snapshot_callback(SnapshotCallback callback) { snapshot_callback_ = std::move(callback); }

  // Starts the reader thread (Errc::invalid_argument if running, without a
  // transport, or with bad options).
  Status start();
  void stop() { link_.stop(); }
  bool running() const noexcept { return link_.running(); }
  hid::LinkState state() const noexcept { return link_.state(); }

  // Consumer thread (one): the newest snapshot (empty before the first).
  // Never blocks.
  BusSnapshot snapshot();
  // Consumer thread (one, may be another than snapshot()'s): the newest statistics.
  RigBusDeviceStats stats() { return published_.newest(); }

 private:
  Result<std::string> on_open(hid::HidTransport& transport) override;
  void on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) override;
  void end_burst(bool link_lost) override;
  void on_silence(TimeNs now_ns) override;
  void publish() override;

  RigBusDeviceOptions options_;
  const Clock& clock_;

  // Link thread only.
  RigBusHost host_;
  RigBusDeviceStats stats_;
  hid::ClockSync unused_clock_;  // the stats' clock fields stay empty: no device clock is aligned
  SnapshotCallback snapshot_callback_;
  TimeNs last_publish_ns_ = 0;

  Mailbox<BusSnapshot> snapshots_;
  BusSnapshot snapshot_copy_;
  hid::PublishedStats<RigBusDeviceStats> published_;
  hid::LinkThread link_;  // last: its thread uses everything above
};

}  // namespace proprio::rig_bus
