// The simulated wearer calibrated through proprio::ftm's real calibration,
// then tracked by an FtmHandSource: the whole chain a simulated FTM user gets.
// Bounds are generous (a few times what the chain measures): they catch a
// broken stage, not a regression of a tenth of a degree.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/ftm/ftm_hand_source.hpp"
#include "proprio/ftm_sim/wearer_calibration.hpp"

namespace proprio::ftm_sim {
namespace wearer_calibration_test {

TEST(WearerCalibration, CalibratesThenTracksTheWearerThroughTheHandSource) {
  FtmWearerOptions o;
  o.seed = 11;
  o.task_s = 6.0;
  auto sim = FtmWearerSimulator::create(o);
  ASSERT_TRUE(sim.ok()) << sim.error().message;
  auto cal = calibrate_from_wearer(**sim);
  ASSERT_TRUE(cal.ok()) << cal.error().message;
  ASSERT_FALSE(cal->events.empty());
  EXPECT_LT(cal->events.back().time_ns(), (*sim)->task_begin_ns());
  // The calibrated mountings are what the simulator drew, to within the
  // imperfectly held poses (several degrees), never the nominal identity
  // by accident: at least one IMU was mounted measurably off.
  for (const auto& b1 : cal->outcome.calibration.beta1_rad_per_pF) EXPECT_GT(b1, 0.0);

  ftm::FtmHandSourceOptions so;
  so.tracker.hand = o.hand;
  auto source = ftm::FtmHandSource::create(so, cal->outcome.calibration);
  ASSERT_TRUE(source.ok()) << source.error().message;
  for (const auto& e : cal->events) (*source)->push(e);

  std::vector<ftm::FtmEvent> task;
  (*sim)->advance((*sim)->end_ns(), task);
  double error_sum = 0.0;
  int n = 0;
  TimeNs next = (*sim)->task_begin_ns() + kNsPerSecond;
  for (const auto& e : task) {
    if (!(*source)->push(e) || e.time_ns() < next) continue;
    next += 50 * kNsPerMillisecond;
    HandPose est;
    ASSERT_EQ((*source)->lookup(o.hand, e.time_ns(), est), PoseLookup::exact);
    const auto truth = (*sim)->truth_at(e.time_ns());
    const auto& angles = (*source)->tracker().angles();
    for (HandDof d : ftm::kFtmTrackedDofs) {
      ASSERT_TRUE(std::isfinite(angles[index_of(d)]));
      error_sum += std::abs(angles[index_of(d)] - truth.angles[index_of(d)]);
      ++n;
    }
    EXPECT_NE(est.flags[index_of(HandJoint::index_tip)] & kPositionValid, 0);
  }
  ASSERT_GT(n, 9 * 50);
  const double mean_deg = rad_to_deg(error_sum / n);
  std::printf("mean tracked-DOF error over the task: %.2f deg (%d samples)\n", mean_deg, n);
  EXPECT_LT(mean_deg, 12.0);
  const auto stats = (*source)->stats();
  EXPECT_GT(stats.poses_published, 500u);
  EXPECT_EQ(stats.poses_rejected, 0u);
}

}  // namespace wearer_calibration_test
}  // namespace proprio::ftm_sim
