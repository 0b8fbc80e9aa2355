// The `haptics` plugin: the fingertip devices behind the OpenXR layer's
// XR_PROPRIO_fingertip_haptics and xrApplyHapticFeedback
// (openxr_layer/fingertip_haptics_service.hpp). It is the haptics module's one
// servo loop, unchanged: device models, safety gates, the contact simulation
// with both hands' proxies in one world, and the devices' sinks. What the app
// adds (its forces, vibrations) enters through haptics::ExtraForces.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <thread>

#include "proprio/core/data_dir.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/mailbox.hpp"
#include "proprio/fingertip_device/fingertip_device.hpp"
#include "proprio/hand_sources/plugin_abi.hpp"
#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/hid_channels.hpp"
#include "proprio/haptics/servo_loop.hpp"
#include "proprio/openxr/XR_PROPRIO_fingertip_haptics.h"
#include "proprio/openxr_layer/fingertip_haptics_service.hpp"

namespace proprio::hand_sources {
namespace {

using openxr_layer::ColliderKind;
using openxr_layer::ColliderSpec;
using openxr_layer::FingertipCapability;
using openxr_layer::FingertipGate;
using openxr_layer::FingertipHapticsReport;
using openxr_layer::FingertipHapticsService;
using openxr_layer::HapticDevices;
using openxr_layer::HapticsConfig;
using openxr_layer::HandCapabilities;
using openxr_layer::TrackedHandFeed;
using haptics::FingertipForce;

constexpr int kColliderSlots = XR_MAX_HAPTIC_COLLIDERS_PROPRIO;
// How often the feeder hands the tracked hands to the simulation: trackers
// deliver 60-120 Hz, so 250 Hz loses nothing, and the inverse kinematics
// stays off the 1 kHz thread.
constexpr DurationNs kFeedPeriodNs = 4 * kNsPerMillisecond;
// xrApplyHapticFeedback's XR_MIN_HAPTIC_DURATION, and the shortest press a
// rate-limited fingertip device renders so that it can be felt.
constexpr DurationNs kMinPressNs = 100 * kNsPerMillisecond;

// One app force as the servo thread reads it.
struct AppForce {
  FingertipForce force;
  TimeNs at_ns = 0;
  bool set = false;
};
struct Press {
  double normal_n = 0.0;
  TimeNs until_ns = 0;
};

FingertipGate gate_of(haptics::GateState s) {
  switch (s) {
    case haptics::GateState::ramping: return FingertipGate::ramping;
    case haptics::GateState::active: return FingertipGate::active;
    case haptics::GateState::faulted: return FingertipGate::faulted;
    default: return FingertipGate::off;
  }
}

haptics::ShapeKind shape_of(ColliderKind k) {
  switch (k) {
    case ColliderKind::box: return haptics::ShapeKind::box;
    case ColliderKind::capsule: return haptics::ShapeKind::capsule;
    case ColliderKind::cylinder: return haptics::ShapeKind::cylinder;
    default: return haptics::ShapeKind::sphere;
  }
}

Result<std::shared_ptr<const haptics::FingertipDeviceModel>> load_model(const std::string& name) {
  // A bare name is a shipped model; anything with a slash or .toml a file.
  const bool is_path = name.find('/') != std::string::npos || name.ends_with(".toml");
  const std::string file = is_path ? name : data_path("haptics/" + name + ".toml");
  auto model = haptics::load_device_model(file);
  if (!model) return model.error().with_context("[haptics] model '" + name + "'");
  return std::shared_ptr<const haptics::FingertipDeviceModel>(std::move(*model));
}

struct ChannelInfo {
  Handedness side = Handedness::right;
  Finger finger = Finger::index;
};

class HapticsService final : public FingertipHapticsService, public haptics::ExtraForces {
 public:
  static Result<std::unique_ptr<HapticsService>> start(const HapticsConfig& config) {
    auto service = std::unique_ptr<HapticsService>(new HapticsService(config));
    if (auto st = service->open(); !st) return st.error();
    return service;
  }

  ~HapticsService() override {
    stop_contact();
    if (loop_) loop_->stop();  // disengages every gate and sends zero to every device
  }

  const std::array<HandCapabilities, 2>& capabilities() const noexcept override { return caps_; }
  bool contact_allowed() const noexcept override { return config_.contact; }

  bool apply_forces(Handedness hand, const std::array<Vec3, kFingerCount>& f_in_tip, TimeNs now) noexcept override {
    std::lock_guard lock(app_mutex_);
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      if (channels_[c].side != hand) continue;
      const Vec3& f = f_in_tip[static_cast<std::size_t>(channels_[c].finger)];
      app_[c].publish({FingertipForce::from_tip_frame(f), now, true});
    }
    // Also a finger without a device: the call was invalid either way.
    return std::all_of(f_in_tip.begin(), f_in_tip.end(), [](const Vec3& f) { return f.allFinite(); });
  }

  void vibrate(Handedness hand, double amplitude, DurationNs duration, TimeNs now) noexcept override {
    if (!(std::isfinite(amplitude) && amplitude > 0.0)) {
      stop_vibration(hand);
      return;
    }
    std::lock_guard lock(app_mutex_);
    const double a = std::min(amplitude, 1.0) * config_.vibration_gain;
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      if (channels_[c].side != hand) continue;
      const double max_n = models_[c]->limits().max_normal_n;
      press_[c].publish({a * max_n, now + std::max(duration, kMinPressNs)});
    }
  }

  void stop_vibration(Handedness hand) noexcept override {
    std::lock_guard lock(app_mutex_);
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      if (channels_[c].side == hand) press_[c].publish({});
    }
  }

  void clear_app_forces() noexcept override {
    std::lock_guard lock(app_mutex_);
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      app_[c].publish({});
      press_[c].publish({});
    }
  }

  void set_output(bool on) noexcept override {
    std::lock_guard lock(app_mutex_);  // fit_proxies may be replacing the loop
    output_on_.store(on, std::memory_order_release);
    loop_->request_output(on);
  }

  Status start_contact(TrackedHandFeed* feed) override {
    if (!config_.contact) {
      return make_error(Errc::unsupported, "the layer's [haptics] table has contact = false");
    }
    if (feed == nullptr) return make_error(Errc::invalid_argument, "no tracked-hand feed");
    stop_contact();
    fit_proxies(*feed);
    feed_ = feed;
    feeding_.store(true, std::memory_order_release);
    feeder_ = std::thread([this] { feed_hands(); });
    loop_->set_simulation_enabled(true);
    return {};
  }

  void stop_contact() noexcept override {
    if (feeder_.joinable()) {
      feeding_.store(false, std::memory_order_release);
      feeder_.join();
    }
    feed_ = nullptr;
    if (loop_) loop_->set_simulation_enabled(false);
    std::lock_guard lock(app_mutex_);
    for (auto& slot : colliders_.slots) slot.active = false;
    if (loop_) loop_->publish_colliders(colliders_);
  }

  int add_collider(const ColliderSpec& spec, const Pose& T_world_collider) noexcept override {
    haptics::ColliderShape shape;
    shape.shape = shape_of(spec.kind);
    shape.radius_m = spec.radius_m;
    shape.half_length_m = spec.half_length_m;
    shape.half_extents_m = spec.half_extents_m;
    shape.friction = spec.friction;
    if (!shape.validate() || !T_world_collider.p.allFinite() || !T_world_collider.q.coeffs().allFinite() ||
        T_world_collider.q.norm() < 0.5) {
      return kBadCollider;
    }
    std::lock_guard lock(app_mutex_);
    for (int k = 0; k < kColliderSlots; ++k) {
      auto& slot = colliders_.slots[static_cast<std::size_t>(k)];
      if (slot.active) continue;
      slot = {true, shape, {T_world_collider.q.normalized(), T_world_collider.p}};
      loop_->publish_colliders(colliders_);
      return k;
    }
    return kCollidersFull;
  }

  bool move_collider(int id, const Pose& T_world_collider) noexcept override {
    if (id < 0 || id >= kColliderSlots || !T_world_collider.p.allFinite() || !T_world_collider.q.coeffs().allFinite() ||
        T_world_collider.q.norm() < 0.5) {
      return false;
    }
    std::lock_guard lock(app_mutex_);
    auto& slot = colliders_.slots[static_cast<std::size_t>(id)];
    if (!slot.active) return false;
    slot.T_world_collider = {T_world_collider.q.normalized(), T_world_collider.p};
    loop_->publish_colliders(colliders_);
    return true;
  }

  void remove_collider(int id) noexcept override {
    if (id < 0 || id >= kColliderSlots) return;
    std::lock_guard lock(app_mutex_);
    colliders_.slots[static_cast<std::size_t>(id)].active = false;
    loop_->publish_colliders(colliders_);
  }

  bool proxy_hand(Handedness hand, HandPose& out) noexcept override {
    std::lock_guard lock(read_mutex_);
    const haptics::ServoSnapshot* s = loop_->latest();
    if (s == nullptr || !s->simulating || feed_ == nullptr) return false;
    for (std::size_t h = 0; h < s->hand_count; ++h) {
      if (s->hands[h].side != hand) continue;
      out = s->hands[h].proxy;
      return have_hand_[static_cast<std::size_t>(hand)].load(std::memory_order_acquire);
    }
    return false;
  }

  bool report(Handedness hand, FingertipHapticsReport& out) noexcept override {
    std::lock_guard lock(read_mutex_);
    const haptics::ServoSnapshot* s = loop_->latest();
    if (s == nullptr) return false;
    out = {};
    out.time_ns = s->time_ns;
    for (std::size_t h = 0; h < s->hand_count; ++h) {
      if (s->hands[h].side != hand) continue;
      for (std::size_t f = 0; f < kFingerCount; ++f) out.fingers[f].contact_in_tip = s->hands[h].on_pad[f].in_tip_frame();
    }
    for (std::size_t c = 0; c < s->channel_count; ++c) {
      if (channels_[c].side != hand) continue;
      const auto& ch = s->channels[c];
      auto& r = out.fingers[static_cast<std::size_t>(ch.finger)];
      r.gate = gate_of(ch.gate);
      r.connected = ch.connected;
      r.commanded_in_tip = ch.commanded.in_tip_frame();
      r.measured_in_tip = ch.measured.in_tip_frame();
    }
    return true;
  }

  std::string describe() const override {
    std::string s = config_.describe();
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      s += "\n  " + std::string(to_string(channels_[c].side)) + " " + std::string(to_string(channels_[c].finger)) +
           ": " + caps_[static_cast<std::size_t>(channels_[c].side)][static_cast<std::size_t>(channels_[c].finger)].device;
    }
    return s;
  }

  // haptics::ExtraForces, on the servo thread.
  FingertipForce force(std::size_t c, TimeNs now) noexcept override {
    app_[c].fetch(app_now_[c]);
    press_[c].fetch(press_now_[c]);
    FingertipForce f;
    const AppForce& a = app_now_[c];
    if (a.set) {
      if (!a.force.is_finite()) return a.force;  // the gate faults: zero until the next good force
      // Held, then faded linearly to zero at the watchdog period: an app that
      // stops submitting (a hitch, a crash) leaves nothing pressing, and a
      // steady 90 Hz submitter never fades. The fade starts from what the
      // device can render and is slow enough for the gate's rate limit to
      // follow, so the output really is zero at the period.
      const haptics::DeviceLimits& limits = models_[c]->limits();
      const FingertipForce renderable = models_[c]->renderable(a.force);
      const auto period = static_cast<double>(limits.watchdog_ns);
      const double fade = std::min(period, std::max(0.5 * period, 1.2e9 * limits.max_normal_n / limits.max_rate_n_per_s));
      const double age = static_cast<double>(now - a.at_ns);
      const double w = std::clamp((period - age) / fade, 0.0, 1.0);
      f.normal_n = w * renderable.normal_n;
      f.shear_x_n = w * renderable.shear_x_n;
      f.shear_z_n = w * renderable.shear_z_n;
    }
    if (now < press_now_[c].until_ns) f.normal_n += press_now_[c].normal_n;
    return f;
  }

 private:
  explicit HapticsService(const HapticsConfig& config) : config_(config) {}

  Status open() {
    std::vector<haptics::ServoChannel> channels;
    if (config_.devices == HapticDevices::emulated) {
      auto model = load_model(config_.model);
      if (!model) return model.error();
      for (std::size_t side = 0; side < 2; ++side) {
        for (Finger f : config_.fingers[side]) {
          auto sink = haptics::EmulatedFingertip::create(*model);
          if (!sink) return sink.error().with_context("[haptics] emulated device");
          channels.push_back({f, *model, std::shared_ptr<haptics::FingertipSink>(std::move(*sink)), side});
          channels_.push_back({static_cast<Handedness>(side), f});
        }
      }
    } else {
      auto listed = devices::enumerate_fingertip_devices();
      if (!listed) return listed.error().with_context("[haptics] devices = \"hid\"");
      std::vector<hid::HidDeviceInfo> available = *listed;
      for (std::size_t side = 0; side < 2; ++side) {
        if (config_.fingers[side].empty()) continue;
        haptics::HidChannelOptions ho;
        ho.fingers = config_.fingers[side];
        ho.hand = static_cast<Handedness>(side);
        for (const auto& b : config_.bindings[side]) {
          auto binding = haptics::parse_hid_binding(b);
          if (!binding) return binding.error().with_context("[haptics] bind_" + std::string(to_string(ho.hand)));
          ho.bindings.push_back(*binding);
        }
        if (!config_.model.empty()) {
          auto model_file = config_.model.find('/') != std::string::npos || config_.model.ends_with(".toml")
                                ? config_.model
                                : data_path("haptics/" + config_.model + ".toml");
          ho.model_file = model_file;
        }
        ho.model_dir = data_path("haptics");
        auto opened = haptics::open_hid_channels(ho, available);
        if (!opened) return opened.error().with_context(std::string(to_string(ho.hand)) + " hand");
        for (auto& c : *opened) {
          std::erase_if(available, [&](const hid::HidDeviceInfo& d) { return d.path == c.listed.path; });
          c.channel.hand = side;
          channels_.push_back({ho.hand, c.channel.finger});
          channels.push_back(std::move(c.channel));
        }
      }
    }
    for (const auto& c : channels) models_.push_back(c.model);
    channel_specs_ = std::move(channels);
    if (auto st = build_loop(); !st) return st;
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      const auto& limits = models_[c]->limits();
      FingertipCapability& cap =
          caps_[static_cast<std::size_t>(channels_[c].side)][static_cast<std::size_t>(channels_[c].finger)];
      cap.present = true;
      cap.connected = true;
      const haptics::ForceAxes axes = models_[c]->axes();
      cap.force_dofs = 1 + (axes.shear_x ? 1 : 0) + (axes.shear_z ? 1 : 0);
      cap.max_normal_n = limits.max_normal_n;
      cap.max_shear_n = cap.force_dofs > 1 ? limits.max_shear_n : 0.0;
      cap.max_rate_n_per_s = limits.max_rate_n_per_s;
      cap.friction_coefficient = limits.friction_coefficient;
      cap.watchdog_ns = limits.watchdog_ns;
      cap.device = std::string(models_[c]->kind()) +
                   (config_.devices == HapticDevices::emulated ? " (emulated)" : " (USB HID)");
    }
    return loop_->start();
  }

  // The world: both proxies (which hands the app will track is its
  // business) of shapes_' sizes, the collider slots, no floor (the app's
  // world is its own); the servo loop over it, not started.
  Status build_loop() {
    const haptics::ProxyHandSpec hands[] = {{HandModel(shapes_[0]), Handedness::left},
                                            {HandModel(shapes_[1]), Handedness::right}};
    haptics::HapticScene scene;
    scene.floor_height_m.reset();
    haptics::ContactSimOptions sim_options;
    sim_options.collider_slots = config_.contact ? kColliderSlots : 0;
    auto sim = haptics::ContactSimulation::create(hands, scene, sim_options);
    if (!sim) return sim.error().with_context("[haptics] contact simulation");
    haptics::ServoLoopOptions lo;
    lo.force_scale = config_.force_scale;
    lo.engage_on_start = output_on_.load(std::memory_order_acquire);
    auto loop = haptics::ServoLoop::create(std::move(*sim), channel_specs_, lo);
    if (!loop) return loop.error();
    loop_ = std::move(*loop);
    loop_->set_simulation_enabled(false);
    loop_->set_extra_forces(std::shared_ptr<haptics::ExtraForces>(this, [](haptics::ExtraForces*) {}));
    return {};
  }

  // The proxies take the sizes of the hands tracked now (the default hand
  // where one is not tracked): a proxy of another size would touch objects
  // centimetres from where the user's fingertips are. Rebuilding the world
  // stops the loop for a moment: the devices go to zero and ramp in again.
  void fit_proxies(TrackedHandFeed& feed) {
    std::array<HandShape, 2> fitted = shapes_;
    bool changed = false;
    for (Handedness side : {Handedness::left, Handedness::right}) {
      HandPose pose;
      if (!feed.tracked_hand(side, MonotonicClock::instance().now_ns(), pose)) {
        logger().info("Proprio layer: fingertip haptics: the {} hand is not tracked now; its proxy keeps a {:.0f} x "
                      "{:.0f} mm hand", to_string(side), shapes_[static_cast<std::size_t>(side)].hand_length_m * 1e3,
                      shapes_[static_cast<std::size_t>(side)].hand_width_m * 1e3);
        continue;
      }
      auto shape = HandShape::from_tracked_pose(pose);
      if (!shape) {
        logger().warn("Proprio layer: fingertip haptics: the {} hand's size: {}", to_string(side), shape.error().message);
        continue;
      }
      HandShape& old = fitted[static_cast<std::size_t>(side)];
      changed |= std::abs(shape->hand_length_m - old.hand_length_m) > 5e-4 ||
                 std::abs(shape->hand_width_m - old.hand_width_m) > 5e-4;
      old = *shape;
    }
    if (!changed) return;
    // App threads keep calling in meanwhile (the layer holds no lock of its
    // own over this); they wait here for the new loop.
    std::scoped_lock lock(app_mutex_, read_mutex_);
    loop_->stop();
    const std::array<HandShape, 2> previous = shapes_;
    shapes_ = fitted;
    Status st = build_loop();
    if (!st) {
      logger().warn("Proprio layer: fingertip haptics: keeping the default proxies: {}", st.error().message);
      shapes_ = previous;
      st = build_loop();
    }
    if (st) st = loop_->start();
    loop_->publish_colliders(colliders_);
    if (!st) logger().error("Proprio layer: fingertip haptics: the servo loop did not restart: {}", st.error().message);
    for (std::size_t h = 0; h < 2; ++h) {
      logger().info("Proprio layer: fingertip haptics: {} proxy: {}", to_string(static_cast<Handedness>(h)),
                    shapes_[h].describe());
    }
  }

  void feed_hands() {
    const Clock& clock = MonotonicClock::instance();
    HandPose pose;
    while (feeding_.load(std::memory_order_acquire)) {
      const TimeNs now = clock.now_ns();
      for (Handedness side : {Handedness::left, Handedness::right}) {
        if (feed_->tracked_hand(side, now, pose) && pose.active) {
          pose.hand = side;
          loop_->submit_tracked_hand(pose);
          have_hand_[static_cast<std::size_t>(side)].store(true, std::memory_order_release);
        }
      }
      std::this_thread::sleep_for(std::chrono::nanoseconds(kFeedPeriodNs));
    }
  }

  HapticsConfig config_;
  std::vector<ChannelInfo> channels_;
  std::vector<std::shared_ptr<const haptics::FingertipDeviceModel>> models_;
  std::array<HandCapabilities, 2> caps_{};
  std::vector<haptics::ServoChannel> channel_specs_;  // what every (re)built loop drives
  std::array<HandShape, 2> shapes_{*HandShape::from_measurements(0.19, 0.10), *HandShape::from_measurements(0.19, 0.10)};
  std::atomic<bool> output_on_{true};
  std::unique_ptr<haptics::ServoLoop> loop_;

  std::mutex app_mutex_;   // app threads: the producers of app_, press_ and colliders_
  std::mutex read_mutex_;  // app threads: the consumer of loop_->latest()
  std::array<Mailbox<AppForce>, haptics::kMaxServoChannels> app_;
  std::array<Mailbox<Press>, haptics::kMaxServoChannels> press_;
  std::array<AppForce, haptics::kMaxServoChannels> app_now_{};  // servo thread
  std::array<Press, haptics::kMaxServoChannels> press_now_{};   // servo thread
  haptics::ColliderTable colliders_;

  TrackedHandFeed* feed_ = nullptr;
  std::atomic<bool> feeding_{false};
  std::array<std::atomic<bool>, 2> have_hand_{};
  std::thread feeder_;
};

Result<std::unique_ptr<FingertipHapticsService>> start_haptics(const HapticsConfig& config) {
  auto service = HapticsService::start(config);
  if (!service) return service.error();
  return std::unique_ptr<FingertipHapticsService>(std::move(*service));
}

}  // namespace
}  // namespace proprio::hand_sources

PROPRIO_DEFINE_HAPTICS_PLUGIN(proprio::hand_sources::start_haptics)
