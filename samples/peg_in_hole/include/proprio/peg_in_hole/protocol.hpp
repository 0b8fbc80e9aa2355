#pragma once
// The protocol's randomisation: which setting each of the 20 trials gets
// (four settings, each round of four in random order, rounds repeated), and
// where the peg starts and the hole sits in each trial. Both are pure
// functions of the config, the participant and the seed (proprio::Rng).
#include <cstdint>
#include <optional>
#include <string>

#include "proprio/core/result.hpp"
#include "proprio/haptics/scene.hpp"
#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/ftm_glove.hpp"
#include "proprio/study/design.hpp"
#include "proprio/study/session.hpp"

namespace proprio::peg_in_hole {

// The study design as proprio::study sees it: factors round x haptics x aa,
// blocked by round (file order), each round's four cells shuffled; the
// stimulus is the hole clearance (mm), the response "completed".
std::string study_design_toml(const PegInHoleConfig& config);
Result<study::StudyDesign> study_design(const PegInHoleConfig& config);
// The setting of a session trial (its levels: round, haptics, aa).
Setting setting_of(const std::vector<std::string>& levels);

// The per-trial CSV columns the sample adds (docs/peg-in-hole.md).
const std::vector<std::string>& trial_columns();

struct TrialLayout {
  Vec3 p_peg_start_in_world = Vec3::Zero();  // the peg's base centre
  Vec3 p_hole_in_world = Vec3::Zero();       // centre of the hole's opening
};
// Trial `trial_index` of the participant whose session seed is participant_seed.
TrialLayout trial_layout(const PegInHoleConfig& config, std::uint64_t participant_seed, int trial_index);

// What a finished trial measured, live or simulated.
struct TrialMeasures {
  bool completed = false;   // inserted before the timeout
  double time_s = 0.0;      // clock running through breaks
  int breaks = 0, drops = 0;
  double peak_force_n = 0.0, mean_force_n = 0.0;
  std::string recording;    // relative path of the trial's .prec, or empty
  std::string participant_kind;  // "real" or "simulated"
  // The simulated FTM glove's figures (--tracker ftm); empty columns without.
  std::optional<FtmTrialFigures> ftm;
};
// The trial's CSV row (trial_columns()).
study::Response trial_response(const PegInHoleConfig& config, int trial_index, const Setting& setting,
                               const TrialLayout& layout, const TrialMeasures& m);

// The haptic scene of a trial: table, upright peg at its start, the plate
// with the hole. The peg's pose for a (re)spawn:
haptics::HapticScene trial_scene(const PegInHoleConfig& config, const TrialLayout& layout);
Pose peg_spawn_pose(const PegInHoleConfig& config, const Vec3& p_base_in_world);

}  // namespace proprio::peg_in_hole
