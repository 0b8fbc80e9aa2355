#include "proprio/perception_threshold/protocol.hpp"

#include <fmt/format.h>

#include <cmath>

#include "proprio/core/config.hpp"
#include "proprio/core/data_dir.hpp"

namespace proprio::perception {
namespace {

constexpr double kDegToRad = kPi / 180.0;
// Sub-streams of a participant's seed (the study library uses stream 1 for its plan).
constexpr std::uint64_t kPresentationStream = 1000;

Status positive(double v, const char* name) {
  if (!(std::isfinite(v) && v > 0.0)) {
    return make_error(Errc::invalid_argument, fmt::format("{} must be a positive number, not {}", name, v));
  }
  return {};
}
Status non_negative(double v, const char* name) {
  if (!(std::isfinite(v) && v >= 0.0)) {
    return make_error(Errc::invalid_argument, fmt::format("{} must be >= 0, not {}", name, v));
  }
  return {};
}

}  // namespace

std::string ObserverParams::describe() const {
  return fmt::format("observer: proprioceptive noise {:.2f} cm (x exp(N(0, {:.2f})) per participant), decision noise "
                     "{:.2f}, haptic weight {:.2f} (noise {:.2f}), lapse {:.3f}, motor noise {:.2f} cm",
                     proprioceptive_noise_cm, between_participant_sd, decision_noise, haptic_weight, haptic_noise,
                     lapse, motor_noise_cm);
}

Status ObserverParams::validate() const {
  for (auto s : {positive(proprioceptive_noise_cm, "observer.proprioceptive_noise_cm"),
                 non_negative(decision_noise, "observer.decision_noise"),
                 non_negative(haptic_weight, "observer.haptic_weight"),
                 non_negative(haptic_noise, "observer.haptic_noise"),
                 non_negative(between_participant_sd, "observer.between_participant_sd"),
                 non_negative(motor_noise_cm, "observer.motor_noise_cm")}) {
    if (!s) return s;
  }
  if (!(lapse >= 0.0 && lapse < 1.0)) {
    return make_error(Errc::invalid_argument, fmt::format("observer.lapse must be in [0, 1), not {}", lapse));
  }
  return {};
}

haptics::ContactLawOptions PerceptionProtocol::contact_law() const {
  haptics::ContactLawOptions law;
  law.onset_force_n = onset_force_n;
  law.stiffness_n_per_m = stiffness_n_per_cm * 100.0;  // N/cm -> N/m
  law.max_force_n = max_force_n;
  return law;
}

Pose PerceptionProtocol::T_head_cylinder() const {
  // Horizontal, axis pointing away from the participant, curved side up: the
  // cylinder's axes are {H}'s axes.
  return {Quat::Identity(), head_point_from_spherical(cylinder_r_m, cylinder_azimuth_deg * kDegToRad,
                                                      cylinder_elevation_deg * kDegToRad)};
}

std::string PerceptionProtocol::describe() const {
  return fmt::format(
      "perception threshold protocol:\n"
      "  scene: fingertip sphere r = {:.1f} cm; half cylinder r = {:.1f} cm, length {:.1f} cm, centre at "
      "(r, theta, phi) = ({:.1f} cm, {:.1f} deg, {:.1f} deg) in the head frame\n"
      "  phases: familiarisation {:.0f} s, adaptation {:.1f} s, blind {:.1f} s (arrow every {:.1f} s, dead zone "
      "{:.1f} deg), answer until answered\n"
      "  contact force: {:.2f} N at onset + {:.3f} N/cm x penetration, at most {:.2f} N\n"
      "  design: {}\n  {}",
      fingertip_radius_m * 100, cylinder_radius_m * 100, cylinder_length_m * 100, cylinder_r_m * 100,
      cylinder_azimuth_deg, cylinder_elevation_deg, familiarisation_s, adaptation_s, blind_s, cue_update_s,
      cue_dead_zone_deg, onset_force_n, stiffness_n_per_cm, max_force_n, design_file.string(), observer.describe());
}

Status PerceptionProtocol::validate() const {
  for (auto s : {positive(fingertip_radius_m, "scene.fingertip_radius_cm"),
                 positive(cylinder_radius_m, "scene.cylinder_radius_cm"),
                 positive(cylinder_length_m, "scene.cylinder_length_cm"), positive(cylinder_r_m, "scene.cylinder_r_cm"),
                 non_negative(familiarisation_s, "phases.familiarisation_s"), positive(adaptation_s, "phases.adaptation_s"),
                 positive(blind_s, "phases.blind_s"), positive(cue_update_s, "phases.cue_update_s"),
                 non_negative(cue_dead_zone_deg, "phases.cue_dead_zone_deg"),
                 non_negative(onset_force_n, "haptics.onset_force_n"),
                 non_negative(stiffness_n_per_cm, "haptics.stiffness_n_per_cm"),
                 positive(max_force_n, "haptics.max_force_n")}) {
    if (!s) return s;
  }
  if (std::abs(cylinder_azimuth_deg) > 180 || std::abs(cylinder_elevation_deg) > 90) {
    return make_error(Errc::invalid_argument, "scene.cylinder_azimuth_deg must be in [-180, 180] and "
                                              "scene.cylinder_elevation_deg in [-90, 90]");
  }
  return observer.validate();
}

PerceptionProtocol PerceptionProtocol::defaults() {
  PerceptionProtocol p;
  p.design_file = data_path("studies/perception_threshold.toml");
  return p;
}

PerceptionProtocol PerceptionProtocol::defaults(const std::filesystem::path& source_dir) {
  PerceptionProtocol p;
  p.design_file = source_dir / "config/studies/perception_threshold.toml";
  return p;
}

Result<PerceptionProtocol> PerceptionProtocol::load_file(const std::filesystem::path& path) {
  auto c = Config::load_file(path);
  if (!c) return c.error();
  if (auto s = c->check_keys("top level", {"design", "scene", "phases", "haptics", "observer"}); !s) {
    return s.error();
  }
  PerceptionProtocol p;
  auto design = c->get_string("design");
  if (!design) return design.error().with_context(path.string() + ": the protocol must name its study design");
  p.design_file = std::filesystem::path(*design).is_absolute() ? std::filesystem::path(*design)
                                                                : path.parent_path() / *design;
  // Each optional value keeps the published default when absent.
  auto read = [](const Config& t, const char* key, double& value, double lo, double hi, double scale) -> Status {
    auto v = t.get_double_or(key, value / scale, lo, hi);
    if (!v) return v.error();
    value = *v * scale;
    return {};
  };
  if (c->contains("scene")) {
    auto t = c->table("scene");
    if (!t) return t.error();
    if (auto s = t->check_keys("scene", {"fingertip_radius_cm", "cylinder_radius_cm", "cylinder_length_cm",
                                               "cylinder_r_cm", "cylinder_azimuth_deg", "cylinder_elevation_deg"});
        !s) {
      return s.error();
    }
    for (auto s : {read(*t, "fingertip_radius_cm", p.fingertip_radius_m, 0.1, 10, 0.01),
                   read(*t, "cylinder_radius_cm", p.cylinder_radius_m, 1, 200, 0.01),
                   read(*t, "cylinder_length_cm", p.cylinder_length_m, 1, 400, 0.01),
                   read(*t, "cylinder_r_cm", p.cylinder_r_m, 5, 200, 0.01),
                   read(*t, "cylinder_azimuth_deg", p.cylinder_azimuth_deg, -180, 180, 1),
                   read(*t, "cylinder_elevation_deg", p.cylinder_elevation_deg, -90, 90, 1)}) {
      if (!s) return s.error();
    }
  }
  if (c->contains("phases")) {
    auto t = c->table("phases");
    if (!t) return t.error();
    if (auto s = t->check_keys("phases", {"familiarisation_s", "adaptation_s", "blind_s", "cue_update_s",
                                                "cue_dead_zone_deg"});
        !s) {
      return s.error();
    }
    for (auto s : {read(*t, "familiarisation_s", p.familiarisation_s, 0, 3600, 1),
                   read(*t, "adaptation_s", p.adaptation_s, 0.1, 600, 1), read(*t, "blind_s", p.blind_s, 0.1, 600, 1),
                   read(*t, "cue_update_s", p.cue_update_s, 0.05, 60, 1),
                   read(*t, "cue_dead_zone_deg", p.cue_dead_zone_deg, 0, 45, 1)}) {
      if (!s) return s.error();
    }
  }
  if (c->contains("haptics")) {
    auto t = c->table("haptics");
    if (!t) return t.error();
    if (auto s = t->check_keys("haptics", {"onset_force_n", "stiffness_n_per_cm", "max_force_n"}); !s) {
      return s.error();
    }
    for (auto s : {read(*t, "onset_force_n", p.onset_force_n, 0, 10, 1),
                   read(*t, "stiffness_n_per_cm", p.stiffness_n_per_cm, 0, 100, 1),
                   read(*t, "max_force_n", p.max_force_n, 0.01, 20, 1)}) {
      if (!s) return s.error();
    }
  }
  if (c->contains("observer")) {
    auto t = c->table("observer");
    if (!t) return t.error();
    if (auto s = t->check_keys("observer", {"proprioceptive_noise_cm", "decision_noise", "haptic_weight",
                                                  "haptic_noise", "lapse", "between_participant_sd", "motor_noise_cm"});
        !s) {
      return s.error();
    }
    ObserverParams& o = p.observer;
    for (auto s : {read(*t, "proprioceptive_noise_cm", o.proprioceptive_noise_cm, 0.01, 100, 1),
                   read(*t, "decision_noise", o.decision_noise, 0, 100, 1),
                   read(*t, "haptic_weight", o.haptic_weight, 0, 100, 1),
                   read(*t, "haptic_noise", o.haptic_noise, 0, 100, 1), read(*t, "lapse", o.lapse, 0, 0.5, 1),
                   read(*t, "between_participant_sd", o.between_participant_sd, 0, 2, 1),
                   read(*t, "motor_noise_cm", o.motor_noise_cm, 0, 10, 1)}) {
      if (!s) return s.error();
    }
  }
  if (auto s = p.validate(); !s) return s.error().with_context(path.string());
  return p;
}

Vec3 head_point_from_spherical(double r_m, double azimuth_rad, double elevation_rad) {
  return r_m * Vec3(std::cos(elevation_rad) * std::sin(azimuth_rad), std::sin(elevation_rad),
                    -std::cos(elevation_rad) * std::cos(azimuth_rad));
}

Pose level_head(const Pose& T_world_head) {
  const Vec3 forward = T_world_head.q * Vec3(0, 0, -1);
  const double yaw = std::atan2(-forward.x(), -forward.z());
  return {Quat(Eigen::AngleAxisd(yaw, Vec3::UnitY())), T_world_head.p};
}

const char* to_string(HapticTarget t) noexcept {
  switch (t) {
    case HapticTarget::none: return "none";
    case HapticTarget::true_sphere: return "true_sphere";
    case HapticTarget::false_sphere: return "false_sphere";
  }
  return "?";
}

Result<HapticTarget> parse_haptic_target(const std::string& level) {
  if (level == "none") return HapticTarget::none;
  if (level == "true_sphere") return HapticTarget::true_sphere;
  if (level == "false_sphere") return HapticTarget::false_sphere;
  return make_error(Errc::invalid_argument, "haptics level '" + level + "': expected none, true_sphere or "
                                            "false_sphere");
}

Result<TrialPresentation> make_presentation(const study::Trial& trial, const study::StudyDesign& design,
                                            std::uint64_t participant_seed) {
  TrialPresentation p;
  std::size_t factor = design.factors.size();
  for (std::size_t i = 0; i < design.factors.size(); ++i) {
    if (design.factors[i].name == "haptics") factor = i;
  }
  if (factor == design.factors.size() || factor >= trial.levels.size()) {
    return make_error(Errc::invalid_argument, "the perception-threshold design needs a factor named 'haptics' "
                                              "(levels none, true_sphere, false_sphere)");
  }
  auto haptic = parse_haptic_target(trial.levels[factor]);
  if (!haptic) return haptic.error();
  p.haptic = *haptic;
  // The design's stimulus is the offset in its stated unit.
  const double scale = design.stimulus_unit == "m" ? 1.0 : design.stimulus_unit == "mm" ? 0.001 : 0.01;
  p.offset_m = trial.stimulus * scale;
  if (!(std::isfinite(p.offset_m) && p.offset_m >= 0.0)) {
    return make_error(Errc::invalid_argument, fmt::format("trial {}: offset {} is not a distance", trial.index,
                                                          trial.stimulus));
  }
  Rng rng(mix_seed(participant_seed, kPresentationStream + static_cast<std::uint64_t>(trial.index)));
  Vec3 u;
  do {
    u = Vec3(rng.normal(), rng.normal(), rng.normal());
  } while (u.norm() < 1e-6);
  p.u_offset_in_world = u.normalized();
  p.true_is_blue = rng.below(2) == 0;
  return p;
}

const char* to_string(Phase p) noexcept {
  switch (p) {
    case Phase::adaptation: return "adaptation";
    case Phase::blind: return "blind";
    case Phase::answer: return "answer";
  }
  return "?";
}

Phase phase_at(const PerceptionProtocol& protocol, double t) {
  if (t < protocol.adaptation_s) return Phase::adaptation;
  if (t < protocol.adaptation_s + protocol.blind_s) return Phase::blind;
  return Phase::answer;
}

const char* to_string(Cue c) noexcept {
  switch (c) {
    case Cue::none: return "none";
    case Cue::up: return "up";
    case Cue::down: return "down";
    case Cue::left: return "left";
    case Cue::right: return "right";
  }
  return "?";
}

Cue blind_cue(const Vec3& p, double dead_zone_rad) {
  // The larger of the two angular errors decides, so the finger converges on
  // the centre line without the arrow flickering between axes.
  const double azimuth = std::atan2(p.x(), -p.z());
  const double elevation = std::atan2(p.y(), std::hypot(p.x(), p.z()));
  if (std::max(std::abs(azimuth), std::abs(elevation)) <= dead_zone_rad) return Cue::none;
  if (std::abs(azimuth) >= std::abs(elevation)) return azimuth > 0 ? Cue::left : Cue::right;
  return elevation > 0 ? Cue::down : Cue::up;
}

PlacedScene PlacedScene::place(const PerceptionProtocol& protocol, const Pose& T_world_head_now) {
  PlacedScene s;
  s.T_world_head = level_head(T_world_head_now);
  const Pose T_head_cyl = protocol.T_head_cylinder();
  s.cylinder.T_world_object = {s.T_world_head.q * T_head_cyl.q, s.T_world_head * T_head_cyl.p};
  s.cylinder.radius_m = protocol.cylinder_radius_m;
  s.cylinder.half_length_m = 0.5 * protocol.cylinder_length_m;
  return s;
}

DrawnSphere drawn_sphere(const PerceptionProtocol& protocol, const PlacedScene& scene, const Vec3& p_centre) {
  DrawnSphere d;
  d.contact = haptics::sphere_on_half_cylinder(protocol.contact_law(), scene.cylinder, p_centre,
                                               protocol.fingertip_radius_m, scene.T_world_head.q);
  d.p_in_world = d.contact.in_contact ? Vec3(p_centre + d.contact.penetration_m * d.contact.n_in_world) : p_centre;
  return d;
}

void fill_response_columns(const TrialPresentation& p, bool chose_true, double peak_force_n, study::Response& r) {
  r.correct = chose_true;
  if (p.haptic != HapticTarget::none) {
    const bool chose_haptic = (p.haptic == HapticTarget::true_sphere) == chose_true;
    r.extra["chose_haptic_sphere"] = chose_haptic ? "1" : "0";
  }
  r.extra["true_sphere_colour"] = p.true_is_blue ? "blue" : "red";
  r.extra["offset_direction"] =
      fmt::format("{:.4f} {:.4f} {:.4f}", p.u_offset_in_world.x(), p.u_offset_in_world.y(), p.u_offset_in_world.z());
  r.extra["peak_force_n"] = fmt::format("{:.3f}", peak_force_n);
}

}  // namespace proprio::perception
