#include "proprio/perception_threshold/live.hpp"

#include <fmt/format.h>

#include <chrono>

namespace proprio::perception {
namespace {

constexpr int kCylinderEntity = 0;
// A tracked hand older than this no longer drives the device.
constexpr DurationNs kStaleTargetNs = 100 * kNsPerMillisecond;

engine::FrameContext::Marker sphere_marker(const Vec3& p, double radius, const std::array<float, 4>& rgba) {
  return {engine::FrameContext::Marker::Shape::sphere, Pose{Quat::Identity(), p}, Vec3::Constant(radius), rgba};
}

// An arrow made of a shaft and a head, 20 cm ahead of the eyes, pointing in
// the head frame's `direction` (x right, y up).
void add_arrow(engine::FrameContext& f, Cue cue) {
  if (cue == Cue::none) return;
  Vec3 d = Vec3::Zero();
  if (cue == Cue::up) d.y() = 1;
  if (cue == Cue::down) d.y() = -1;
  if (cue == Cue::left) d.x() = -1;
  if (cue == Cue::right) d.x() = 1;
  const Pose& H = f.T_world_head;
  const Vec3 centre = H * Vec3(0, 0, -0.2);
  const std::array<float, 4> yellow{1.0f, 0.85f, 0.1f, 1.0f};
  // Boxes aligned with the head: the shaft along d, the head as two slanted bars.
  const Quat q_along = H.q * Quat::FromTwoVectors(Vec3::UnitX(), d);
  f.markers.push_back({engine::FrameContext::Marker::Shape::box, Pose{q_along, centre}, Vec3(0.02, 0.003, 0.001), yellow});
  for (double s : {1.0, -1.0}) {
    const Quat q_bar = q_along * Quat(Eigen::AngleAxisd(s * 0.75 * kPi, Vec3::UnitZ()));
    const Vec3 tip = centre + H.q * (0.02 * d);
    f.markers.push_back({engine::FrameContext::Marker::Shape::box, Pose{q_bar, tip + q_bar * Vec3(0.008, 0, 0)},
                         Vec3(0.008, 0.003, 0.001), yellow});
  }
}

}  // namespace

engine::Scene live_scene(const PerceptionProtocol& protocol) {
  engine::Scene scene;
  scene.name = "perception-threshold";
  engine::Entity cylinder;
  cylinder.body = haptics::SceneObject::half_cylinder("cylinder", protocol.cylinder_radius_m,
                                                      0.5 * protocol.cylinder_length_m, Pose{});
  cylinder.body.rgba = {0.72f, 0.72f, 0.76f, 1.0f};
  cylinder.physics = engine::Physics::none;  // contact is the analytic law, not the simulation
  scene.entities.push_back(cylinder);
  // Until the hook places it: where it sits for a standing viewer at the origin.
  const PlacedScene placed = PlacedScene::place(protocol, Pose{Quat::Identity(), Vec3(0, 1.6, 0)});
  scene.entities[kCylinderEntity].body.T_world_object = placed.cylinder.T_world_object;
  scene.p_focus_in_world = placed.cylinder.T_world_object * Vec3(0, protocol.cylinder_radius_m, 0);
  return scene;
}

Result<std::unique_ptr<LiveExperiment>> LiveExperiment::create(const PerceptionProtocol& protocol,
                                                               const study::StudyDesign& design,
                                                               const study::SessionOptions& session,
                                                               std::unique_ptr<ForceChannel> channel) {
  if (auto s = protocol.validate(); !s) return s.error();
  std::unique_ptr<LiveExperiment> e(new LiveExperiment());
  e->protocol_ = protocol;
  e->design_ = design;
  auto opened = study::Session::open(e->design_, session);
  if (!opened) return opened.error();
  e->session_.emplace(std::move(*opened));
  e->channel_ = std::move(channel);
  if (e->channel_) e->force_thread_ = std::thread([p = e.get()] { p->force_loop(); });
  return e;
}

LiveExperiment::~LiveExperiment() {
  stop_.store(true);
  if (force_thread_.joinable()) force_thread_.join();
}

Status LiveExperiment::status() const {
  if (error_) return *error_;
  return {};
}
int LiveExperiment::completed_trials() const { return session_ ? session_->completed_trials() : 0; }
int LiveExperiment::planned_trials() const { return session_ ? session_->planned_trials() : 0; }

void LiveExperiment::force_loop() {
  // Sleeps to absolute 1 ms deadlines; the gate's rate limiter smooths the
  // frame-rate updates of the finger.
  const Clock& clock = MonotonicClock::instance();
  TimeNs next = clock.now_ns();
  HapticTarget target;
  bool engaged = false;
  while (!stop_.load()) {
    next += kNsPerMillisecond;
    std::this_thread::sleep_until(std::chrono::steady_clock::time_point(std::chrono::nanoseconds(next)));
    const TimeNs now = clock.now_ns();
    if (const HapticTarget* t = haptic_target_.read()) target = *t;
    const bool active = target.active && now - target.time_ns < kStaleTargetNs;
    if (active && !engaged) channel_->engage(now);
    engaged = engaged || active;
    haptics::FingertipForce desired;
    if (active) {
      const auto c = haptics::sphere_on_half_cylinder(protocol_.contact_law(), target.cylinder,
                                                      target.p_centre_in_world, protocol_.fingertip_radius_m,
                                                      target.q_world_tip);
      if (c.in_contact) desired = c.on_pad;
    }
    channel_->update(desired, now);
    felt_force_n_.store(channel_->felt().in_tip_frame().norm());
  }
  channel_->disengage(clock.now_ns());
}

void LiveExperiment::start_trial(TimeNs now) {
  auto trial = session_->next_trial();
  if (!trial) {
    error_ = trial.error();
    return;
  }
  auto p = make_presentation(*trial, design_, session_->participant_seed());
  if (!p) {
    error_ = p.error();
    return;
  }
  trial_ = *trial;
  presentation_ = *p;
  stage_ = Stage::trial;
  stage_start_ns_ = now;
  next_cue_ns_ = 0;
  peak_force_n_ = 0;
}

void LiveExperiment::on_frame(engine::FrameContext& f) {
  on_frame_uncalibrated(f);
  // Eq. 2.1: a point commanded at p_cmd appears at T_hmd_graphics * p_cmd
  // (head frame), so command the inverse of where it should appear.
  const Pose T_graphics_hmd = T_hmd_graphics_.inverse();
  for (auto& m : f.markers) {
    const Pose T_head_marker = f.T_world_head.inverse() * m.T_world_marker;
    m.T_world_marker = f.T_world_head * (T_graphics_hmd * T_head_marker);
  }
}

void LiveExperiment::on_frame_uncalibrated(engine::FrameContext& f) {
  const TimeNs now = f.time_ns;
  f.show_hands = false;  // the participant sees spheres, not a hand
  if (error_) {
    f.prompt = "Error: " + error_->message;
    f.stop = true;
    return;
  }
  const bool tracked = f.tracked && f.tracked->active;
  const Pose T_world_tip = tracked ? f.tracked->joint(HandJoint::index_tip) : Pose{};
  const auto haptic_off = [&] { haptic_target_.publish(HapticTarget{}); };
  peak_force_n_ = std::max(peak_force_n_, felt_force_n_.load());

  switch (stage_) {
    case Stage::waiting_for_hand:
      f.prompt = "Put on the fingertip device and hold your index finger in view";
      if (tracked) {
        // The scene is placed in the head frame as it is now, levelled.
        scene_ = PlacedScene::place(protocol_, f.T_world_head);
        f.entities[kCylinderEntity].T_world_entity = scene_.cylinder.T_world_object;
        stage_ = Stage::familiarisation;
        stage_start_ns_ = now;
      }
      haptic_off();
      return;
    case Stage::familiarisation: {
      const double t = static_cast<double>(now - stage_start_ns_) * 1e-9;
      if (tracked) f.markers.push_back(sphere_marker(drawn_sphere(protocol_, scene_, T_world_tip.p).p_in_world,
                                                     protocol_.fingertip_radius_m, protocol_.blue));
      f.prompt = fmt::format("Familiarisation: move your finger and touch the cylinder ({:.0f} s left; Enter to "
                             "start)", std::max(0.0, protocol_.familiarisation_s - t));
      haptic_off();  // the thesis's familiarisation has no haptic feedback
      bool enter = false;
      for (const auto& k : f.keys) enter = enter || k == "enter";
      if (enter || t >= protocol_.familiarisation_s) start_trial(now);
      return;
    }
    case Stage::trial:
    case Stage::answering: {
      if (session_->finished()) {
        stage_ = Stage::done;
        stage_start_ns_ = now;
        return;
      }
      const double t = static_cast<double>(now - stage_start_ns_) * 1e-9;
      const Phase phase = phase_at(protocol_, t);
      if (phase == Phase::blind && now >= next_cue_ns_) {
        // Toward the centre line of the view as the head is now.
        cue_ = tracked ? blind_cue(f.T_world_head.inverse() * T_world_tip.p,
                                   protocol_.cue_dead_zone_deg * kPi / 180.0)
                       : Cue::none;
        next_cue_ns_ = now + static_cast<DurationNs>(protocol_.cue_update_s * 1e9);
      }
      f.show_scene = phase != Phase::blind;
      if (!tracked) {
        f.prompt = "Hand not tracked";
        haptic_off();
        return;
      }
      const TrialView view = trial_view(protocol_, scene_, presentation_, phase, T_world_tip.p, cue_);
      for (const auto& s : view.spheres) {
        f.markers.push_back(sphere_marker(s.p_in_world, protocol_.fingertip_radius_m,
                                          s.blue ? protocol_.blue : protocol_.red));
      }
      add_arrow(f, view.cue);
      haptic_target_.publish(HapticTarget{view.p_haptic_centre_in_world.has_value(),
                                          view.p_haptic_centre_in_world.value_or(Vec3::Zero()), T_world_tip.q, now,
                                          scene_.cylinder});
      if (phase != Phase::answer) return;
      stage_ = Stage::answering;
      f.prompt = "Swipe with each sphere, then: B = blue is my finger, R = red, Space = another look";
      for (const auto& k : f.keys) {
        if (k == "space") {  // the same trial again from its adaptation phase
          stage_ = Stage::trial;
          stage_start_ns_ = now;
          next_cue_ns_ = 0;
          return;
        }
        if (k == "b" || k == "r") {
          const bool chose_blue = k == "b";
          study::Response r;
          fill_response_columns(presentation_, chose_blue == presentation_.true_is_blue, peak_force_n_, r);
          r.response_time_s = t - protocol_.adaptation_s - protocol_.blind_s;
          if (auto s = session_->record(*trial_, r); !s) {
            error_ = s.error();
            return;
          }
          haptic_off();
          if (session_->finished()) {
            stage_ = Stage::done;
            stage_start_ns_ = now;
          } else {
            start_trial(now);
          }
          return;
        }
      }
      return;
    }
    case Stage::done:
      haptic_off();
      f.prompt = fmt::format("Done: {} answers saved. Thank you!", session_->completed_trials());
      f.stop = static_cast<double>(now - stage_start_ns_) * 1e-9 > 3.0;
      return;
  }
}

}  // namespace proprio::perception
