// The vist plugin's live inputs through start_hand_source, as the OpenXR
// layer starts them: "device" starts without a board or a camera and serves
// an inactive hand; "emulated" renders from the host's head pose
// (TrackedPoseProvider) and writes the wearer's truth; configuration errors
// fail the start. Accuracy is tests/unit/input/vist_eval's business.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>

#include "proprio/hand_sources/hand_sources.hpp"
#include "proprio/sim/hand_truth_writer.hpp"
#include "support/temp_dir.hpp"

namespace proprio::hand_sources::vist_plugin_test {
namespace {

using namespace std::chrono_literals;
using openxr_layer::ReferenceSpace;
using openxr_layer::SourceConfig;
using openxr_layer::SourceType;
using testing_support::TempDir;

class CountingHead final : public TrackedPoseProvider {
 public:
  bool locate(TrackedPose what, TimeNs, Pose& T_world_x) noexcept override {
    calls.fetch_add(1);
    if (what != TrackedPose::head) return false;
    T_world_x = {Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
    return true;
  }
  std::atomic<std::uint64_t> calls{0};
};

SourceConfig live_vist(const std::string& input) {
  SourceConfig sc;
  sc.type = SourceType::vist;
  sc.space = ReferenceSpace::local;
  sc.input = input;
  sc.hands = {Handedness::right};
  return sc;
}

bool eventually(const std::function<bool()>& pred, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(10ms);
  }
  return true;
}

TEST(VistPlugin, ADeviceSourceStartsWithoutItsDevicesAndServesAnInactiveHand) {
  SourceConfig sc = live_vist("device");
  sc.camera = "/dev/video_proprio_test_absent";
  sc.imu_serial = "proprio-test-no-such-board";
  CountingHead head;
  auto source = start_hand_source(sc, 50 * kNsPerMillisecond, &head);
  ASSERT_TRUE(source) << source.error().message;
  EXPECT_TRUE((*source)->available(Handedness::right));
  for (int i = 0; i < 20; ++i) {
    HandPose pose;
    const PoseLookup r = (*source)->lookup(Handedness::right, MonotonicClock::instance().now_ns(), pose);
    EXPECT_FALSE(is_usable(r) && pose.active);
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_EQ(head.calls.load(), 0u) << "no frame, so no head pose asked for";
  source->reset();
}

TEST(VistPlugin, LiveConfigurationErrorsFailTheStart) {
  TempDir dir;
  SourceConfig sc = live_vist("device");
  sc.camera = "/dev/video_proprio_test_absent";
  sc.glove_description = (dir / "no_glove.toml").string();
  auto no_glove = start_hand_source(sc, 0);
  ASSERT_FALSE(no_glove);
  EXPECT_NE(no_glove.error().message.find("no_glove.toml"), std::string::npos) << no_glove.error().message;

  sc = live_vist("device");
  sc.camera = (dir / "no_video.avi").string();
  EXPECT_FALSE(start_hand_source(sc, 0));

  sc = live_vist("emulated");
  sc.hands = {Handedness::left, Handedness::right};
  auto two = start_hand_source(sc, 0);
  ASSERT_FALSE(two);
  EXPECT_NE(two.error().message.find("one glove"), std::string::npos) << two.error().message;

  sc = live_vist("emulated");
  sc.subject = 99;
  EXPECT_FALSE(start_hand_source(sc, 0));
}

TEST(VistPlugin, AnEmulatedSourceSeesTheHostsHeadAndWritesTheTruth) {
  TempDir dir;
  SourceConfig sc = live_vist("emulated");
  sc.subject = 2;
  sc.seed = 4;
  sc.truth_path = (dir / "truth.csv").string();
  CountingHead head;
  auto source = start_hand_source(sc, 50 * kNsPerMillisecond, &head);
  ASSERT_TRUE(source) << source.error().message;
  ASSERT_TRUE(eventually([&] { return head.calls.load() >= 5; }, 30s)) << "each rendered frame asks for the head";
  std::this_thread::sleep_for(300ms);
  source->reset();  // stops the rig: the truth file is complete
  std::ifstream csv(sc.truth_path);
  std::string header, row;
  ASSERT_TRUE(std::getline(csv, header));
  EXPECT_EQ(header + "\n", sim::HandTruthWriter::header());
  int rows = 0;
  while (std::getline(csv, row)) {
    EXPECT_NE(row.find(",right,"), std::string::npos) << row.substr(0, 80);
    ++rows;
  }
  EXPECT_GT(rows, 10) << "the board ticks at 100 Hz, one truth row each";
}

}  // namespace
}  // namespace proprio::hand_sources::vist_plugin_test
