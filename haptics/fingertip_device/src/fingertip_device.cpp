#include "proprio/fingertip_device/fingertip_device.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proprio/core/log.hpp"

namespace proprio::devices {

namespace {

std::string ms(DurationNs ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g ms", static_cast<double>(ns) / kNsPerMillisecond);
  return buf;
}

}  // namespace

hid::HidDeviceSelector fingertip_device_selector(std::string serial, std::string path) {
  hid::HidDeviceSelector sel;
  sel.vendor_id = kFingertipUsbVendorId;
  sel.product_id = kFingertipUsbProductId;
  sel.usage_page = kFingertipHidUsagePage;
  sel.serial = std::move(serial);
  sel.path = std::move(path);
  return sel;
}

Result<std::vector<hid::HidDeviceInfo>> enumerate_fingertip_devices(std::uint16_t vendor_id, std::uint16_t product_id) {
  auto all = hid::enumerate_hid_devices(vendor_id, product_id);
  if (!all) return all.error().with_context("listing fingertip haptic devices");
  std::vector<hid::HidDeviceInfo> out;
  for (hid::HidDeviceInfo& d : *all) {
    // Some platforms do not report usage pages (0); those interfaces may still be ours.
    if (d.usage_page == kFingertipHidUsagePage || d.usage_page == 0) out.push_back(std::move(d));
  }
  return out;
}

Status FingertipDeviceOptions::validate() const {
  auto bad = [](const char* field, DurationNs v, const char* rule) {
    return make_error(Errc::invalid_argument, std::string("FingertipDeviceOptions.") + field + " = " +
                                                  std::to_string(v) + " ns: " + rule);
  };
  if (poll_interval_ns <= 0) return bad("poll_interval_ns", poll_interval_ns, "must be positive");
  if (reconnect_backoff_min_ns <= 0 || reconnect_backoff_max_ns < reconnect_backoff_min_ns) {
    return bad("reconnect_backoff_min_ns", reconnect_backoff_min_ns, "must be positive and not above the maximum");
  }
  if (max_command_age_ns <= 0) return bad("max_command_age_ns", max_command_age_ns, "must be positive");
  if (silence_timeout_ns <= 0) return bad("silence_timeout_ns", silence_timeout_ns, "must be positive");
  return {};
}

namespace {
std::string fingertip_name(const std::optional<Handedness>& hand, const std::optional<Finger>& finger) {
  if (!hand && !finger) return "any fingertip";
  std::string s = hand ? std::string(to_string(*hand)) : std::string("either hand's");
  s += " ";
  s += finger ? to_string(*finger) : std::string_view("any finger");
  return s;
}
}  // namespace

std::string FingertipDeviceOptions::describe() const {
  return "poll " + ms(poll_interval_ns) + ", reconnect backoff " + ms(reconnect_backoff_min_ns) + " to " +
         ms(reconnect_backoff_max_ns) + ", max command age " + ms(max_command_age_ns) + ", silence timeout " +
         ms(silence_timeout_ns) + ", expects " + fingertip_name(expected_hand, expected_finger);
}

const char* to_string(FingertipCommandStatus status) noexcept {
  switch (status) {
    case FingertipCommandStatus::queued: return "queued";
    case FingertipCommandStatus::not_connected: return "not_connected";
    case FingertipCommandStatus::invalid: return "invalid";
    case FingertipCommandStatus::refused: return "refused";
  }
  return "unknown";
}

namespace {

hid::LinkThreadOptions link_options(const FingertipDeviceOptions& o, std::size_t max_burst) {
  hid::LinkThreadOptions l;
  l.read_timeout_ns = o.poll_interval_ns;
  l.reconnect_backoff_min_ns = o.reconnect_backoff_min_ns;
  l.reconnect_backoff_max_ns = o.reconnect_backoff_max_ns;
  l.max_burst = max_burst;
  return l;
}

}  // namespace

FingertipDevice::FingertipDevice(std::unique_ptr<hid::HidTransport> transport, FingertipDeviceOptions options,
                                 const Clock& clock)
    : options_(std::move(options)),
      clock_(clock),
      clock_sync_(options_.clock),
      link_(std::move(transport), link_options(options_, kMaxBurst), clock, *this, stats_) {}

FingertipDevice::~FingertipDevice() { stop(); }

void FingertipDevice::set_feedback_callback(FeedbackCallback callback) { feedback_callback_ = std::move(callback); }

Status FingertipDevice::start() {
  if (running()) return make_error(Errc::invalid_argument, "FingertipDevice::start: the I/O thread is already running");
  if (!link_.has_transport()) return make_error(Errc::invalid_argument, "FingertipDevice::start: no transport");
  if (auto s = options_.validate(); !s) return s;
  link_.start();
  return {};
}

FingertipCommandStatus FingertipDevice::command(const FingertipSetpoint& setpoint) noexcept {
  if (setpoint.mode != FingertipMode::motor_angles && setpoint.mode != FingertipMode::force) {
    return FingertipCommandStatus::invalid;
  }
  for (double v : setpoint.values) {
    if (!std::isfinite(v)) return FingertipCommandStatus::invalid;
  }
  if (link_.state() != FingertipLinkState::streaming) {
    return FingertipCommandStatus::not_connected;
  }
  if (refused_.load(std::memory_order_acquire)) return FingertipCommandStatus::refused;
  PendingCommand p;
  p.setpoint = setpoint;
  p.host_time_ns = clock_.now_ns();
  commands_.publish(p);
  commands_published_.fetch_add(1, std::memory_order_relaxed);
  return FingertipCommandStatus::queued;
}

FingertipCommandStatus FingertipDevice::command_force(double normal_n, double shear_x_n, double shear_z_n) noexcept {
  FingertipSetpoint s;
  s.mode = FingertipMode::force;
  s.values = {normal_n, shear_x_n, shear_z_n};
  return command(s);
}

FingertipCommandStatus FingertipDevice::command_angles(
    const std::array<double, kFingertipMaxMotors>& output_angle_rad) noexcept {
  FingertipSetpoint s;
  s.mode = FingertipMode::motor_angles;
  s.values = output_angle_rad;
  return command(s);
}

FingertipCommandStatus FingertipDevice::disable() noexcept {
  FingertipSetpoint s;
  s.enable = false;
  return command(s);
}

bool FingertipDevice::latest_feedback(FingertipFeedbackSample& out) noexcept {
  const FingertipFeedbackSample* newest = feedback_.read();
  if (!newest) return false;
  out = *newest;
  return true;
}

bool FingertipDevice::fresh_feedback(FingertipFeedbackSample& out) noexcept { return feedback_.fetch(out); }

FingertipDeviceStats FingertipDevice::stats() {
  if (const FingertipDeviceStats* newest = published_stats_.read()) consumer_stats_ = *newest;
  return consumer_stats_;
}

void FingertipDevice::publish() {
  stats_.feedback = feedback_stream_.counters();
  stats_.commands_published = commands_published_.load(std::memory_order_relaxed);
  stats_.record_clock(clock_sync_);
  stats_.have_info = have_info_;
  stats_.info = info_;
  stats_.assignment_mismatch = refused_.load(std::memory_order_relaxed);
  published_stats_.publish(stats_);
}

Result<std::string> FingertipDevice::on_open(hid::HidTransport& transport) {
  // Without the info report the host cannot turn encoder counts into angles,
  // nor know how many values a motor command needs: no info, no connection.
  std::array<std::uint8_t, kFingertipReportSize> buf{};
  auto n = transport.get_feature(static_cast<std::uint8_t>(FingertipReportId::device_info), buf);
  std::string problem;
  FingertipDeviceInfo info;
  if (!n) {
    problem = n.error().message;
  } else if (auto s = decode_fingertip_info(std::span<const std::uint8_t>(buf).first(std::min(*n, buf.size())), info);
             !s) {
    problem = describe(s);
  }
  if (!problem.empty()) {
    ++stats_.info_failures;
    transport.close();
    return make_error(Errc::unavailable,
                      transport.describe() + " opened, but its device-info report (feature 0x42) is unusable: " +
                          problem + ". Is it a fingertip device whose firmware speaks protocol 1.x? Retrying.");
  }
  info_ = info;
  have_info_ = true;
  std::string detail = transport.describe() + ": " + describe(info);
  const bool wrong_hand = options_.expected_hand && info.hand && *info.hand != *options_.expected_hand;
  const bool wrong_finger = options_.expected_finger && info.finger && *info.finger != *options_.expected_finger;
  refused_.store(wrong_hand || wrong_finger, std::memory_order_release);
  if (wrong_hand || wrong_finger) {
    detail += "; WRONG FINGERTIP: the device is assigned to the " + fingertip_name(info.hand, info.finger) +
              " but this driver drives the " + fingertip_name(options_.expected_hand, options_.expected_finger) +
              ", so it refuses to command it (put the device on its own fingertip, or change the assignment)";
    logger().error("fingertip device: {}", detail);
  }
  motor_count_.store(info.motor_count, std::memory_order_release);
  feedback_stream_.reset();
  clock_sync_.reset();
  have_applied_ = false;
  first_command_ = true;
  last_feedback_ns_ = clock_.now_ns();
  // A setpoint published before this connection is not for it.
  PendingCommand discard;
  (void)commands_.fetch(discard);
  return detail;
}

bool FingertipDevice::before_read() {
  send_pending_command();
  return link_.transport().is_open();  // false: the write lost the link
}

void FingertipDevice::on_silence(TimeNs now) {
  if (now - last_feedback_ns_ >= options_.silence_timeout_ns) {
    ++stats_.silences;
    link_.lose_link("no feedback for " + ms(now - last_feedback_ns_) + ": the device hung or was reset; reconnecting");
  } else {
    publish();
  }
}

void FingertipDevice::end_burst(bool link_lost) {
  deliver_pending();
  if (link_lost) return;
  send_pending_command();
  publish();
}

void FingertipDevice::on_exit() {
  if (link_.transport().is_open()) send_disable();
}

void FingertipDevice::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  FingertipFeedback f;
  const FingertipStreamResult r = feedback_stream_.push(report, f);
  if (!r.decode) {
    if (r.decode.code != FingertipDecodeErrc::crc_mismatch) {
      logger().debug("fingertip device: report dropped: {}", describe(r.decode));
    }
    return;
  }
  if (!r.accepted()) return;
  if (f.motor_count != info_.motor_count || f.fsr_count != info_.fsr_count) {
    ++stats_.motor_count_mismatches;
    return;
  }
  last_feedback_ns_ = receive_ns;
  if (r.sequence.verdict == FingertipSequenceVerdict::restart) {
    deliver_pending();  // on the old clock, before it is forgotten
    clock_sync_.reset();
  }
  // The device sends a report right after the control tick it describes.
  (void)stats_.observe_clock(clock_sync_, f.device_time_us, receive_ns);
  if (f.applied_host_time_ns != 0 && (!have_applied_ || f.applied_sequence != last_applied_sequence_)) {
    have_applied_ = true;
    last_applied_sequence_ = f.applied_sequence;
    const DurationNs rt = receive_ns - f.applied_host_time_ns;
    stats_.round_trip_last_ns = rt;
    stats_.round_trip_max_ns = std::max(stats_.round_trip_max_ns, rt);
    stats_.round_trip_sum_ns += static_cast<double>(rt);
    ++stats_.round_trip_count;
  }
  if (pending_count_ == pending_.size()) return;  // a burst larger than kMaxBurst keeps its oldest
  FingertipFeedbackSample& s = pending_[pending_count_++];
  s.receive_ns = receive_ns;
  s.device_time_us = f.device_time_us;
  s.sequence = f.sequence;
  s.applied_sequence = f.applied_sequence;
  s.applied_host_time_ns = f.applied_host_time_ns;
  s.status = f.status;
  s.mode = f.mode;
  s.command_result = f.command_result;
  s.motor_count = f.motor_count;
  s.fsr_count = f.fsr_count;
  for (std::size_t i = 0; i < kFingertipMaxMotors; ++i) {
    s.encoder_counts[i] = f.encoder_counts[i];
    s.output_angle_rad[i] = info_.output_angle_rad(f.encoder_counts[i]);
    s.fsr_force_n[i] = f.fsr_force_mn[i] / kFingertipMnPerN;
    s.current_a[i] = f.current_ma[i] / kFingertipMaPerA;
  }
  s.ramp = f.ramp_permille / 1000.0;
  s.rejected_commands = f.rejected_commands;
}

void FingertipDevice::deliver_pending() {
  for (std::size_t i = 0; i < pending_count_; ++i) {
    FingertipFeedbackSample& s = pending_[i];
    s.time_ns = clock_sync_.to_host_ns(s.device_time_us);
    if (feedback_callback_) feedback_callback_(s);
  }
  if (pending_count_ > 0) feedback_.publish(pending_[pending_count_ - 1]);
  pending_count_ = 0;
}

bool FingertipDevice::write_command(const FingertipCommand& command) {
  if (auto s = link_.transport().write(encode_fingertip_command(command)); !s) {
    ++stats_.write_failures;
    logger().debug("fingertip device: sending command {} failed: {}", command.sequence, s.error().message);
    // A transport that closed itself on the failure (the device is gone) is a
    // lost link like a failed read: counted, reported, reconnected.
    if (!link_.transport().is_open() && !link_.stop_requested()) {
      link_.lose_link("sending a command failed: " + s.error().message);
    }
    return false;
  }
  ++stats_.commands_sent;
  stats_.last_sent_sequence = command.sequence;
  first_command_ = false;
  return true;
}

void FingertipDevice::send_pending_command() {
  PendingCommand p;
  if (!commands_.fetch(p)) return;
  if (refused_.load(std::memory_order_acquire)) return;
  if (clock_.now_ns() - p.host_time_ns > options_.max_command_age_ns) {
    ++stats_.commands_too_old;
    return;
  }
  FingertipCommand c;
  c.sequence = next_sequence_++;
  c.mode = p.setpoint.mode;
  c.flags = static_cast<std::uint8_t>((p.setpoint.enable ? fingertip_command_flags::enable : 0) |
                                      (p.setpoint.clear_faults ? fingertip_command_flags::clear_faults : 0) |
                                      (first_command_ ? fingertip_command_flags::sequence_reset : 0));
  const bool angles = c.mode == FingertipMode::motor_angles;
  c.count = angles ? std::max<std::uint8_t>(info_.motor_count, 1) : static_cast<std::uint8_t>(kFingertipMaxMotors);
  // command() let only finite values through.
  (void)set_fingertip_command_values(c, p.setpoint.values);
  c.host_time_ns = p.host_time_ns;
  (void)write_command(c);
}

void FingertipDevice::send_disable() {
  FingertipCommand c;
  c.sequence = next_sequence_++;
  c.mode = FingertipMode::force;
  c.flags = first_command_ ? fingertip_command_flags::sequence_reset : 0;
  c.count = static_cast<std::uint8_t>(kFingertipMaxMotors);
  c.host_time_ns = clock_.now_ns();
  (void)write_command(c);
}

}  // namespace proprio::devices
