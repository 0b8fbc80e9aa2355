#include "proprio/devices/stretch_device.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <string>

#include "proprio/core/log.hpp"

namespace proprio::devices {

HidDeviceSelector stretch_board_selector() {
  HidDeviceSelector sel;
  sel.vendor_id = kStretchUsbVendorId;
  sel.product_id = kStretchUsbProductId;
  sel.usage_page = kStretchHidUsagePage;
  return sel;
}

StretchDevice::StretchDevice(std::unique_ptr<HidTransport> transport, StretchDeviceOptions options,
                             const Clock& clock)
    : transport_(std::move(transport)),
      options_(options),
      clock_(clock),
      stream_(options_.stream),
      clock_sync_(options_.clock),
      ring_(options_.queue_capacity) {
  pending_.reserve(kStretchMaxBurst * kStretchMeasurementsPerReport);
}

StretchDevice::~StretchDevice() { stop(); }

void StretchDevice::set_sample_callback(SampleCallback callback) { sample_callback_ = std::move(callback); }
void StretchDevice::set_state_callback(StateCallback callback) { state_callback_ = std::move(callback); }

Status StretchDevice::start() {
  if (running()) {
    return make_error(Errc::invalid_argument, "StretchDevice::start: the reader thread is already running");
  }
  if (!transport_) return make_error(Errc::invalid_argument, "StretchDevice::start: no transport");
  stop_requested_.store(false, std::memory_order_release);
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
  return {};
}

void StretchDevice::stop() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(mutex_);
    stop_requested_.store(true, std::memory_order_release);
  }
  stop_cv_.notify_all();
  thread_.join();
  transport_->close();
  set_state(StretchLinkState::stopped, "stopped");
  running_.store(false, std::memory_order_release);
}

StretchDeviceStats StretchDevice::stats() {
  if (const StretchDeviceStats* newest = published_.read()) consumer_stats_ = *newest;
  return consumer_stats_;
}

void StretchDevice::send_command(const StretchCommand& command) {
  std::lock_guard lock(mutex_);
  pending_commands_.push_back(command);
  commands_pending_.store(true, std::memory_order_release);
}

void StretchDevice::set_state(StretchLinkState state, std::string_view detail) {
  if (state_.exchange(state, std::memory_order_acq_rel) == state) return;
  stats_.state = state;
  publish_stats();
  if (state_callback_) state_callback_(state, detail);
}

bool StretchDevice::wait_for_stop(DurationNs duration) {
  std::unique_lock lock(mutex_);
  return stop_cv_.wait_for(lock, std::chrono::nanoseconds(duration),
                           [this] { return stop_requested_.load(std::memory_order_acquire); });
}

void StretchDevice::publish_stats() {
  stats_.clock_locked = clock_sync_.locked();
  stats_.clock_skew_ppm = clock_sync_.skew_ppm();
  stats_.clock_span_ns = clock_sync_.span_ns();
  stats_.clock_relocks = clock_sync_.stats().relocks;
  published_.publish(stats_);
}

void StretchDevice::send_pending_commands() {
  if (!commands_pending_.load(std::memory_order_acquire)) return;
  std::vector<StretchCommand> commands;
  {
    std::lock_guard lock(mutex_);
    commands.swap(pending_commands_);
    commands_pending_.store(false, std::memory_order_relaxed);
  }
  for (const StretchCommand& c : commands) {
    if (auto s = transport_->write(encode_stretch_command(c)); !s) {
      ++stats_.write_failures;
      logger().warn("stretch board: sending command {} failed: {}", static_cast<int>(c.op), s.error().message);
    }
  }
}

bool StretchDevice::connect() {
  if (state_.load(std::memory_order_acquire) == StretchLinkState::stopped) {
    set_state(StretchLinkState::connecting, transport_->describe());
  }
  if (auto s = transport_->open(); !s) {
    ++stats_.open_failures;
    set_state(StretchLinkState::disconnected, s.error().message);
    return false;
  }
  ++stats_.connects;
  layout_warned_ = false;
  last_data_ns_ = clock_.now_ns();
  std::string detail = transport_->describe();
  if (options_.query_info) {
    std::array<std::uint8_t, kStretchInfoReportSize> buf{};
    auto n = transport_->get_feature(static_cast<std::uint8_t>(StretchReportId::device_info), buf);
    if (n) {
      auto info = decode_stretch_info_report(std::span<const std::uint8_t>(buf).first(std::min(*n, buf.size())));
      if (info) {
        stats_.have_info = true;
        stats_.info = *info;
        char text[200];
        std::snprintf(text, sizeof text, ": firmware %u.%u.%u, %u x %u strips (%zu combinations) at %u/s, full scale %.1f pF%s",
                      info->firmware[0], info->firmware[1], info->firmware[2], info->top_strips, info->bottom_strips,
                      info->combination_count(), info->rate_hz, stretch_count_to_pf(info->full_scale_ff),
                      info->streaming ? "" : ", not streaming");
        detail += text;
        const StretchStreamOptions& so = options_.stream;
        if ((so.expected_top_strips && info->top_strips != so.expected_top_strips) ||
            (so.expected_bottom_strips && info->bottom_strips != so.expected_bottom_strips)) {
          std::snprintf(text, sizeof text, "; WRONG LAYOUT: the layout expects %u x %u strips, so its "
                        "measurements will be refused", so.expected_top_strips, so.expected_bottom_strips);
          detail += text;
        }
      } else {
        logger().warn("stretch board: device info report unreadable: {}", info.error().message);
      }
    } else {
      logger().debug("stretch board: no device info report: {}", n.error().message);
    }
  }
  set_state(StretchLinkState::streaming, detail);
  return true;
}

void StretchDevice::run() {
  DurationNs backoff = options_.reconnect_backoff_min_ns;
  std::array<std::uint8_t, 256> buf{};  // larger than any report, so a foreign one shows as bad_length
  while (!stop_requested_.load(std::memory_order_acquire)) {
    if (!transport_->is_open()) {
      if (!connect()) {
        publish_stats();
        if (wait_for_stop(backoff)) break;
        backoff = std::min(backoff * 2, options_.reconnect_backoff_max_ns);
        continue;
      }
      backoff = options_.reconnect_backoff_min_ns;
    }
    send_pending_commands();
    auto n = transport_->read(buf, options_.read_timeout_ns);
    if (!n) {
      lose_link(n.error().message);
      continue;  // the first reconnect attempt is immediate; later ones back off
    }
    const TimeNs now = clock_.now_ns();
    if (*n == 0) {
      if (options_.restart_after_silence_ns > 0 && now - last_data_ns_ >= options_.restart_after_silence_ns) {
        StretchCommand start;
        start.op = StretchCommandOp::start_streaming;
        start.token = next_token_++;
        if (auto s = transport_->write(encode_stretch_command(start)); !s) {
          ++stats_.write_failures;
        } else {
          ++stats_.restart_commands;
        }
        last_data_ns_ = now;  // give the board another silence period before asking again
      }
      publish_stats();
      continue;
    }
    ++stats_.reports_read;
    handle_report(std::span<const std::uint8_t>(buf).first(*n), now);
    // Whatever else is already waiting belongs to the same backlog: observe it before mapping any of it.
    bool lost = false;
    for (std::size_t k = 1; k < kStretchMaxBurst; ++k) {
      auto more = transport_->read(buf, 0);
      if (!more) {
        deliver_pending();
        lose_link(more.error().message);
        lost = true;
        break;
      }
      if (*more == 0) break;
      ++stats_.reports_read;
      handle_report(std::span<const std::uint8_t>(buf).first(*more), clock_.now_ns());
    }
    if (lost) continue;
    deliver_pending();
    stats_.stream = stream_.stats();
    publish_stats();
  }
}

void StretchDevice::lose_link(std::string_view why) {
  ++stats_.disconnects;
  transport_->close();
  stats_.stream = stream_.stats();
  set_state(StretchLinkState::disconnected, why);
  publish_stats();
}

void StretchDevice::handle_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  std::array<StretchSample, kStretchMeasurementsPerReport> samples;
  const StretchPushResult r = stream_.push(report, samples, receive_ns);
  const bool data = r.verdict == StretchReportVerdict::accepted || r.verdict == StretchReportVerdict::duplicate ||
                    r.verdict == StretchReportVerdict::late;
  if (r.verdict == StretchReportVerdict::wrong_layout && !layout_warned_) {
    layout_warned_ = true;
    const StretchStreamStats& s = stream_.stats();
    logger().error("stretch board: the board measures {} x {} strips but the layout expects {} x {}: a different "
                   "glove is plugged in, or the layout file is not this glove's; its measurements are refused",
                   s.top_strips, s.bottom_strips, options_.stream.expected_top_strips,
                   options_.stream.expected_bottom_strips);
  }
  if (data) {
    last_data_ns_ = receive_ns;
    if (r.device_reset) {
      deliver_pending();  // on the old epoch's clock, before it is forgotten
      clock_sync_.reset();
    }
    // Duplicates and late reports are observations too: they arrived later
    // than their twin would have, so they sit above the envelope and cannot pull it.
    const ClockSyncEvent event =
        clock_sync_.observe(static_cast<std::uint32_t>(r.last_device_time_us), receive_ns);
    if (event == ClockSyncEvent::tracked) {
      const DurationNs excess = clock_sync_.last_excess_latency_ns();
      stats_.excess_latency_max_ns = std::max(stats_.excess_latency_max_ns, excess);
      stats_.excess_latency_sum_ns += static_cast<double>(excess);
      ++stats_.excess_latency_count;
    }
  }
  if (r.verdict == StretchReportVerdict::accepted) {
    for (std::size_t i = 0; i < r.sample_count && pending_.size() < pending_.capacity(); ++i) {
      pending_.push_back(samples[i]);
    }
  }
}

void StretchDevice::deliver_pending() {
  for (StretchSample& s : pending_) {
    // The unwrapped device time equals the wire's counter modulo 2^32, which is what ClockSync unwraps.
    TimeNs t = clock_sync_.to_host_ns(static_cast<std::uint32_t>(s.device_time_us));
    if (delivered_any_ && t <= last_time_ns_) {
      t = last_time_ns_ + 1000;
      ++stats_.time_clamps;
    }
    delivered_any_ = true;
    last_time_ns_ = t;
    s.time_ns = t;
    if (s.status != StretchMeasurementStatus::ok && !options_.deliver_flagged) {
      ++stats_.samples_rejected;
      continue;
    }
    if (sample_callback_) {
      sample_callback_(s);
    } else if (!ring_.try_push(s)) {
      ++stats_.queue_overruns;
      continue;
    }
    ++stats_.samples_delivered;
  }
  pending_.clear();
}

}  // namespace proprio::devices
