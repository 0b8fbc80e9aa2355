#include "proprio/devices/glove_device.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <string>

#include "proprio/core/log.hpp"

namespace proprio::devices {

const char* to_string(GloveLinkState state) noexcept {
  switch (state) {
    case GloveLinkState::stopped: return "stopped";
    case GloveLinkState::connecting: return "connecting";
    case GloveLinkState::streaming: return "streaming";
    case GloveLinkState::disconnected: return "disconnected";
  }
  return "unknown";
}

GloveDevice::GloveDevice(std::unique_ptr<HidTransport> transport, GloveDeviceOptions options, const Clock& clock)
    : transport_(std::move(transport)),
      options_(options),
      clock_(clock),
      stream_(options_.stream),
      clock_sync_(options_.clock),
      ring_(options_.queue_capacity) {}

GloveDevice::~GloveDevice() { stop(); }

void GloveDevice::set_sample_callback(SampleCallback callback) { sample_callback_ = std::move(callback); }
void GloveDevice::set_state_callback(StateCallback callback) { state_callback_ = std::move(callback); }

Status GloveDevice::start() {
  if (running()) return make_error(Errc::invalid_argument, "GloveDevice::start: the reader thread is already running");
  if (!transport_) return make_error(Errc::invalid_argument, "GloveDevice::start: no transport");
  stop_requested_.store(false, std::memory_order_release);
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
  return {};
}

void GloveDevice::stop() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(mutex_);
    stop_requested_.store(true, std::memory_order_release);
  }
  stop_cv_.notify_all();
  thread_.join();
  transport_->close();
  set_state(GloveLinkState::stopped, "stopped");
  running_.store(false, std::memory_order_release);
}

GloveDeviceStats GloveDevice::stats() {
  if (const GloveDeviceStats* newest = published_.read()) consumer_stats_ = *newest;
  return consumer_stats_;
}

void GloveDevice::send_command(const GloveCommand& command) {
  std::lock_guard lock(mutex_);
  pending_commands_.push_back(command);
  commands_pending_.store(true, std::memory_order_release);
}

void GloveDevice::set_state(GloveLinkState state, std::string_view detail) {
  if (state_.exchange(state, std::memory_order_acq_rel) == state) return;
  stats_.state = state;
  publish_stats();
  if (state_callback_) state_callback_(state, detail);
}

bool GloveDevice::wait_for_stop(DurationNs duration) {
  std::unique_lock lock(mutex_);
  return stop_cv_.wait_for(lock, std::chrono::nanoseconds(duration),
                           [this] { return stop_requested_.load(std::memory_order_acquire); });
}

void GloveDevice::publish_stats() {
  stats_.clock_locked = clock_sync_.locked();
  stats_.clock_skew_ppm = clock_sync_.skew_ppm();
  stats_.clock_span_ns = clock_sync_.span_ns();
  stats_.clock_relocks = clock_sync_.stats().relocks;
  published_.publish(stats_);
}

void GloveDevice::send_pending_commands() {
  if (!commands_pending_.load(std::memory_order_acquire)) return;
  std::vector<GloveCommand> commands;
  {
    std::lock_guard lock(mutex_);
    commands.swap(pending_commands_);
    commands_pending_.store(false, std::memory_order_relaxed);
  }
  for (const GloveCommand& c : commands) {
    const auto bytes = encode_command(c);
    if (auto s = transport_->write(bytes); !s) {
      ++stats_.write_failures;
      logger().warn("glove: sending command {} failed: {}", static_cast<int>(c.op), s.error().message);
    }
  }
}

bool GloveDevice::connect() {
  if (state_.load(std::memory_order_acquire) == GloveLinkState::stopped) {
    set_state(GloveLinkState::connecting, transport_->describe());
  }
  if (auto s = transport_->open(); !s) {
    ++stats_.open_failures;
    set_state(GloveLinkState::disconnected, s.error().message);
    return false;
  }
  ++stats_.connects;
  last_data_ns_ = clock_.now_ns();
  std::string detail = transport_->describe();
  if (options_.query_info) {
    std::array<std::uint8_t, kGloveInfoReportSize> buf{};
    auto n = transport_->get_feature(static_cast<std::uint8_t>(GloveReportId::device_info), buf);
    if (n) {
      auto info = decode_info_report(std::span<const std::uint8_t>(buf).first(std::min(*n, buf.size())));
      if (info) {
        stats_.have_info = true;
        stats_.info = *info;
        char text[160];
        std::snprintf(text, sizeof text, ": firmware %u.%u.%u, %u IMUs at %u Hz, %s, %s%s", info->firmware[0],
                      info->firmware[1], info->firmware[2], info->imu_count, info->rate_hz,
                      to_string(info->accel_range), to_string(info->gyro_range),
                      info->streaming ? "" : ", not streaming");
        detail += text;
      } else {
        logger().warn("glove: device info report unreadable: {}", info.error().message);
      }
    } else {
      logger().debug("glove: no device info report: {}", n.error().message);
    }
  }
  set_state(GloveLinkState::streaming, detail);
  return true;
}

void GloveDevice::run() {
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
      ++stats_.disconnects;
      transport_->close();
      set_state(GloveLinkState::disconnected, n.error().message);
      publish_stats();
      continue;  // the first reconnect attempt is immediate; later ones back off
    }
    const TimeNs now = clock_.now_ns();
    if (*n == 0) {
      if (options_.restart_after_silence_ns > 0 && now - last_data_ns_ >= options_.restart_after_silence_ns) {
        GloveCommand start;
        start.op = GloveCommandOp::start_streaming;
        start.token = next_token_++;
        if (auto s = transport_->write(encode_command(start)); !s) {
          ++stats_.write_failures;
        } else {
          ++stats_.restart_commands;
        }
        last_data_ns_ = now;  // give the glove another silence period before asking again
      }
      publish_stats();
      continue;
    }
    ++stats_.reports_read;
    handle_report(std::span<const std::uint8_t>(buf).first(*n), now);
  }
}

void GloveDevice::handle_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  std::array<GloveSample, kGloveImusPerReport> samples;
  const GlovePushResult r = stream_.push(report, samples, receive_ns);
  const bool data = r.verdict == GloveReportVerdict::accepted || r.verdict == GloveReportVerdict::duplicate ||
                    r.verdict == GloveReportVerdict::late;
  if (data) {
    last_data_ns_ = receive_ns;
    if (r.device_reset) clock_sync_.reset();
    // Duplicates and late reports are observations too: they arrived later
    // than their twin would have, so they sit above the envelope and cannot pull it.
    const ClockSyncEvent event = clock_sync_.observe(r.timestamp_us, receive_ns);
    if (event == ClockSyncEvent::tracked) {
      const DurationNs excess = clock_sync_.last_excess_latency_ns();
      stats_.excess_latency_max_ns = std::max(stats_.excess_latency_max_ns, excess);
      stats_.excess_latency_sum_ns += static_cast<double>(excess);
      ++stats_.excess_latency_count;
    }
  }
  if (r.verdict == GloveReportVerdict::accepted && r.sample_count > 0) {
    TimeNs t = clock_sync_.to_host_ns(r.timestamp_us);
    const std::size_t part = samples[0].imu.sensor_id / kGloveImusPerReport;
    if (part_delivered_[part] && t <= last_part_time_ns_[part]) {
      t = last_part_time_ns_[part] + 1000;
      ++stats_.time_clamps;
    }
    part_delivered_[part] = true;
    last_part_time_ns_[part] = t;
    for (std::size_t i = 0; i < r.sample_count; ++i) {
      GloveSample& s = samples[i];
      s.time_ns = t;
      if (s.status != 0 && !options_.deliver_flagged) {
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
  }
  stats_.stream = stream_.stats();
  publish_stats();
}

}  // namespace proprio::devices
