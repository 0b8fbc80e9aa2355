#pragma once
// Soft tissue: a glove's markers and IMUs sit on skin and fabric, not on bone.
// Three effects move each mount from the place the glove as built gives it
// (glove_as_built.hpp covers the per-glove and per-donning placement):
//
// - Sliding with the joints. Flexing a joint by theta lengthens the skin at
//   height h above its axis by about h * theta (the dorsal skin over a knuckle
//   stretches; the palmar side folds). The skin on both sides slides toward
//   the joint to supply part of it, most near the joint: a mount at distance d
//   from a joint moves toward it by
//       sliding_gain * h * theta * exp(-d / sliding_decay_m)
//   along the bone (h signed: dorsal mounts are pulled toward a flexing joint,
//   palmar ones pushed away). Ryu et al. 2006 (J Biomech 39(5):844-852)
//   measured dorsal skin moving over the phalanges with flexion in MR images,
//   most near the joints; our gain and decay length are ASSUMPTIONS of that
//   order (about 2-3 mm next to a knuckle flexed 80 degrees, a few tenths of a
//   millimetre mid-bone), not a fit to their data.
// - Wobble. The skin and glove patch over each bone is a damped spring to it
//   (the wobbling-mass picture of soft-tissue artefacts; Leardini et al. 2005,
//   Gait Posture 21(2):212-225): x'' + 2 zeta w x' + w^2 x = -f, f the
//   specific force of the bone (acceleration minus gravity) in the segment
//   frame. It sags under gravity by g / w^2 and rings after quick stops.
//   Wakeling & Nigg 2001 (J Appl Physiol 90(2):412-420) measured soft-tissue
//   vibration at 10-50 Hz with damping ratios of a few tenths in the leg; for
//   the thin tissue of a finger we ASSUME 20 Hz (+-15 % per segment and
//   donning) and zeta = 0.3: 0.6 mm of sag, 1.7x amplification at resonance.
// - Slip. Over a session the glove creeps: per segment, an Ornstein-Uhlenbeck
//   walk along the bone and sideways, starting at zero at donning, with a
//   stationary sigma of 1 mm and a 5-minute time constant (ASSUMED).
//
// Everything is deterministic in t: sliding and slip are functions of the
// pose and t; wobble is integrated on a fixed grid from t = 0 with the exact
// zero-order-hold discretisation and interpolated (cubic Hermite) between grid
// points, so any query order gives the same answer (a query older than the
// kept history restarts the integration). Each effect draws from its own
// stream of the seed.
#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <vector>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio::sim {

struct SoftTissueOptions {
  bool sliding = true;
  double sliding_gain = 0.3;       // share of h * theta each side's skin supplies by sliding
  double sliding_decay_m = 0.010;  // how far from the joint the sliding reaches (1/e)

  bool wobble = true;
  double wobble_frequency_hz = 20.0;
  double wobble_frequency_spread = 0.15;  // per segment: uniform in +-this fraction, drawn per donning
  double wobble_damping_ratio = 0.3;
  double wobble_step_s = 1e-3;   // integration grid
  double wobble_history_s = 2.0;  // kept for queries into the past

  bool slip = true;
  double slip_sigma_m = 0.001;          // stationary 1-sigma per axis (along the bone, sideways)
  double slip_time_constant_s = 300.0;  // mean reversion
  double slip_knot_s = 1.0;             // the walk's knots; smooth (Catmull-Rom) between them

  // Mounts rigid on the bone: the idealised simulator of the first wave.
  static SoftTissueOptions rigid();
  bool any() const noexcept { return sliding || wobble || slip; }
  Status validate() const;  // Errc::invalid_argument naming the field
  std::string describe() const;
};

// A marker or IMU on a segment. p_in_segment is in the frame of the hand the
// simulator wears unless `mirrored`: then it is given for the other hand (x
// mirrored), as StereoMarkerSimulator's places are, and offsets come back in
// that same convention.
struct SkinMount {
  HandJoint segment = HandJoint::wrist;
  Vec3 p_in_segment = Vec3::Zero();
  bool mirrored = false;
};

using SoftTissuePoseFunction = std::function<HandPose(TimeNs)>;

class SoftTissue {
 public:
  // `poses` is the hand's motion (deterministic in t, as for ImuSimulator);
  // wobble samples it on its grid. Errors: invalid options, no pose function,
  // a mount on a tip (tips are not segments).
  static Result<SoftTissue> create(SoftTissuePoseFunction poses, std::vector<SkinMount> mounts,
                                   SoftTissueOptions options, std::uint64_t seed);

  // Where mount i has moved from its place at time t, the hand then in `pose`
  // (what poses(t) returns), in its segment frame. Not thread-safe (wobble
  // integrates lazily).
  Vec3 offset(std::size_t mount, const HandPose& pose, TimeNs t);
  // Every mount's offset, in mount order.
  void offsets(const HandPose& pose, TimeNs t, std::vector<Vec3>& out);

  // The effects one by one (segment frame of the worn hand, unmirrored), for
  // tests and the ablation; each is zero when switched off.
  Vec3 sliding(std::size_t mount, const HandPose& pose) const;
  Vec3 wobble(HandJoint segment, TimeNs t);
  Vec3 slip(HandJoint segment, TimeNs t) const;
  double wobble_frequency_hz(HandJoint segment) const;

  const std::vector<SkinMount>& mounts() const noexcept { return mounts_; }
  const SoftTissueOptions& options() const noexcept { return options_; }

 private:
  // A joint a mount's skin spans: flexion of `child` relative to `parent`
  // about the parent's x axis, the joint at child's origin.
  struct SpannedJoint {
    HandJoint parent = HandJoint::wrist;
    HandJoint child = HandJoint::wrist;
    bool mount_on_child = false;  // the mount is distal to the joint
  };
  struct WobbleSegment {
    HandJoint segment = HandJoint::wrist;
    Vec3 centre_in_segment = Vec3::Zero();  // mean of its mounts: where the bone drives the patch
    double omega_radps = 0.0;
    Eigen::Matrix2d phi = Eigen::Matrix2d::Identity();  // exact ZOH step of [x, v]
    Eigen::Vector2d gamma = Eigen::Vector2d::Zero();
  };
  struct WobbleState {
    std::vector<Vec3> x, v;  // per wobble segment, segment frame
  };
  SoftTissue(SoftTissuePoseFunction poses, std::vector<SkinMount> mounts, SoftTissueOptions options,
             std::uint64_t seed);
  void wobble_restart();
  void wobble_advance();  // one grid step
  Vec3 specific_force(std::size_t w, const HandPose& before, const HandPose& at, const HandPose& after) const;
  std::size_t wobble_index(HandJoint segment) const;

  SoftTissuePoseFunction poses_;
  std::vector<SkinMount> mounts_;
  std::vector<std::vector<SpannedJoint>> spans_;  // per mount
  SoftTissueOptions options_;
  std::uint64_t seed_ = 0;
  double step_s_ = 1e-3;
  TimeNs step_ns_ = 1000000;
  std::vector<WobbleSegment> wobble_segments_;
  // Grid states k0_ .. k0_ + history_.size() - 1, and the poses at the newest
  // grid point and the one before it (the second difference needs three).
  std::deque<WobbleState> history_;
  std::int64_t k0_ = 0;
  HandPose pose_prev_, pose_newest_;
  // Slip knots per patch (along the bone, sideways), knot j at j * slip_knot_s,
  // drawn lazily from each patch's own stream.
  mutable std::vector<std::vector<Eigen::Vector2d>> slip_knots_;
  mutable std::vector<Rng> slip_rngs_;
  void slip_extend(std::size_t w, std::size_t knots) const;
};

}  // namespace proprio::sim
