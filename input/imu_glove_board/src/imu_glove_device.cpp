#include "proprio/imu_glove_board/imu_glove_device.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>

#include "proprio/core/log.hpp"
#include "proprio/hid/info_report.hpp"

namespace proprio::devices {

ImuGloveDevice::ImuGloveDevice(std::unique_ptr<hid::HidTransport> transport, ImuGloveDeviceOptions options, const Clock& clock)
    : options_(options),
      clock_(clock),
      stream_(options_.stream),
      clock_sync_(options_.clock),
      outlet_(options_.queue_capacity),
      link_(std::move(transport), hid::link_options_of(options_, 1), clock, *this, stats_) {}

ImuGloveDevice::~ImuGloveDevice() { stop(); }

Status ImuGloveDevice::start() {
  if (running()) return make_error(Errc::invalid_argument, "ImuGloveDevice::start: the reader thread is already running");
  if (!link_.has_transport()) return make_error(Errc::invalid_argument, "ImuGloveDevice::start: no transport");
  link_.start();
  return {};
}

bool ImuGloveDevice::before_read() {
  hid::send_queued_commands(commands_, link_.transport(), stats_, encode_command, "glove");
  return true;
}

Result<std::string> ImuGloveDevice::on_open(hid::HidTransport& transport) {
  restart_.saw_data(clock_.now_ns());
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
  restart_.on_silence<ImuGloveCommand>(now, options_.restart_after_silence_ns, link_.transport(), encode_command,
                                       stats_, stats_.restart_commands);
  publish();
}

void ImuGloveDevice::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  std::array<ImuGloveSample, kImuGloveImusPerReport> samples;
  const ImuGlovePushResult r = stream_.push(report, samples, receive_ns);
  const bool data = r.verdict == ImuGloveReportVerdict::accepted || r.verdict == ImuGloveReportVerdict::duplicate ||
                    r.verdict == ImuGloveReportVerdict::late;
  if (data) {
    restart_.saw_data(receive_ns);
    if (r.device_reset) clock_sync_.reset();
    // Duplicates and late reports are observations too: they arrived later
    // than their twin would have, so they sit above the envelope and cannot pull it.
    (void)stats_.observe_clock(clock_sync_, r.timestamp_us, receive_ns);
  }
  if (r.verdict == ImuGloveReportVerdict::accepted && r.sample_count > 0) {
    const std::size_t part = samples[0].imu.sensor_id / kImuGloveImusPerReport;
    const TimeNs t = part_times_[part].place(clock_sync_.to_host_ns(r.timestamp_us), stats_.time_clamps);
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
