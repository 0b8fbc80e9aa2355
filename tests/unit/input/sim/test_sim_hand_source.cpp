#include <gtest/gtest.h>

#include <thread>

#include "proprio/sim/sim_hand_source.hpp"

using namespace proprio;
using namespace proprio::sim;

TEST(SimHandSource, ServesInterpolatedPosesAtTheClocksTimes) {
  ManualClock clock(1'000 * kNsPerSecond);
  SimHandSourceOptions o;
  o.rate_hz = 0;  // driven by the test
  auto src = SimHandSource::create(o, clock);
  ASSERT_TRUE(src.ok()) << src.error().message;
  for (int k = 1; k <= 10; ++k) (*src)->produce(clock.now_ns() + k * 11'111'111);
  EXPECT_TRUE((*src)->available(Handedness::left));
  HandPose p;
  EXPECT_EQ((*src)->lookup(Handedness::right, clock.now_ns() + 50'000'000, p), PoseLookup::interpolated);
  EXPECT_TRUE(p.fully_valid());
  EXPECT_EQ(p.hand, Handedness::right);
  EXPECT_EQ((*src)->lookup(Handedness::right, clock.now_ns() - 1, p), PoseLookup::too_old);
  EXPECT_EQ((*src)->lookup(Handedness::left, clock.now_ns() + 111'111'110 + 20'000'000, p), PoseLookup::predicted);
  EXPECT_EQ((*src)->lookup(Handedness::left, clock.now_ns() + 5 * kNsPerSecond, p), PoseLookup::stale);
  auto err = (*src)->pose_at(Handedness::left, clock.now_ns() + 5 * kNsPerSecond);
  ASSERT_FALSE(err.ok());
  EXPECT_EQ(err.error().code, Errc::out_of_range);
}

TEST(SimHandSource, HeadRelativePosesAreInFrontOfTheViewer) {
  ManualClock clock(0);
  SimHandSourceOptions o;
  o.rate_hz = 0;
  o.hands = {Handedness::right};
  auto src = SimHandSource::create(o, clock);
  ASSERT_TRUE(src.ok());
  EXPECT_FALSE((*src)->available(Handedness::left));
  HandPose p;
  ASSERT_EQ((*src)->lookup(Handedness::right, 0, p), PoseLookup::exact);
  const Vec3 wrist = p.joint(HandJoint::wrist).p;
  EXPECT_LT(wrist.z(), -0.2) << "in front (-Z) of the head";
  EXPECT_LT(wrist.y(), 0.0) << "below eye level";
}

TEST(SimHandSource, ThreadProducesAtItsRateAndStopsCleanly) {
  SimHandSourceOptions o;
  o.rate_hz = 200;
  for (int round = 0; round < 5; ++round) {  // rapid create/destroy must not hang
    auto src = SimHandSource::create(o);
    ASSERT_TRUE(src.ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(60));
    HandPose p;
    // 30 ms in the past: inside the history even if a loaded machine delayed the thread.
    const auto r = (*src)->lookup(Handedness::left, MonotonicClock::instance().now_ns() - 30'000'000, p);
    EXPECT_TRUE(is_usable(r)) << static_cast<int>(r);
  }
}

TEST(SimHandSource, RejectsBadOptions) {
  SimHandSourceOptions o;
  o.subject = 42;
  EXPECT_FALSE(SimHandSource::create(o).ok());
  o.subject = 1;
  o.hands.clear();
  EXPECT_FALSE(SimHandSource::create(o).ok());
}
