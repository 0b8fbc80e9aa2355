#include "proprio/imu_glove_board/imu_glove_device.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>

#include "proprio/core/log.hpp"
#include "proprio/hid/info_report.hpp"

namespace proprio::devices {

namespace {

hid::LinkThreadOptions link_options(const ImuGloveDeviceOptions& o) {
  hid::LinkThreadOptions l;
  l.read_timeout_ns = o.read_timeout_ns;
  l.reconnect_backoff_min_ns = o.reconnect_backoff_min_ns;
  l.reconnect_backoff_max_ns = o.reconnect_backoff_max_ns;
  l.max_burst = 1;  // each tick is mapped and delivered as it arrives
  return l;
}

}  // namespace

ImuGloveDevice::ImuGloveDevice(std::unique_ptr<hid::HidTransport> transport, ImuGloveDeviceOptions options, const Clock& clock)
    : options_(options),
      clock_(clock),
      stream_(options_.stream),
      clock_sync_(options_.clock),
      outlet_(options_.queue_capacity),
      link_(std::move(transport), link_options(options_), clock, *this, stats_) {}

ImuGloveDevice::~ImuGloveDevice() { stop(); }

Status ImuGloveDevice::start() {
  if (running()) return make_error(Errc::invalid_argument, "ImuGloveDevice::start: the reader thread is already running");
  if (!link_.has_transport()) return make_error(Errc::invalid_argument, "ImuGloveDevice::start: no transport");
  link_.start();
  return {};
}

ImuGloveDeviceStats ImuGloveDevice::stats() {
  if (const ImuGloveDeviceStats* newest = published_.read()) consumer_stats_ = *newest;
  return consumer_stats_;
}

void ImuGloveDevice::publish() {
  stats_.record_clock(clock_sync_);
  published_.publish(stats_);
}

bool ImuGloveDevice::before_read() {
  for (const ImuGloveCommand& c : commands_.take()) {
    const auto bytes = encode_command(c);
    if (auto s = link_.transport().write(bytes); !s) {
      ++stats_.write_failures;
      logger().warn("glove: sending command {} failed: {}", static_cast<int>(c.op), s.error().message);
    }
  }
  return true;
}

Result<std::string> ImuGloveDevice::on_open(hid::HidTransport& transport) {
  last_data_ns_ = clock_.now_ns();
  std::string detail = transport.describe();
  if (options_.query_info) {
    const auto info = hid::query_info_report<kImuGloveInfoReportSize>(
        transport, static_cast<std::uint8_t>(ImuGloveReportId::device_info), decode_info_report, "glove");
    if (info) {
      stats_.have_info = true;
      stats_.info = *info;
      char text[160];
      std::snprintf(text, sizeof text, ": firmware %u.%u.%u, %u IMUs at %u Hz, %s, %s%s", info->firmware[0],
                    info->firmware[1], info->firmware[2], info->imu_count, info->rate_hz,
                    to_string(info->accel_range), to_string(info->gyro_range), info->streaming ? "" : ", not streaming");
      detail += text;
    }
  }
  return detail;
}

void ImuGloveDevice::on_silence(TimeNs now) {
  if (options_.restart_after_silence_ns > 0 && now - last_data_ns_ >= options_.restart_after_silence_ns) {
    ImuGloveCommand start;
    start.op = ImuGloveCommandOp::start_streaming;
    start.token = next_token_++;
    if (auto s = link_.transport().write(encode_command(start)); !s) {
      ++stats_.write_failures;
    } else {
      ++stats_.restart_commands;
    }
    last_data_ns_ = now;  // give the glove another silence period before asking again
  }
  publish();
}

void ImuGloveDevice::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  std::array<ImuGloveSample, kImuGloveImusPerReport> samples;
  const ImuGlovePushResult r = stream_.push(report, samples, receive_ns);
  const bool data = r.verdict == ImuGloveReportVerdict::accepted || r.verdict == ImuGloveReportVerdict::duplicate ||
                    r.verdict == ImuGloveReportVerdict::late;
  if (data) {
    last_data_ns_ = receive_ns;
    if (r.device_reset) clock_sync_.reset();
    // Duplicates and late reports are observations too: they arrived later
    // than their twin would have, so they sit above the envelope and cannot pull it.
    (void)stats_.observe_clock(clock_sync_, r.timestamp_us, receive_ns);
  }
  if (r.verdict == ImuGloveReportVerdict::accepted && r.sample_count > 0) {
    TimeNs t = clock_sync_.to_host_ns(r.timestamp_us);
    const std::size_t part = samples[0].imu.sensor_id / kImuGloveImusPerReport;
    if (part_delivered_[part] && t <= last_part_time_ns_[part]) {
      t = last_part_time_ns_[part] + 1000;
      ++stats_.time_clamps;
    }
    part_delivered_[part] = true;
    last_part_time_ns_[part] = t;
    for (std::size_t i = 0; i < r.sample_count; ++i) {
      ImuGloveSample& s = samples[i];
      s.time_ns = t;
      if (s.status != 0 && !options_.deliver_flagged) {
        ++stats_.samples_rejected;
        continue;
      }
      if (!outlet_.deliver(s)) {
        ++stats_.queue_overruns;
        continue;
      }
      ++stats_.samples_delivered;
    }
  }
  stats_.stream = stream_.stats();
  publish();
}

}  // namespace proprio::devices
