#pragma once
// FingertipDevice: one cutaneous fingertip haptic device, live. The design of
// StretchDevice (stretch_device.hpp) turned around: the data that matters
// flows to the device.
//
//   servo thread (1 kHz)  command(...)        lock-free, allocation-free, noexcept: the
//                                             setpoint goes into a Mailbox and the call returns
//                         latest_feedback()   lock-free: the newest feedback, in SI
//   I/O thread            opens the hid::HidTransport, reads the device-info report, reads
//                         feedback (which arrives every millisecond and paces the thread),
//                         sends each new setpoint once, maps device time to
//                         CLOCK_MONOTONIC, reconnects with backoff after an unplug and
//                         reports every state change.
//
// The I/O thread sends a setpoint at most one read later than command()
// published it: within one feedback period (1 ms) while the device streams,
// within poll_interval_ns otherwise. It never repeats a setpoint: if the servo
// loop stops, commands stop, and the device's watchdog returns it to rest.
// That is the point of the watchdog, so nothing here keeps it fed.
//
// When the device is gone, command() still returns at once, with
// not_connected, and nothing queued then is sent after a reconnect (the first
// command of each connection carries sequence_reset). Setpoints older than
// max_command_age_ns when the I/O thread gets to them are dropped, not sent.
// stop() sends a disable command if it can, so the device goes to rest at
// once instead of after its watchdog period.
//
// Nothing is global: one FingertipDevice per fingertip device (two hands of
// five fingers are ten instances, each with its own transport, selected by
// serial number or path). The protocol is docs/fingertip-hid-protocol.md.
#include <array>
#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/mailbox.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/fingertip_device/fingertip_protocol.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_thread.hpp"

namespace proprio::devices {

// stopped, connecting, streaming, disconnected: the same for every device.
using FingertipLinkState = hid::LinkState;

// A fingertip device's HID interface: what to pass to hid::HidapiTransport. With
// a serial number (or a device path) it picks one of several.
hid::HidDeviceSelector fingertip_device_selector(std::string serial = {}, std::string path = {});
// Every interface the OS lists with the fingertip VID/PID and usage page (or
// no usage page reported), for a CLI to list. Errc::io_error if hidapi cannot start.
Result<std::vector<hid::HidDeviceInfo>> enumerate_fingertip_devices(std::uint16_t vendor_id = kFingertipUsbVendorId,
                                                               std::uint16_t product_id = kFingertipUsbProductId);

struct FingertipDeviceOptions {
  // The longest one read waits, so also the longest a setpoint waits for the
  // I/O thread when no feedback arrives, and about how long stop() takes.
  DurationNs poll_interval_ns = kNsPerMillisecond;
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  // A setpoint this old when the I/O thread takes it is dropped (the servo
  // loop has moved on; the device would only render the past).
  DurationNs max_command_age_ns = 20 * kNsPerMillisecond;
  // Connected but no feedback for this long: close and reconnect (the device
  // streams feedback all the time, so silence means it hung or was reset).
  DurationNs silence_timeout_ns = kNsPerSecond;
  // Refuse to command a device assigned to another fingertip (its info report
  // says which); unset accepts any, as does a device that is unassigned.
  std::optional<Handedness> expected_hand;
  std::optional<Finger> expected_finger;
  hid::ClockSyncOptions clock;

  Status validate() const;
  std::string describe() const;
};

// What the servo loop asks for, in SI.
struct FingertipSetpoint {
  FingertipMode mode = FingertipMode::force;  // motor_angles or force
  // motor_angles: output-shaft angle of each motor, rad (0 = rest; as many as
  // the device has motors). force: normal, shear_x, shear_z in N, fingertip frame.
  std::array<double, kFingertipMaxMotors> values{};
  bool enable = true;         // false: go to rest
  bool clear_faults = false;  // ask the device to clear latched faults whose cause is gone
};

enum class FingertipCommandStatus : std::uint8_t {
  queued,         // the I/O thread will send it (unless a newer one replaces it first)
  not_connected,  // no device (yet, or any more): nothing was queued
  invalid,        // a value is not finite, or the mode is idle: nothing was queued
  refused,        // the device is assigned to another fingertip (FingertipDeviceOptions)
};
const char* to_string(FingertipCommandStatus status) noexcept;

// One feedback report, in SI.
struct FingertipFeedbackSample {
  TimeNs time_ns = 0;     // CLOCK_MONOTONIC when the device measured it (device clock mapped by hid::ClockSync)
  TimeNs receive_ns = 0;  // when the I/O thread read it
  std::uint32_t device_time_us = 0;
  std::uint16_t sequence = 0;
  std::uint16_t applied_sequence = 0;  // the command the device is applying
  TimeNs applied_host_time_ns = 0;     // when command() was called for it (0: none yet)
  std::uint16_t status = 0;            // fingertip_status bits
  FingertipMode mode = FingertipMode::idle;
  FingertipCommandResult command_result = FingertipCommandResult::none;
  std::uint8_t motor_count = 0;
  std::uint8_t fsr_count = 0;
  std::array<std::int32_t, kFingertipMaxMotors> encoder_counts{};
  std::array<double, kFingertipMaxMotors> output_angle_rad{};
  std::array<double, kFingertipMaxMotors> fsr_force_n{};
  std::array<double, kFingertipMaxMotors> current_a{};
  double ramp = 0.0;  // 0-1
  std::uint16_t rejected_commands = 0;  // by the device, since its power-up (wrapping)

  bool has(std::uint16_t status_bit) const noexcept { return (status & status_bit) != 0; }
  bool faulted() const noexcept { return has(fingertip_status::faults); }
};

// The link's counters and clock (hid::LinkStats: state, connects,
// disconnects, open_failures, reports_read, write_failures, clock_*) plus the
// device's own.
struct FingertipDeviceStats : hid::LinkStats {
  std::uint64_t info_failures = 0;   // opened, but no readable device-info report: not connected
  std::uint64_t silences = 0;        // disconnects because no feedback came for silence_timeout_ns
  FingertipLinkCounters feedback;    // decoding and sequence accounting, all connections
  std::uint64_t motor_count_mismatches = 0;  // feedback disagreeing with the info report: dropped
  std::uint64_t commands_published = 0;  // command() calls that returned queued
  std::uint64_t commands_sent = 0;
  std::uint64_t commands_too_old = 0;  // dropped by max_command_age_ns
  std::uint16_t last_sent_sequence = 0;
  // command() to the first feedback showing the device applied it, host receive time.
  DurationNs round_trip_last_ns = 0;
  DurationNs round_trip_max_ns = 0;
  double round_trip_sum_ns = 0.0;
  std::uint64_t round_trip_count = 0;
  bool have_info = false;
  FingertipDeviceInfo info;
  bool assignment_mismatch = false;  // the device is assigned elsewhere: commands refused
};

class FingertipDevice final : hid::LinkHandler {
 public:
  // Called on the I/O thread (the state callback also once on the thread that
  // calls stop()); must be quick and must not call stop().
  using StateCallback = hid::LinkThread::StateCallback;
  using FeedbackCallback = std::function<void(const FingertipFeedbackSample&)>;

  explicit FingertipDevice(std::unique_ptr<hid::HidTransport> transport, FingertipDeviceOptions options = {},
                           const Clock& clock = MonotonicClock::instance());
  ~FingertipDevice() override;  // stop()s
  FingertipDevice(const FingertipDevice&) = delete;
  FingertipDevice& operator=(const FingertipDevice&) = delete;

  // Set before start().
  void set_state_callback(StateCallback callback) { link_.set_state_callback(std::move(callback)); }
  // Every accepted feedback report, in order (for logging); latest_feedback() works either way.
  void set_feedback_callback(FeedbackCallback callback);

  // Starts the I/O thread; it connects on its own (a device that is not there
  // yet is waited for). Errc::invalid_argument if already running or the options are bad.
  Status start();
  // Sends a disable command if connected, stops and joins the I/O thread, closes the transport.
  void stop() { link_.stop(); }
  bool running() const noexcept { return link_.running(); }
  FingertipLinkState state() const noexcept { return link_.state(); }
  // Motors of the connected device (0 until the first info report).
  std::uint8_t motor_count() const noexcept { return motor_count_.load(std::memory_order_acquire); }

  // Servo thread (one thread at a time): lock-free, allocation-free, returns at once.
  FingertipCommandStatus command(const FingertipSetpoint& setpoint) noexcept;
  FingertipCommandStatus command_force(double normal_n, double shear_x_n, double shear_z_n) noexcept;
  FingertipCommandStatus command_angles(const std::array<double, kFingertipMaxMotors>& output_angle_rad) noexcept;
  FingertipCommandStatus disable() noexcept;
  // Servo thread (one consumer): the newest feedback; false before the first.
  // After a disconnect it is the last sample of the old connection until new
  // ones arrive: check state() or receive_ns before trusting it.
  bool latest_feedback(FingertipFeedbackSample& out) noexcept;
  // The same, but true only when a newer report arrived since the last call.
  bool fresh_feedback(FingertipFeedbackSample& out) noexcept;

  // One other thread (a UI, a test): the newest statistics the I/O thread published.
  FingertipDeviceStats stats();

 private:
  struct PendingCommand {
    FingertipSetpoint setpoint;
    TimeNs host_time_ns = 0;
  };
  static constexpr std::size_t kMaxBurst = 32;  // reports taken in one go before mapping times

  // hid::LinkHandler, on the I/O thread.
  Result<std::string> on_open(hid::HidTransport& transport) override;
  bool before_read() override;
  void on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) override;
  void end_burst(bool link_lost) override;
  void on_silence(TimeNs now_ns) override;
  void on_link_lost() override { pending_count_ = 0; }
  void on_exit() override;
  void publish() override;

  void deliver_pending();
  void send_pending_command();
  void send_disable();
  bool write_command(const FingertipCommand& command);

  FingertipDeviceOptions options_;
  const Clock& clock_;
  FeedbackCallback feedback_callback_;

  // I/O thread only.
  FingertipFeedbackStream feedback_stream_;
  hid::ClockSync clock_sync_;
  FingertipDeviceStats stats_;
  FingertipDeviceInfo info_;
  bool have_info_ = false;
  TimeNs last_feedback_ns_ = 0;
  std::uint16_t next_sequence_ = 1;
  bool first_command_ = true;  // of this connection: carries sequence_reset
  bool have_applied_ = false;
  std::uint16_t last_applied_sequence_ = 0;
  std::array<FingertipFeedbackSample, kMaxBurst> pending_{};
  std::size_t pending_count_ = 0;

  // Servo thread -> I/O thread, and back.
  Mailbox<PendingCommand> commands_;
  Mailbox<FingertipFeedbackSample> feedback_;
  std::atomic<std::uint64_t> commands_published_{0};
  std::atomic<std::uint8_t> motor_count_{0};
  std::atomic<bool> refused_{false};
  Mailbox<FingertipDeviceStats> published_stats_;
  FingertipDeviceStats consumer_stats_;
  hid::LinkThread link_;  // last: its thread uses everything above
};

}  // namespace proprio::devices
