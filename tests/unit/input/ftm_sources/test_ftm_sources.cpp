// The FTM glove's live sources (issue 27 §4): the simulated wearer in real
// time, the same wearer behind the emulated board and the real driver, and a
// board that is not there. Bounds are generous (several times what the chain
// measures off-line): they catch a broken stage, not a small regression.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "proprio/ftm_sources/ftm_sources.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/hid/hid_transport.hpp"
#include <unistd.h>

namespace proprio::ftm_sources {
namespace ftm_sources_test {

void fs_sleep_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }

// Mean distance (m) of index, middle and thumb tips from the truth file's
// rows looked up in the source at the rows' times (rows the source has).
struct FsTipError {
  double mean_m = 0.0;
  int rows = 0;
};

FsTipError fs_compare_with_truth(HandSource& source, Handedness hand, const std::filesystem::path& truth_csv) {
  std::ifstream in(truth_csv);
  std::string line;
  std::getline(in, line);  // header
  // Column layout: time_ns, hand, then per joint x y z qw qx qy qz (sim::HandTruthWriter).
  FsTipError out;
  double sum = 0.0;
  while (std::getline(in, line)) {
    std::vector<double> v;
    std::size_t pos = 0;
    while (pos <= line.size()) {
      const std::size_t comma = line.find(',', pos);
      const std::string cell = line.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
      v.push_back(std::strtod(cell.c_str(), nullptr));
      if (comma == std::string::npos) break;
      pos = comma + 1;
    }
    if (v.size() < 2 + 7 * kHandJointCount) continue;  // a row still being written
    const auto t = static_cast<TimeNs>(v[0]);
    HandPose est;
    if (source.lookup(hand, t, est) != PoseLookup::exact && source.lookup(hand, t, est) != PoseLookup::interpolated) {
      continue;
    }
    for (HandJoint j : {HandJoint::index_tip, HandJoint::middle_tip, HandJoint::thumb_tip}) {
      const std::size_t c = 2 + 7 * index_of(j);
      const Vec3 truth(v[c], v[c + 1], v[c + 2]);
      sum += (est.T_world_joint[index_of(j)].p - truth).norm();
    }
    ++out.rows;
  }
  if (out.rows > 0) out.mean_m = sum / (3.0 * out.rows);
  return out;
}

TEST(FtmSources, SimSourceServesPosesCloseToTheTruth) {
  const auto truth = std::filesystem::temp_directory_path() / ("ftm_sources_sim_truth_" + std::to_string(::getpid()) + ".csv");
  FtmSimSourceOptions o;
  o.seed = 5;
  o.task_s = 30.0;
  o.truth_path = truth;
  auto source = make_sim_ftm_source(o);
  ASSERT_TRUE(source.ok()) << source.error().message;
  EXPECT_EQ((*source)->name(), "ftm");
  fs_sleep_ms(1500);
  EXPECT_TRUE((*source)->available(Handedness::right));
  EXPECT_FALSE((*source)->available(Handedness::left));
  const auto stats = (*source)->live_stats();
  EXPECT_GT(stats.source.poses_published, 200u);  // the calibration's warm-up plus ~1.5 s at 200 Hz
  EXPECT_EQ(stats.source.poses_rejected, 0u);
  const FsTipError err = fs_compare_with_truth(**source, Handedness::right, truth);
  source->reset();
  std::printf("sim source: fingertip error %.1f mm over %d truth rows\n", 1e3 * err.mean_m, err.rows);
  EXPECT_GT(err.rows, 50);
  EXPECT_LT(err.mean_m, 0.04);
  std::filesystem::remove(truth);
}

TEST(FtmSources, EmulatedSourceSurvivesAnUnplug) {
  FtmEmulatedSourceOptions o;
  o.wearer.seed = 6;
  o.wearer.task_s = 30.0;
  o.faults.unplugs.push_back({400 * kNsPerMillisecond, 300 * kNsPerMillisecond});
  auto source = make_emulated_ftm_source(o);
  ASSERT_TRUE(source.ok()) << source.error().message;
  // Before the unplug: streaming.
  fs_sleep_ms(300);
  EXPECT_TRUE((*source)->available(Handedness::right));
  const auto before = (*source)->live_stats().source.poses_published;
  // During it: the source goes stale.
  fs_sleep_ms(350);
  EXPECT_FALSE((*source)->available(Handedness::right));
  // After it the board boots and the driver finds it again.
  bool back = false;
  for (int i = 0; i < 60 && !back; ++i) {
    fs_sleep_ms(50);
    back = (*source)->available(Handedness::right);
  }
  EXPECT_TRUE(back);
  const auto after = (*source)->live_stats();
  EXPECT_GT(after.source.poses_published, before);
  EXPECT_TRUE(after.have_device);
  EXPECT_GE(after.device.connects, 2u);  // once at the start, once after the unplug
  HandPose pose;
  EXPECT_NE((*source)->lookup(Handedness::right, MonotonicClock::instance().now_ns(), pose), PoseLookup::empty);
}

TEST(FtmSources, BoardSourceWithNoBoardStartsUnavailable) {
  const auto cal = std::filesystem::temp_directory_path() / ("ftm_sources_cal_" + std::to_string(::getpid()) + ".toml");
  ASSERT_TRUE(ftm::save_ftm_calibration(cal, ftm::nominal_ftm_calibration(Handedness::right, 0.19, 0.10)).ok());
  FtmDeviceSourceOptions o;
  o.calibration = cal;
  auto link = std::make_shared<hid::FakeHidLink>();
  link->unplug_for(3600 * kNsPerSecond);  // nothing on the other end
  auto source = make_board_ftm_source(std::make_unique<hid::FakeHidTransport>(link), o);
  ASSERT_TRUE(source.ok()) << source.error().message;
  fs_sleep_ms(200);
  EXPECT_FALSE((*source)->available(Handedness::right));
  HandPose pose;
  EXPECT_EQ((*source)->lookup(Handedness::right, MonotonicClock::instance().now_ns(), pose), PoseLookup::empty);
  EXPECT_EQ((*source)->live_stats().source.poses_published, 0u);
  source->reset();
  std::filesystem::remove(cal);

  FtmDeviceSourceOptions none;
  auto refused = make_board_ftm_source(std::make_unique<hid::FakeHidTransport>(link), none);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("calibration"), std::string::npos);
}

}  // namespace ftm_sources_test
}  // namespace proprio::ftm_sources
