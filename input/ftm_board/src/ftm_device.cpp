#include "proprio/ftm_board/ftm_device.hpp"

#include <algorithm>
#include <cstdio>
#include <string>

#include "proprio/core/log.hpp"
#include "proprio/hid/info_report.hpp"

namespace proprio::devices {

hid::HidDeviceSelector ftm_board_selector() {
  hid::HidDeviceSelector sel;
  sel.vendor_id = kFtmUsbVendorId;
  sel.product_id = kFtmUsbProductId;
  sel.usage_page = kFtmHidUsagePage;
  return sel;
}

namespace {

const char* accel_name(FtmAccelRange r) noexcept {
  switch (r) {
    case FtmAccelRange::g2: return "±2 g";
    case FtmAccelRange::g4: return "±4 g";
    case FtmAccelRange::g8: return "±8 g";
    case FtmAccelRange::g16: return "±16 g";
  }
  return "?";
}
const char* gyro_name(FtmGyroRange r) noexcept {
  switch (r) {
    case FtmGyroRange::dps250: return "±250 °/s";
    case FtmGyroRange::dps500: return "±500 °/s";
    case FtmGyroRange::dps1000: return "±1000 °/s";
    case FtmGyroRange::dps2000: return "±2000 °/s";
  }
  return "?";
}

}  // namespace

Status FtmDeviceOptions::validate() const {
  auto bad = [](const char* what) {
    return make_error(Errc::invalid_argument, std::string("FtmDeviceOptions.") + what);
  };
  if (read_timeout_ns <= 0) return bad("read_timeout_ns must be positive");
  if (reconnect_backoff_min_ns <= 0 || reconnect_backoff_max_ns < reconnect_backoff_min_ns) {
    return bad("reconnect_backoff_min_ns must be positive and at most reconnect_backoff_max_ns");
  }
  if (restart_after_silence_ns < 0) return bad("restart_after_silence_ns must be 0 (never) or positive");
  if (queue_capacity == 0) return bad("queue_capacity must be at least 1");
  return {};
}

std::string FtmDeviceOptions::describe() const {
  char text[240];
  std::snprintf(text, sizeof text,
                "read timeout %.0f ms, reconnect backoff %.0f-%.0f ms, restart after %.0f ms of silence, "
                "info query %s, queue %zu samples",
                static_cast<double>(read_timeout_ns) * 1e-6, static_cast<double>(reconnect_backoff_min_ns) * 1e-6,
                static_cast<double>(reconnect_backoff_max_ns) * 1e-6,
                static_cast<double>(restart_after_silence_ns) * 1e-6, query_info ? "on" : "off", queue_capacity);
  return text;
}

FtmBoardDevice::FtmBoardDevice(std::unique_ptr<hid::HidTransport> transport, FtmDeviceOptions options,
                               const Clock& clock)
    : options_(options),
      clock_(clock),
      clock_sync_(options_.clock),
      outlet_(options_.queue_capacity),
      link_(std::move(transport), hid::link_options_of(options_, kFtmMaxBurst), clock, *this, stats_) {
  pending_.reserve(kFtmMaxBurst * kFtmMaxSamplesPerReport);
}

FtmBoardDevice::~FtmBoardDevice() { stop(); }

Status FtmBoardDevice::start() {
  if (running()) {
    return make_error(Errc::invalid_argument, "FtmBoardDevice::start: the reader thread is already running");
  }
  if (!link_.has_transport()) return make_error(Errc::invalid_argument, "FtmBoardDevice::start: no transport");
  if (auto s = options_.validate(); !s) return s;
  link_.start();
  return {};
}

bool FtmBoardDevice::before_read() {
  hid::send_queued_commands(commands_, link_.transport(), stats_, encode_ftm_command, "FTM board");
  return true;
}

Result<std::string> FtmBoardDevice::on_open(hid::HidTransport& transport) {
  restart_.saw_data(clock_.now_ns());
  std::string detail = transport.describe();
  if (options_.query_info) {
    const auto info = hid::query_info_report<kFtmInfoReportSize>(
        transport, static_cast<std::uint8_t>(FtmReportId::device_info), decode_ftm_info_report, "FTM board");
    if (info) {
      stats_.have_info = true;
      stats_.info = *info;
      char text[220];
      std::snprintf(text, sizeof text,
                    ": firmware %u.%u.%u, IMUs at %u Hz (compass %u Hz, %s, %s), bend sensors at %u Hz, IMUs "
                    "present 0x%x, bend sensors 0x%x%s",
                    info->firmware[0], info->firmware[1], info->firmware[2], info->imu_rate_hz, info->mag_rate_hz,
                    accel_name(info->accel_range), gyro_name(info->gyro_range), info->bend_rate_hz,
                    info->imus_present, info->bends_present, info->streaming ? "" : ", not streaming");
      detail += text;
    }
  }
  return detail;
}

void FtmBoardDevice::on_silence(TimeNs now) {
  restart_.on_silence<FtmCommand>(now, options_.restart_after_silence_ns, link_.transport(), encode_ftm_command, stats_,
                                  stats_.restart_commands);
  publish();
}

void FtmBoardDevice::end_burst(bool link_lost) {
  deliver_pending();
  if (link_lost) return;  // the loss report publishes
  stats_.stream = stream_.stats();
  publish();
}

void FtmBoardDevice::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  std::array<FtmBoardSample, kFtmMaxSamplesPerReport> samples;
  const FtmPushResult r = stream_.push(report, samples, receive_ns);
  const bool data = r.verdict == FtmReportVerdict::accepted || r.verdict == FtmReportVerdict::duplicate ||
                    r.verdict == FtmReportVerdict::late;
  if (data) {
    restart_.saw_data(receive_ns);
    if (r.device_reset) {
      deliver_pending();  // on the old epoch's clock, before it is forgotten
      clock_sync_.reset();
    }
    // Duplicates and late reports arrived later than their twin would have:
    // they sit above the envelope and cannot pull it.
    (void)stats_.observe_clock(clock_sync_, static_cast<std::uint32_t>(r.last_device_time_us), receive_ns);
  }
  if (r.verdict == FtmReportVerdict::accepted) {
    for (std::size_t i = 0; i < r.sample_count && pending_.size() < pending_.capacity(); ++i) {
      pending_.push_back(samples[i]);
    }
  }
}

void FtmBoardDevice::deliver_pending() {
  if (pending_.empty()) return;
  for (FtmBoardSample& s : pending_) {
    // The unwrapped device time equals the wire's counter modulo 2^32, which ClockSync unwraps.
    s.event.imu.time_ns = 0;
    s.event.bend.time_ns = 0;
    const TimeNs t = clock_sync_.to_host_ns(static_cast<std::uint32_t>(s.device_time_us));
    if (s.event.kind == ftm::FtmEvent::Kind::imu) {
      s.event.imu.time_ns = t;
    } else {
      s.event.bend.time_ns = t;
    }
  }
  std::stable_sort(pending_.begin(), pending_.end(), [](const FtmBoardSample& a, const FtmBoardSample& b) {
    const TimeNs ta = a.event.time_ns(), tb = b.event.time_ns();
    return ta != tb ? ta < tb : a.event.kind < b.event.kind;
  });
  for (FtmBoardSample& s : pending_) {
    const bool imu = s.event.kind == ftm::FtmEvent::Kind::imu;
    const std::size_t slot = imu ? s.event.index % ftm::kFtmImuCount
                                 : ftm::kFtmImuCount + s.event.index % ftm::kFtmBendCount;
    TimeNs& t = imu ? s.event.imu.time_ns : s.event.bend.time_ns;
    if (last_time_ns_[slot] != 0 && t <= last_time_ns_[slot]) {
      t = last_time_ns_[slot] + 1000;
      ++stats_.time_clamps;
    }
    last_time_ns_[slot] = t;
    if (!outlet_.deliver(s)) {
      ++stats_.queue_overruns;
      continue;
    }
    ++stats_.samples_delivered;
  }
  pending_.clear();
  if (burst_callback_) burst_callback_();
}

void FtmBoardFeed::advance(TimeNs t_ns, std::vector<ftm::FtmEvent>& out) {
  FtmBoardSample s;
  while (device_.pop(s)) held_.push_back(s.event);
  auto before = [](const ftm::FtmEvent& a, const ftm::FtmEvent& b) {
    return a.time_ns() != b.time_ns() ? a.time_ns() < b.time_ns() : a.kind < b.kind;
  };
  std::stable_sort(held_.begin(), held_.end(), before);
  std::size_t n = 0;
  for (; n < held_.size() && held_[n].time_ns() <= t_ns; ++n) {
    const ftm::FtmEvent& e = held_[n];
    if (delivered_ > 0 && e.time_ns() < last_ns_) {
      ++dropped_;
      continue;
    }
    last_ns_ = e.time_ns();
    out.push_back(e);
    ++delivered_;
  }
  held_.erase(held_.begin(), held_.begin() + static_cast<std::ptrdiff_t>(n));
}

}  // namespace proprio::devices
