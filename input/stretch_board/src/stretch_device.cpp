#include "proprio/stretch_board/stretch_device.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>

#include "proprio/core/log.hpp"
#include "proprio/hid/info_report.hpp"

namespace proprio::devices {

hid::HidDeviceSelector stretch_board_selector() {
  hid::HidDeviceSelector sel;
  sel.vendor_id = kStretchUsbVendorId;
  sel.product_id = kStretchUsbProductId;
  sel.usage_page = kStretchHidUsagePage;
  return sel;
}

StretchDevice::StretchDevice(std::unique_ptr<hid::HidTransport> transport, StretchDeviceOptions options,
                             const Clock& clock)
    : options_(options),
      clock_(clock),
      stream_(options_.stream),
      clock_sync_(options_.clock),
      outlet_(options_.queue_capacity),
      link_(std::move(transport), hid::link_options_of(options_, kStretchMaxBurst), clock, *this, stats_) {
  pending_.reserve(kStretchMaxBurst * kStretchMeasurementsPerReport);
}

StretchDevice::~StretchDevice() { stop(); }

Status StretchDevice::start() {
  if (running()) {
    return make_error(Errc::invalid_argument, "StretchDevice::start: the reader thread is already running");
  }
  if (!link_.has_transport()) return make_error(Errc::invalid_argument, "StretchDevice::start: no transport");
  link_.start();
  return {};
}

bool StretchDevice::before_read() {
  hid::send_queued_commands(commands_, link_.transport(), stats_, encode_stretch_command, "stretch board");
  return true;
}

Result<std::string> StretchDevice::on_open(hid::HidTransport& transport) {
  layout_warned_ = false;
  restart_.saw_data(clock_.now_ns());
  std::string detail = transport.describe();
  if (options_.query_info) {
    const auto info = hid::query_info_report<kStretchInfoReportSize>(
        transport, static_cast<std::uint8_t>(StretchReportId::device_info), decode_stretch_info_report,
        "stretch board");
    if (info) {
      stats_.have_info = true;
      stats_.info = *info;
      char text[200];
      std::snprintf(text, sizeof text,
                    ": firmware %u.%u.%u, %u x %u strips%s (%zu combinations) at %u/s, full scale %.1f pF%s",
                    info->firmware[0], info->firmware[1], info->firmware[2], info->top_strips, info->bottom_strips,
                    info->single_strips ? " and single strips" : "", info->combination_count(), info->rate_hz,
                    stretch_count_to_pf(info->full_scale_ff), info->streaming ? "" : ", not streaming");
      detail += text;
      const StretchStreamOptions& so = options_.stream;
      if ((so.expected_top_strips && info->top_strips != so.expected_top_strips) ||
          (so.expected_bottom_strips && info->bottom_strips != so.expected_bottom_strips)) {
        std::snprintf(text, sizeof text, "; WRONG LAYOUT: the layout expects %u x %u strips, so its "
                      "measurements will be refused", so.expected_top_strips, so.expected_bottom_strips);
        detail += text;
      }
      if (so.require_single_strips && !info->single_strips) {
        detail += "; WRONG PLAN: the layout needs single-strip rows (protocol 1.1) and this board does not measure "
                  "them, so its measurements will be refused";
      }
    }
  }
  return detail;
}

void StretchDevice::on_silence(TimeNs now) {
  restart_.on_silence<StretchCommand>(now, options_.restart_after_silence_ns, link_.transport(), encode_stretch_command,
                                      stats_, stats_.restart_commands);
  publish();
}

void StretchDevice::end_burst(bool link_lost) {
  deliver_pending();
  if (link_lost) return;  // the loss report publishes
  stats_.stream = stream_.stats();
  publish();
}

void StretchDevice::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  std::array<StretchSample, kStretchMeasurementsPerReport> samples;
  const StretchPushResult r = stream_.push(report, samples, receive_ns);
  const bool data = r.verdict == StretchReportVerdict::accepted || r.verdict == StretchReportVerdict::duplicate ||
                    r.verdict == StretchReportVerdict::late;
  if (r.verdict == StretchReportVerdict::wrong_layout && !layout_warned_) {
    layout_warned_ = true;
    const StretchStreamStats& s = stream_.stats();
    logger().error("stretch board: the board measures {} x {} strips{} but the layout expects {} x {}{}: a "
                   "different glove or array is plugged in, the layout file is not this one's, or the firmware does "
                   "not measure single strips; its measurements are refused",
                   s.top_strips, s.bottom_strips, s.single_strips ? " with single strips" : " (pairs only)",
                   options_.stream.expected_top_strips, options_.stream.expected_bottom_strips,
                   options_.stream.require_single_strips ? " with single strips" : "");
  }
  if (data) {
    restart_.saw_data(receive_ns);
    if (r.device_reset) {
      deliver_pending();  // on the old epoch's clock, before it is forgotten
      clock_sync_.reset();
    }
    // Duplicates and late reports are observations too: they arrived later
    // than their twin would have, so they sit above the envelope and cannot pull it.
    (void)stats_.observe_clock(clock_sync_, static_cast<std::uint32_t>(r.last_device_time_us), receive_ns);
  }
  if (r.verdict == StretchReportVerdict::accepted) {
    for (std::size_t i = 0; i < r.sample_count && pending_.size() < pending_.capacity(); ++i) {
      pending_.push_back(samples[i]);
    }
  }
}

void StretchDevice::deliver_pending() {
  if (pending_.empty()) return;
  for (StretchSample& s : pending_) {
    // The unwrapped device time equals the wire's counter modulo 2^32, which is what hid::ClockSync unwraps.
    s.time_ns = delivered_times_.place(clock_sync_.to_host_ns(static_cast<std::uint32_t>(s.device_time_us)),
                                       stats_.time_clamps);
    if (s.status != StretchMeasurementStatus::ok && !options_.deliver_flagged) {
      ++stats_.samples_rejected;
      continue;
    }
    if (!outlet_.deliver(s)) {
      ++stats_.queue_overruns;
      continue;
    }
    ++stats_.samples_delivered;
  }
  pending_.clear();
  if (burst_callback_) burst_callback_();
}

}  // namespace proprio::devices
