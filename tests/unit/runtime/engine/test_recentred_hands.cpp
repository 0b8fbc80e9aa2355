// RecentredHandSource: a source in its own coordinates moved into the scene
// by one translation, fixed at the first usable pose.
#include <gtest/gtest.h>

#include "proprio/engine/scripted_hands.hpp"

namespace proprio::engine {
namespace {

// A hand whose wrist moves 1 cm per second along x from p0; nothing before t = 1 s.
class DriftingHand final : public HandSource {
 public:
  explicit DriftingHand(Vec3 p0) : p0_(std::move(p0)) {}
  std::string_view name() const noexcept override { return "drifting"; }
  bool available(Handedness) const noexcept override { return true; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override {
    HandPose p;
    if (lookup(hand, t_ns, p) == PoseLookup::empty) return make_error(Errc::unavailable, "no pose yet");
    return p;
  }
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override {
    if (t_ns < kNsPerSecond) return PoseLookup::empty;
    out = HandPose{};
    out.hand = hand;
    out.time_ns = t_ns;
    out.active = true;
    const Vec3 drift(0.01 * static_cast<double>(t_ns) / kNsPerSecond, 0.0, 0.0);
    for (std::size_t j = 0; j < kHandJointCount; ++j) {
      out.T_world_joint[j] = Pose{Quat(Eigen::AngleAxisd(0.3, Vec3::UnitY())), p0_ + drift + Vec3(0, 0, -0.01 * j)};
    }
    return PoseLookup::exact;
  }

 private:
  Vec3 p0_;
};

TEST(RecentredHandSource, TheFirstWristLandsOnTheTargetAndTheOffsetStaysFixed) {
  auto inner = std::make_shared<DriftingHand>(Vec3(0.0, -0.3, -0.4));
  const Vec3 target(0.1, 1.08, -0.36);
  RecentredHandSource source(inner, target);
  HandPose pose;
  EXPECT_EQ(source.lookup(Handedness::right, 0, pose), PoseLookup::empty);
  EXPECT_TRUE(source.offset().isZero());

  ASSERT_EQ(source.lookup(Handedness::right, 2 * kNsPerSecond, pose), PoseLookup::exact);
  EXPECT_NEAR((pose.joint(HandJoint::wrist).p - target).norm(), 0.0, 1e-12);
  // The hand's shape and orientation are untouched: joints keep their spacing.
  EXPECT_NEAR((pose.T_world_joint[5].p - pose.T_world_joint[0].p).norm(), 0.05, 1e-12);
  EXPECT_NEAR(pose.joint(HandJoint::wrist).q.angularDistance(Quat(Eigen::AngleAxisd(0.3, Vec3::UnitY()))), 0.0, 1e-12);

  // Ten seconds later the hand has moved 10 cm in its own frame, and so it
  // does in the scene: the offset is not re-estimated.
  auto later = source.pose_at(Handedness::right, 12 * kNsPerSecond);
  ASSERT_TRUE(later);
  EXPECT_NEAR((later->joint(HandJoint::wrist).p - (target + Vec3(0.1, 0, 0))).norm(), 0.0, 1e-12);
}

TEST(RecentredHandSource, TheTargetIsAboveAndInFrontOfTheFocus) {
  Scene scene;
  scene.p_focus_in_world = Vec3(0.2, 0.9, -0.6);
  const Vec3 target = recentred_wrist_target(scene);
  EXPECT_GT(target.y(), scene.p_focus_in_world.y());
  EXPECT_GT(target.z(), scene.p_focus_in_world.z());  // towards the viewer (+Z)
  EXPECT_LT((target - scene.p_focus_in_world).norm(), 0.25);
}

}  // namespace
}  // namespace proprio::engine
