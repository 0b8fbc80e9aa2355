#pragma once
// The perception-threshold experiment of Lee 2021 (seed 004, sections 2.2-2.4):
// which of two spheres is my fingertip? Everything the protocol fixes (scene
// geometry, phase timing, the contact force law) lives here with the thesis's
// values as defaults; the trial plan (conditions, offsets, repetitions,
// counterbalancing) is a proprio::study design file that the protocol names.
//
// Frames: {H} is the head frame at the session's start with pitch and roll
// removed (x right, y up, z backwards, as OpenXR's VIEW space). Spherical
// coordinates (r, azimuth theta, elevation phi) are taken in {H}: theta > 0 to
// the right, phi > 0 up. {C} is the half cylinder's frame: its axis is z
// (pointing away from the participant), its curved surface faces +y.
#include <array>
#include <filesystem>
#include <optional>
#include <string>

#include "proprio/core/math.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/haptics/force_laws.hpp"
#include "proprio/study/design.hpp"
#include "proprio/study/session.hpp"

namespace proprio::perception {

inline constexpr double kPi = 3.14159265358979323846;

// The simulated participant's parameters (observer.hpp; docs/perception-threshold.md).
struct ObserverParams {
  double proprioceptive_noise_cm = 1.63;  // sd of the felt fingertip position, per axis
  double decision_noise = 6.4;            // sd added to the log-likelihood ratio
  double haptic_weight = 2.4;             // log-likelihood ratio the felt contact adds for its sphere
  double haptic_noise = 0.0;              // sd of that evidence
  double lapse = 0.02;                    // probability of answering at random
  double between_participant_sd = 0.1;    // log-normal spread of the proprioceptive noise across participants
  double motor_noise_cm = 0.4;            // sd of the slow wander of the moving finger
  std::string describe() const;
  Status validate() const;
};

struct PerceptionProtocol {
  // Scene, in the thesis's units (section 2.2.2).
  double fingertip_radius_m = 0.01;
  double cylinder_radius_m = 0.25;
  double cylinder_length_m = 0.50;
  double cylinder_r_m = 0.45;             // centre of the cylinder in {H}: (r, theta, phi)
  double cylinder_azimuth_deg = 0.0;
  double cylinder_elevation_deg = -60.0;
  // Phases (section 2.3.2).
  double familiarisation_s = 120.0;       // live runs; the simulated observer does not learn
  double adaptation_s = 5.0;
  double blind_s = 3.0;
  double cue_update_s = 1.0;
  double cue_dead_zone_deg = 3.0;         // blind phase: no arrow when the finger is this close to the view centre
  // Contact force (section 2.4.2): F = onset + K * penetration, K in N/cm as published.
  double onset_force_n = 0.45;
  double stiffness_n_per_cm = 0.042;
  double max_force_n = 2.0;
  // Sphere colours, linear RGB; which one is the true sphere is random per trial.
  std::array<float, 4> blue{0.15f, 0.35f, 1.0f, 1.0f};
  std::array<float, 4> red{1.0f, 0.15f, 0.12f, 1.0f};
  ObserverParams observer;
  std::filesystem::path design_file;      // the study design (conditions, offsets, repetitions)

  haptics::ContactLawOptions contact_law() const;
  // The half cylinder's pose in {H}.
  Pose T_head_cylinder() const;
  std::string describe() const;
  Status validate() const;

  // The published protocol with the shipped studies/perception_threshold.toml
  // (proprio::data_path: installed, or the source tree's config/) as its design.
  static PerceptionProtocol defaults();
  // The same with <source_dir>/config/studies/perception_threshold.toml.
  static PerceptionProtocol defaults(const std::filesystem::path& source_dir);
  // A protocol file (config/samples/perception_threshold.toml documents the
  // keys); `design` is resolved relative to the file.
  static Result<PerceptionProtocol> load_file(const std::filesystem::path& path);
};

// (r, theta, phi) in {H} to a point in {H}.
Vec3 head_point_from_spherical(double r_m, double azimuth_rad, double elevation_rad);
// {H} for a head pose: the same position, yaw kept, pitch and roll removed.
Pose level_head(const Pose& T_world_head);

enum class HapticTarget { none, true_sphere, false_sphere };
const char* to_string(HapticTarget t) noexcept;
// From the design's "haptics" factor level.
Result<HapticTarget> parse_haptic_target(const std::string& level);

// What one trial shows: the false sphere's offset (a random direction on the
// sphere of radius `offset`), the colours, and where the haptic cue is.
struct TrialPresentation {
  double offset_m = 0.0;
  Vec3 u_offset_in_world = Vec3::UnitX();
  bool true_is_blue = true;
  HapticTarget haptic = HapticTarget::none;

  Vec3 p_false_in_world(const Vec3& p_true_in_world) const { return p_true_in_world + offset_m * u_offset_in_world; }
};
// Seeded by the participant's seed and the trial index, so a resumed session
// shows the same trial again.
Result<TrialPresentation> make_presentation(const study::Trial& trial, const study::StudyDesign& design,
                                            std::uint64_t participant_seed);

enum class Phase { adaptation, blind, answer };
const char* to_string(Phase p) noexcept;
Phase phase_at(const PerceptionProtocol& protocol, double t_in_trial_s);

// The blind phase's arrow: which way to move the finger toward the centre line
// of the view (theta = phi = 0), from the finger in the current head frame.
enum class Cue { none, up, down, left, right };
const char* to_string(Cue c) noexcept;
Cue blind_cue(const Vec3& p_finger_in_head, double dead_zone_rad);

// The scene in the world: the half cylinder placed in {H}.
struct PlacedScene {
  Pose T_world_head;       // {H}
  haptics::HalfCylinderShape cylinder;
  static PlacedScene place(const PerceptionProtocol& protocol, const Pose& T_world_head_now);
};

// A fingertip sphere as drawn: pushed out of the cylinder when it penetrates
// (the thesis removes penetration graphically), with the contact it makes.
struct DrawnSphere {
  Vec3 p_in_world = Vec3::Zero();
  haptics::AnalyticContact contact;
};
DrawnSphere drawn_sphere(const PerceptionProtocol& protocol, const PlacedScene& scene, const Vec3& p_centre_in_world);

// The trial's extra CSV columns (the design's extra_columns).
void fill_response_columns(const TrialPresentation& p, bool chose_true, double peak_force_n, study::Response& r);

}  // namespace proprio::perception
