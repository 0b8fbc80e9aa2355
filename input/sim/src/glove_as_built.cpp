#include "proprio/sim/glove_as_built.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "proprio/core/random.hpp"

namespace proprio::sim {

Status GloveBuildErrors::validate() const {
  auto bad = [](const char* what, double v, const char* range) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "glove build errors: %s is %g; it must be %s", what, v, range);
    return make_error(Errc::invalid_argument, buf);
  };
  if (!(per_glove_m >= 0.0 && per_glove_m <= 0.02)) return bad("per_glove_m", per_glove_m, "in 0..0.02 m");
  if (!(per_donning_m >= 0.0 && per_donning_m <= 0.02)) return bad("per_donning_m", per_donning_m, "in 0..0.02 m");
  if (!(diameter_fraction >= 0.0 && diameter_fraction <= 0.3)) {
    return bad("diameter_fraction", diameter_fraction, "in 0..0.3");
  }
  return {};
}

std::string GloveBuildErrors::describe() const {
  char buf[96];
  std::snprintf(buf, sizeof buf, "per_glove=%.1fmm per_donning=%.1fmm diameter=%.0f%%", per_glove_m * 1e3,
                per_donning_m * 1e3, diameter_fraction * 100.0);
  return buf;
}

namespace {

// A surface offset (along, across/around) in metres.
struct Shift {
  double along_m = 0.0;
  double across_m = 0.0;
};

Shift draw_shift(Rng& rng, double sigma_m) { return {sigma_m * rng.normal(), sigma_m * rng.normal()}; }

// Length of the bone that starts at `segment` and the skin radius on it, on this hand at rest.
struct BoneSize {
  double length_m = 0.04;
  double radius_m = 0.008;
};

BoneSize bone_size(const HandPose& rest, HandJoint segment) {
  const std::size_t i = index_of(segment);
  BoneSize b;
  if (i + 1 < kHandJointCount) b.length_m = std::max(0.01, (rest.T_world_joint[i + 1].p - rest.T_world_joint[i].p).norm());
  b.radius_m = std::max(0.004, rest.radius_m[i]);
  return b;
}

}  // namespace

ImuGloveDescription glove_as_built(const ImuGloveDescription& drawn, const HandShape& shape,
                                   const GloveBuildErrors& errors, std::uint64_t glove_seed,
                                   std::uint64_t donning_seed) {
  ImuGloveDescription built = drawn;
  if (!errors.any()) return built;
  const HandPose rest = HandModel(shape).forward(Handedness::right, HandAngles{}, Pose{}, 0);
  // One donning shift per segment, drawn in the segments' order so adding a
  // marker does not move the others' shifts.
  std::map<HandJoint, Shift> donning;
  {
    Rng rng(mix_seed(donning_seed, 1));
    for (HandJoint s : drawn.segments()) donning[s] = draw_shift(rng, errors.per_donning_m);
  }
  // Moves a place given as (along fraction, across fraction or around angle) by `d` metres.
  auto move = [&](HandJoint segment, double& along_fraction, double& across, bool around_in_deg, const Shift& d) {
    if (segment == HandJoint::wrist) {
      along_fraction = std::clamp(along_fraction + d.along_m / shape.hand_length_m, 0.0, 1.0);
      across = std::clamp(across + d.across_m / shape.hand_width_m, -0.5, 0.5);
      return;
    }
    const BoneSize b = bone_size(rest, segment);
    along_fraction = std::clamp(along_fraction + d.along_m / b.length_m, 0.0, 1.0);
    if (around_in_deg) across = std::clamp(across + rad_to_deg(d.across_m / b.radius_m), -180.0, 180.0);
  };
  Rng glove_rng(mix_seed(glove_seed, 2));
  for (MarkerSpec& m : built.markers) {
    const Shift g = draw_shift(glove_rng, errors.per_glove_m);
    const double diameter_factor = 1.0 + errors.diameter_fraction * glove_rng.normal();
    const Shift& d = donning[m.segment];
    const Shift total{g.along_m + d.along_m, g.across_m + d.across_m};
    if (m.segment == HandJoint::wrist) {
      move(m.segment, m.along_fraction, m.across_fraction, false, total);
    } else {
      move(m.segment, m.along_fraction, m.around_deg, true, total);
    }
    m.diameter_m *= std::clamp(diameter_factor, 0.7, 1.3);
  }
  for (ImuMount& u : built.imus) {
    const Shift g = draw_shift(glove_rng, errors.per_glove_m);
    const Shift& d = donning[u.segment];
    const Shift total{g.along_m + d.along_m, g.across_m + d.across_m};
    // IMUs sit on the back of a finger bone (the format has no around angle
    // for them): there only the along part moves them; `move` leaves `across` alone.
    move(u.segment, u.along_fraction, u.across_fraction, false, total);
  }
  return built;
}

}  // namespace proprio::sim
