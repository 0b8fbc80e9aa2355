#include "proprio/rig_live/rig_live.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::rig_live {

using rig_bus::BusSnapshot;
using rig_bus::ComponentKind;

Result<std::unique_ptr<EmulatedBusLink>> EmulatedBusLink::create(rig_bus::BusTree tree,
                                                                 rig_bus::BusEmulatorOptions options,
                                                                 rig_bus::BusAnglesFn angles,
                                                                 rig_bus::RigBusServeOptions serve,
                                                                 rig_bus::RigBusDeviceOptions device) {
  if (auto st = device.validate(); !st) return st.error();
  auto emulator = rig_bus::RigBusEmulator::create(std::move(tree), std::move(options), std::move(angles));
  if (!emulator) return emulator.error();
  std::unique_ptr<EmulatedBusLink> out(new EmulatedBusLink());
  out->link_ = std::make_shared<hid::FakeHidLink>(MonotonicClock::instance());
  out->server_ = std::make_unique<rig_bus::RigBusEmulatorServer>(std::move(*emulator), out->link_, serve);
  out->device_ = std::make_unique<rig_bus::RigBusDevice>(std::make_unique<hid::FakeHidTransport>(out->link_), device);
  return out;
}

EmulatedBusLink::~EmulatedBusLink() { stop(); }

Status EmulatedBusLink::start() {
  server_->start();
  return device_->start();
}

void EmulatedBusLink::stop() {
  if (device_) device_->stop();
  if (server_) server_->stop();
}

TimeNs EmulatedBusLink::emulator_now_ns() const {
  return MonotonicClock::instance().now_ns() - server_->time_zero_ns();
}

std::vector<rig_bus::BusTruthEvent> EmulatedBusLink::truth_events() const {
  return server_->with_emulator([](const rig_bus::RigBusEmulator& e) { return e.events(); });
}

std::vector<rig_bus::BusTopologyTracker::Edge> EmulatedBusLink::truth_edges() const {
  return server_->with_emulator([](const rig_bus::RigBusEmulator& e) { return e.truth_edges(); });
}

Status RigLiveOptions::validate() const {
  if (device != "emulate" && device != "usb")
    return make_error(Errc::invalid_argument, "the device must be 'emulate' or 'usb', not '" + device + "'");
  if (!(stale_after_s > 0.0 && stale_after_s <= 10.0))
    return make_error(Errc::invalid_argument, "stale_after_s must be in (0, 10] seconds");
  if (auto st = emulated.validate(); !st) return st;
  if (auto st = faults.validate(); !st) return st;
  return retarget.validate();
}

std::string RigLiveOptions::describe() const {
  std::string s = device == "usb" ? "device: a rig base on USB" + (hid_path.empty() ? std::string() : " at " + hid_path)
                                  : "device: the plan's device emulated on the fake USB cable; " + emulated.describe();
  if (device == "emulate") {
    s += "\nbus faults: loss " + std::to_string(faults.loss_probability * 100.0).substr(0, 4) + " %, corruption " +
         std::to_string(faults.corrupt_probability * 100.0).substr(0, 4) + " %";
    s += faults.power_loss_interval_ns > 0
             ? ", a link power loss every " + std::to_string(faults.power_loss_interval_ns / kNsPerSecond) + " s"
             : ", no power losses";
    if (faults.clock_skew_max_ppm > 0) s += ", clock skew up to " + std::to_string(static_cast<int>(faults.clock_skew_max_ppm)) + " ppm";
  }
  s += "\n" + retarget.describe();
  return s;
}

Result<SnapshotPoser> SnapshotPoser::create(const rig_plan::RigInput& input, const rig_plan::Plan& plan,
                                            const rig_plan::RetargetOptions& options, double stale_after_s) {
  auto retargeter = rig_plan::Retargeter::create(input, plan, options);
  if (!retargeter) return retargeter.error();
  return SnapshotPoser(plan, std::move(*retargeter), stale_after_s);
}

Status SnapshotPoser::pose(const BusSnapshot& snap, TimeNs now_ns, RigLiveFrame& frame) {
  observed_.clear();
  frame.components_attached = 0;
  for (const auto& c : snap.components) {
    if (!c.attached) continue;
    ++frame.components_attached;
    if (c.kind == ComponentKind::base || c.id == snap.base_id) continue;
    if (!c.type_known) continue;  // its kind is not known yet: bound once its type message arrives
    rig_plan::ObservedModule m;
    m.id = c.id;
    m.is_splitter = c.kind == ComponentKind::splitter;
    m.kind = c.kind_name;
    m.parent_id = c.parent_id == snap.base_id ? 0 : c.parent_id;
    m.parent_outlet = c.parent_outlet == rig_bus::kNoOutlet ? 0 : c.parent_outlet;
    observed_.push_back(std::move(m));
  }
  auto binding = rig_plan::bind_device(plan_, observed_);
  if (!binding) return binding.error();
  frame.binding_problems = binding->describe();
  frame.q_in_out.assign(plan_.modules.size(), std::nullopt);
  frame.joints_planned = 0;
  frame.joints_live = 0;
  double newest_age_s = std::numeric_limits<double>::infinity();
  for (std::size_t m = 0; m < plan_.modules.size(); ++m) {
    if (plan_.modules[m].type != rig_plan::DeviceModule::Type::joint) continue;
    ++frame.joints_planned;
    const std::uint32_t id = binding->observed_id[m];
    if (id == 0) continue;
    const auto* c = snap.find(id);
    if (!c || !c->have_angles) continue;
    // The snapshot was published a moment ago; its ages are as of then.
    const double age_s = static_cast<double>(c->angles_age_ns + std::max<TimeNs>(0, now_ns - snap.time_ns)) * 1e-9;
    newest_age_s = std::min(newest_age_s, age_s);
    if (age_s > stale_after_s_) continue;
    frame.q_in_out[m] = rig_device::joint_rotation(c->angles);
    ++frame.joints_live;
  }
  frame.newest_reading_age_ms = std::isfinite(newest_age_s) ? 1e3 * newest_age_s : std::nan("");
  return retargeter_.retarget(frame.q_in_out, frame.pose);
}

Result<std::unique_ptr<RigLiveSource>> RigLiveSource::create(const rig_plan::RigInput& input,
                                                             const rig_plan::Plan& plan,
                                                             const RigLiveOptions& options) {
  if (auto st = options.validate(); !st) return st.error();
  std::unique_ptr<RigLiveSource> s(new RigLiveSource());
  s->options_ = options;
  auto poser = SnapshotPoser::create(input, plan, options.retarget, options.stale_after_s);
  if (!poser) return poser.error();
  s->poser_.emplace(std::move(*poser));
  if (options.device == "emulate") {
    auto tree = bus_tree_for_plan(plan, options.emulated.seed);
    if (!tree) return tree.error();
    auto device = EmulatedPlanDevice::create(plan, *tree, options.emulated);
    if (!device) return device.error();
    s->emulated_device_ = *device;
    rig_bus::BusEmulatorOptions eo;
    eo.seed = options.bus_seed;
    eo.faults = options.faults;
    auto link = EmulatedBusLink::create(tree->tree, eo, angles_callback(*device));
    if (!link) return link.error();
    s->emulated_ = std::move(*link);
    s->device_ = &s->emulated_->device();
    auto truth = rig_plan::Retargeter::create(input, plan, options.retarget);
    if (!truth) return truth.error();
    s->truth_retargeter_.emplace(std::move(*truth));
  } else {
    hid::HidDeviceSelector selector = rig_bus::rig_bus_selector();
    if (!options.hid_path.empty()) selector.path = options.hid_path;
    s->usb_ = std::make_unique<rig_bus::RigBusDevice>(std::make_unique<hid::HidapiTransport>(selector));
    s->device_ = s->usb_.get();
  }
  return s;
}

RigLiveSource::~RigLiveSource() { stop(); }

Status RigLiveSource::start() {
  start_ns_ = MonotonicClock::instance().now_ns();
  return emulated_ ? emulated_->start() : usb_->start();
}

void RigLiveSource::stop() {
  if (emulated_) emulated_->stop();
  if (usb_) usb_->stop();
}

Status RigLiveSource::update(RigLiveFrame& frame) {
  const BusSnapshot snap = device_->snapshot();
  frame.time_ns = MonotonicClock::instance().now_ns();
  frame.t_s = static_cast<double>(frame.time_ns - start_ns_) * 1e-9;
  if (auto st = poser_->pose(snap, frame.time_ns, frame); !st) return st;
  if (emulated_) {
    const double t_emu_s = static_cast<double>(emulated_->emulator_now_ns()) * 1e-9;
    emulated_device_->animator().q_in_out(t_emu_s, truth_q_);
    truth_opt_.assign(truth_q_.begin(), truth_q_.end());
    if (!frame.truth) frame.truth.emplace();
    if (auto st = truth_retargeter_->retarget(truth_opt_, *frame.truth); !st) return st;
    frame.target_sample = emulated_device_->animator().target_sample(t_emu_s);
  } else {
    frame.truth.reset();
  }
  return {};
}

rig_bus::RigBusDeviceStats RigLiveSource::device_stats() { return device_->stats(); }

std::optional<rig_bus::BusEmulatorStats> RigLiveSource::emulator_stats() const {
  if (!emulated_) return std::nullopt;
  return emulated_->emulator_stats();
}

rig_bus::BusSnapshot RigLiveSource::snapshot() { return device_->snapshot(); }

}  // namespace proprio::rig_live
