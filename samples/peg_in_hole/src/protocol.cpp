#include "proprio/peg_in_hole/protocol.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "proprio/core/random.hpp"

namespace proprio::peg_in_hole {

namespace {
// Sub-stream of the participant's seed for layouts (the plan uses stream 1,
// adaptive choices 1000+n: study/session.cpp).
constexpr std::uint64_t kLayoutStream = 0x5045474c41594f55ull;  // "PEGLAYOU"
}  // namespace

const std::vector<std::string>& trial_columns() {
  static const std::vector<std::string> columns = {
      "setting",        "setting_label",  "familiarisation", "completion_time_s", "timed_out",
      "breaks",         "drops",          "peak_force_n",    "mean_force_n",      "peg_start_x_m",
      "peg_start_z_m",  "hole_y_m",       "hole_z_m",        "recording",         "participant_kind",
      // The simulated FTM glove (--tracker ftm; empty otherwise), per IMU
      // in the order dorsum, thumb metacarpal, index proximal, middle proximal.
      "tracker", "ftm_max_disturbance_uT_dorsum", "ftm_max_disturbance_uT_thumb_mc", "ftm_max_disturbance_uT_index_pp",
      "ftm_max_disturbance_uT_middle_pp", "ftm_flagged_fraction_dorsum", "ftm_flagged_fraction_thumb_mc",
      "ftm_flagged_fraction_index_pp", "ftm_flagged_fraction_middle_pp", "ftm_disturbed_fraction_max",
      "ftm_max_device_current_a", "ftm_angle_error_deg", "ftm_wrist_error_mm"};
  return columns;
}

std::string study_design_toml(const PegInHoleConfig& c) {
  std::string rounds;
  for (int r = 1; r <= c.main_task.repetitions; ++r) rounds += fmt::format("{}\"{}\"", r > 1 ? ", " : "", r);
  std::string extra;
  for (const std::string& col : trial_columns()) extra += fmt::format("{}\"{}\"", extra.empty() ? "" : ", ", col);
  // Keys are documented in docs/study.md; "kind" selects the completion-time
  // analysis in `proprio study analyze`.
  return fmt::format(R"(# Generated from the peg-in-hole config (samples/peg_in_hole): Lee 2021 §3.3.3.
[study]
name = "{}"
kind = "completion-time"
description = "Peg-in-hole: completion time under {{with, without}} haptic feedback x {{with, without}} AA tracking"
seed = {}
stimulus = "clearance_mm"
stimulus_unit = "mm"
response = "completed"
extra_columns = [{}]

[[factor]]
name = "round"
levels = [{}]

[[factor]]
name = "haptics"
levels = ["on", "off"]

[[factor]]
name = "aa"
levels = ["on", "off"]

[blocks]
by = "round"
counterbalance = "none"

[procedure]
type = "constant"
levels = [{:.6g}]
repetitions = 1
)",
                     c.name, c.seed, extra, rounds, 1e3 * c.hole.clearance_m);
}

Result<study::StudyDesign> study_design(const PegInHoleConfig& config) {
  return study::StudyDesign::parse(study_design_toml(config), config.name + " (generated design)");
}

Setting setting_of(const std::vector<std::string>& levels) {
  Setting s;
  if (levels.size() >= 3) {
    s.haptics = levels[1] == "on";
    s.abduction = levels[2] == "on";
  }
  return s;
}

TrialLayout trial_layout(const PegInHoleConfig& c, std::uint64_t participant_seed, int trial_index) {
  Rng rng(mix_seed(mix_seed(participant_seed, kLayoutStream), static_cast<std::uint64_t>(trial_index)));
  const auto jitter = [&](const Vec3& range) {
    Vec3 v;
    for (int k = 0; k < 3; ++k) v[k] = range[k] > 0.0 ? rng.uniform(-range[k], range[k]) : 0.0;
    return v;
  };
  TrialLayout t;
  t.p_peg_start_in_world = c.layout.peg_start_m + jitter(c.layout.peg_start_range_m);
  t.p_hole_in_world = c.layout.hole_m + jitter(c.layout.hole_range_m);
  return t;
}

Pose peg_spawn_pose(const PegInHoleConfig& c, const Vec3& p_base_in_world) {
  const Quat q_upright(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitX()));  // object z (axis) along world +y
  return Pose{q_upright, p_base_in_world + Vec3(0, 0.5 * c.peg.length_m, 0)};
}

haptics::HapticScene trial_scene(const PegInHoleConfig& c, const TrialLayout& layout) {
  haptics::HapticScene::PegInHoleOptions o;
  o.peg_radius_m = c.peg.radius_m;
  o.peg_length_m = c.peg.length_m;
  o.peg_mass_kg = c.peg.mass_kg;
  o.clearance_m = c.hole.clearance_m;
  o.plate_thickness_m = c.hole.plate_thickness_m;
  o.p_peg_in_world = layout.p_peg_start_in_world;
  o.p_hole_in_world = layout.p_hole_in_world;
  o.table_height_m = c.layout.table_height_m;
  haptics::HapticScene scene = haptics::HapticScene::peg_in_hole(o);
  for (auto& obj : scene.objects) {
    if (obj.name == "peg") obj.friction = c.peg.friction;
  }
  return scene;
}

study::Response trial_response(const PegInHoleConfig& config, int trial_index, const Setting& setting,
                               const TrialLayout& layout, const TrialMeasures& m) {
  study::Response resp;
  resp.correct = m.completed;
  resp.response_time_s = m.time_s;
  auto& e = resp.extra;
  e["setting"] = std::to_string(setting.number());
  e["setting_label"] = setting.label();
  e["familiarisation"] = trial_index < config.main_task.familiarisation_trials ? "1" : "0";
  e["completion_time_s"] = fmt::format("{:.3f}", m.time_s);
  e["timed_out"] = m.completed ? "0" : "1";
  e["breaks"] = std::to_string(m.breaks);
  e["drops"] = std::to_string(m.drops);
  e["peak_force_n"] = fmt::format("{:.3f}", m.peak_force_n);
  e["mean_force_n"] = fmt::format("{:.3f}", m.mean_force_n);
  e["peg_start_x_m"] = fmt::format("{:.4f}", layout.p_peg_start_in_world.x());
  e["peg_start_z_m"] = fmt::format("{:.4f}", layout.p_peg_start_in_world.z());
  e["hole_y_m"] = fmt::format("{:.4f}", layout.p_hole_in_world.y());
  e["hole_z_m"] = fmt::format("{:.4f}", layout.p_hole_in_world.z());
  e["recording"] = m.recording;
  e["participant_kind"] = m.participant_kind;
  static const char* imu_names[] = {"dorsum", "thumb_mc", "index_pp", "middle_pp"};
  e["tracker"] = m.ftm ? "ftm" : (m.participant_kind == "simulated" ? "ideal" : "");
  double disturbed = 0.0, current = 0.0;
  if (m.ftm) {
    for (double d : m.ftm->disturbed_fraction) disturbed = std::max(disturbed, d);
    for (double c : m.ftm->max_current_a) current = std::max(current, c);
  }
  for (std::size_t i = 0; i < 4; ++i) {
    e[fmt::format("ftm_max_disturbance_uT_{}", imu_names[i])] = m.ftm ? fmt::format("{:.4f}", m.ftm->max_disturbance_uT[i]) : "";
    e[fmt::format("ftm_flagged_fraction_{}", imu_names[i])] = m.ftm ? fmt::format("{:.4f}", m.ftm->flagged_fraction[i]) : "";
  }
  e["ftm_disturbed_fraction_max"] = m.ftm ? fmt::format("{:.4f}", disturbed) : "";
  e["ftm_max_device_current_a"] = m.ftm ? fmt::format("{:.3f}", current) : "";
  e["ftm_angle_error_deg"] = m.ftm ? fmt::format("{:.2f}", m.ftm->mean_angle_error_deg) : "";
  e["ftm_wrist_error_mm"] = m.ftm ? fmt::format("{:.2f}", m.ftm->mean_wrist_error_mm) : "";
  return resp;
}

}  // namespace proprio::peg_in_hole
