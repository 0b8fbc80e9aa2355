#include "proprio/rig_bus/bus_device.hpp"

#include <cstdio>

namespace proprio::rig_bus {

hid::HidDeviceSelector rig_bus_selector() {
  hid::HidDeviceSelector sel;
  sel.vendor_id = kRigBusUsbVendorId;
  sel.product_id = kRigBusUsbProductId;
  sel.usage_page = kRigBusHidUsagePage;
  return sel;
}

Status RigBusDeviceOptions::validate() const {
  auto bad = [](const char* what) { return make_error(Errc::invalid_argument, std::string("RigBusDeviceOptions.") + what); };
  if (read_timeout_ns <= 0) return bad("read_timeout_ns must be positive");
  if (reconnect_backoff_min_ns <= 0 || reconnect_backoff_max_ns < reconnect_backoff_min_ns) {
    return bad("reconnect_backoff_min_ns must be positive and at most reconnect_backoff_max_ns");
  }
  // A read timeout beyond the detach time would let a silent bus look attached for longer.
  if (read_timeout_ns > tracker.detach_after_ns) return bad("read_timeout_ns must not exceed tracker.detach_after_ns");
  if (snapshot_interval_ns < 0 || snapshot_interval_ns > tracker.detach_after_ns) {
    return bad("snapshot_interval_ns must be 0 (every burst) to tracker.detach_after_ns");
  }
  return tracker.validate();
}

std::string RigBusDeviceOptions::describe() const {
  char text[200];
  std::snprintf(text, sizeof text, "read timeout %.0f ms, reconnect backoff %.0f-%.0f ms, snapshots every %.0f ms; ",
                static_cast<double>(read_timeout_ns) * 1e-6, static_cast<double>(reconnect_backoff_min_ns) * 1e-6,
                static_cast<double>(reconnect_backoff_max_ns) * 1e-6, static_cast<double>(snapshot_interval_ns) * 1e-6);
  return text + tracker.describe();
}

RigBusDevice::RigBusDevice(std::unique_ptr<hid::HidTransport> transport, RigBusDeviceOptions options,
                           const Clock& clock)
    : options_(options),
      clock_(clock),
      host_(options_.tracker),
      link_(std::move(transport), hid::link_options_of(options_, kRigBusMaxBurst), clock, *this, stats_) {}

RigBusDevice::~RigBusDevice() { stop(); }

Status RigBusDevice::start() {
  if (running()) return make_error(Errc::invalid_argument, "RigBusDevice::start: the reader thread is already running");
  if (!link_.has_transport()) return make_error(Errc::invalid_argument, "RigBusDevice::start: no transport");
  if (auto s = options_.validate(); !s) return s;
  link_.start();
  return {};
}

Result<std::string> RigBusDevice::on_open(hid::HidTransport& transport) { return transport.describe(); }

void RigBusDevice::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  (void)host_.on_report(report, receive_ns);
}

void RigBusDevice::end_burst(bool link_lost) {
  if (link_lost) return;  // the loss report publishes
  if (clock_.now_ns() - last_publish_ns_ >= options_.snapshot_interval_ns) publish();
}

void RigBusDevice::on_silence(TimeNs) { publish(); }

void RigBusDevice::publish() {
  const TimeNs now = clock_.now_ns();
  last_publish_ns_ = now;
  host_.update(now);
  stats_.host = host_.stats();
  const BusSnapshot s = host_.tracker().snapshot(now);
  snapshots_.publish(s);
  ++stats_.snapshots_published;
  if (snapshot_callback_) snapshot_callback_(s);
  published_.publish(stats_, unused_clock_);
}

BusSnapshot RigBusDevice::snapshot() {
  if (const BusSnapshot* s = snapshots_.read()) snapshot_copy_ = *s;
  return snapshot_copy_;
}

}  // namespace proprio::rig_bus
