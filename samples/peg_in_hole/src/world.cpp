#include "proprio/peg_in_hole/world.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "proprio/core/data_dir.hpp"
#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"

namespace proprio::peg_in_hole {

Result<std::shared_ptr<const haptics::FingertipDeviceModel>> load_device_model(const PegInHoleConfig& config) {
  const std::filesystem::path path = config.devices.model.empty()
                                         ? std::filesystem::path(data_path("haptics/platform_3dof.toml"))
                                         : config.devices.model;
  auto m = haptics::load_device_model(path);
  if (!m) return m.error().with_context("peg-in-hole fingertip device model");
  return std::shared_ptr<const haptics::FingertipDeviceModel>(std::move(*m));
}

haptics::ContactSimOptions contact_sim_options(const PegInHoleConfig& config) {
  haptics::ContactSimOptions o;
  o.coupling.joint_stiffness_nm_per_rad = config.devices.finger_joint_stiffness_nm_per_rad;
  // Critically damped at the new stiffness (contact_sim.hpp: 2 sqrt(k I)).
  o.coupling.joint_damping_nms_per_rad =
      2.0 * std::sqrt(o.coupling.joint_stiffness_nm_per_rad * o.coupling.joint_armature_kg_m2);
  o.solver_tolerance = config.devices.solver_tolerance;
  o.torsional_friction = config.devices.torsional_friction;
  return o;
}

haptics::ServoLoopOptions servo_loop_options(const PegInHoleConfig& config, Setting setting) {
  haptics::ServoLoopOptions o;
  // With the FTM the tracker removes the abduction (the thesis's way), so
  // the servo must not remove it a second time.
  o.remove_finger_abduction = !setting.abduction && config.tracker != SimTracker::ftm;
  o.haptics_enabled = setting.haptics;
  o.force_scale = config.devices.force_scale;
  return o;
}

PegWorld::PegWorld(const PegInHoleConfig& config, const TrialLayout& layout, Setting setting, WorldPhase phase)
    : config_(config),
      layout_(layout),
      setting_(setting),
      phase_(phase),
      hole_(hole_geometry(config, layout.p_hole_in_world)),
      monitor_(config.peg.break_force_n, config.peg.break_filter_time_constant_s) {}

Result<std::unique_ptr<PegWorld>> PegWorld::create(const PegInHoleConfig& config, const TrialLayout& layout,
                                                   Setting setting, const HandModel& hand_model,
                                                   std::shared_ptr<const haptics::FingertipDeviceModel> device_model,
                                                   WorldPhase phase) {
  if (Status s = config.validate(); !s) return s.error();
  if (!device_model) return make_error(Errc::invalid_argument, "PegWorld needs a fingertip device model");
  std::unique_ptr<PegWorld> w(new PegWorld(config, layout, setting, phase));
  haptics::HapticScene scene = trial_scene(config, layout);
  if (const haptics::SceneObject* table = scene.find("table")) {
    w->p_table_in_world_ = table->T_world_object.p;
    w->table_half_extents_m_ = table->half_extents_m;
  }
  if (phase != WorldPhase::trial) {
    // Familiarisation has no hole to finish in.
    std::erase_if(scene.objects, [](const haptics::SceneObject& o) { return o.name == "hole_plate"; });
  }
  auto sim = haptics::ContactSimulation::create(hand_model, Handedness::right, scene, contact_sim_options(config));
  if (!sim) return sim.error().with_context("peg-in-hole scene");
  if (phase == WorldPhase::spring) {
    const FamiliarisationOptions& f = config.familiarisation;
    if (Status s = sim->place_object("peg", Pose{peg_spawn_pose(config, Vec3::Zero()).q,
                                                 f.spring_anchor_m - Vec3(0, 0.5 * config.peg.length_m, 0)});
        !s) {
      return s.error();
    }
    if (Status s = sim->set_object_spring("peg", f.spring_anchor_m - Vec3(0, 0.5 * config.peg.length_m, 0),
                                          f.spring_stiffness_n_per_m, f.spring_damping_ns_per_m);
        !s) {
      return s.error();
    }
  }
  std::vector<haptics::ServoChannel> channels;
  for (Finger f : config.devices.fingers) {
    devices::FingertipEmulatorOptions eo = haptics::emulator_options_for(*device_model);
    eo.physics_substeps = static_cast<std::uint32_t>(config.devices.emulator_substeps);
    auto dev = haptics::EmulatedFingertip::create(device_model, eo);
    if (!dev) return dev.error().with_context("emulated fingertip device");
    std::shared_ptr<haptics::EmulatedFingertip> shared_dev(std::move(*dev));
    w->devices_.emplace_back(f, shared_dev);
    channels.push_back({f, device_model, shared_dev});
  }
  haptics::ServoLoopOptions so = servo_loop_options(config, setting);
  so.realtime_priority = false;  // stepped in simulated time, no thread
  auto loop = haptics::ServoLoop::create(std::move(*sim), std::move(channels), so);
  if (!loop) return loop.error();
  w->servo_ = std::move(*loop);
  w->now_ns_ = 0;
  w->start_ns_ = 0;
  w->servo_->engage(0);
  if (auto p = w->servo_->simulation().object_pose("peg")) w->peg_pose_ = *p;
  return w;
}

std::array<double, kFingerCount> PegWorld::device_current_a() const noexcept {
  std::array<double, kFingerCount> out{};
  for (const auto& [finger, dev] : devices_) {
    const auto& snap = dev->emulator().snapshot();
    double sum = 0.0;
    for (const auto& m : snap.motors) sum += std::abs(m.current_a);
    out[static_cast<std::size_t>(finger)] = sum;
  }
  return out;
}

void PegWorld::submit_hand(const Pose& T_world_wrist, const HandAngles& angles) {
  servo_->submit_tracked_hand(now_ns_, T_world_wrist, angles);
}

double PegWorld::elapsed_s() const noexcept { return 1e-9 * static_cast<double>(now_ns_ - start_ns_); }

std::array<float, 4> PegWorld::peg_rgba() const noexcept {
  return peg_colour(monitor_.filtered_n(), config_.peg.colour_scale_max_n, monitor_.broken());
}

void PegWorld::respawn() {
  haptics::ContactSimulation& sim = servo_->simulation();
  if (phase_ == WorldPhase::spring) {
    const Vec3 p = config_.familiarisation.spring_anchor_m - Vec3(0, 0.5 * config_.peg.length_m, 0);
    (void)sim.place_object("peg", Pose{peg_spawn_pose(config_, Vec3::Zero()).q, p});
  } else {
    (void)sim.place_object("peg", peg_spawn_pose(config_, layout_.p_peg_start_in_world));
  }
  monitor_.reset();
  ++respawns_;
  idle_since_ns_ = -1;
}

PegEvent PegWorld::step() {
  now_ns_ += kNsPerMillisecond;
  servo_->tick(now_ns_);
  if (const haptics::ServoSnapshot* s = servo_->latest()) snapshot_ = *s;
  if (auto p = servo_->simulation().object_pose("peg")) peg_pose_ = *p;

  const double force = grasp_force_n(snapshot_.hands[0].object_normal_n);
  if (std::isfinite(force)) {
    peak_force_n_ = std::max(peak_force_n_, force);
    if (force > 0.05) {
      force_sum_ += force;
      ++contact_ticks_;
    }
  }
  PegEvent ev{PegEvent::Kind::none, now_ns_};
  if (monitor_.broken()) {
    if (1e-9 * static_cast<double>(now_ns_ - broken_at_ns_) >= config_.peg.respawn_delay_s) {
      respawn();
      ev.kind = PegEvent::Kind::respawned;
    }
    return ev;
  }
  if (monitor_.update(now_ns_, force)) {
    ++breaks_;
    broken_at_ns_ = now_ns_;
    return {PegEvent::Kind::broke, now_ns_};
  }
  if (phase_ == WorldPhase::trial) {
    insertion_ = insertion_state(peg_pose_, 0.5 * config_.peg.length_m, hole_);
    if (insertion_.inserted && !inserted_) {
      inserted_ = true;
      return {PegEvent::Kind::inserted, now_ns_};
    }
  }
  if (config_.peg.respawn_dropped && phase_ != WorldPhase::spring) {
    // Fell off the table, or rests untouched for a second not standing
    // (more than 18 deg from upright: on its side, or leaning on the hole's
    // plate), a bottle the experimenter stands up again. A free standing
    // bottle of this shape falls past 15 deg, so nothing rests in between.
    const double table = config_.layout.table_height_m;
    const bool not_standing = std::abs(peg_axis(peg_pose_).y()) < 0.95;
    const bool untouched = force < 0.05;
    // Beyond the table's edges a held peg is fine; a let-go one would fall
    // (the table's contact plane has no edges to fall from).
    const Vec3 p_peg_in_table = peg_pose_.p - p_table_in_world_;
    const bool beyond_edge = std::abs(p_peg_in_table.x()) > table_half_extents_m_.x() ||
                             std::abs(p_peg_in_table.z()) > table_half_extents_m_.z();
    const bool fell_off = peg_pose_.p.y() < table - 0.05 || (beyond_edge && untouched);
    if (not_standing && untouched && !insertion_.inserted) {
      if (idle_since_ns_ < 0) idle_since_ns_ = now_ns_;
    } else {
      idle_since_ns_ = -1;
    }
    if (fell_off || (idle_since_ns_ >= 0 && now_ns_ - idle_since_ns_ > kNsPerSecond)) {
      ++drops_;
      respawn();
      return {PegEvent::Kind::dropped, now_ns_};
    }
  }
  return ev;
}

}  // namespace proprio::peg_in_hole
