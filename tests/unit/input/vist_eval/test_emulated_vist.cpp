// The emulated VIST rig behind the live wiring, in real time: a simulated
// wearer's IMU board served over the fake HID link to the real driver, its
// stereo camera rendered at each grab from a head that a fake XR runtime
// moves, the tracker's hand compared with the wearer's truth. Then the faults
// a live source must survive: the board unplugged and back, the camera
// unplugged and back, a runtime that never knows the head.
//
// Every wait is for a condition with a generous deadline; nothing asserts how
// long anything took. The camera renders at half the rig's resolution
// (EmulatedVistOptions::camera_scale) to keep the CPU load of a 2-core machine
// down.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "proprio/core/tracked_pose_provider.hpp"
#include "proprio/sim/hand_truth_writer.hpp"
#include "proprio/vist_eval/emulated_vist.hpp"
#include "support/temp_dir.hpp"

namespace proprio::vist_eval {
namespace {

using namespace std::chrono_literals;

// A headset the runtime tracks: standing off the origin, turned 30 degrees,
// swaying and turning its head a little (a few degrees, a few centimetres).
class MovingHead final : public TrackedPoseProvider {
 public:
  explicit MovingHead(bool known = true) : known_(known) {}
  bool locate(TrackedPose what, TimeNs t_ns, Pose& T_world_x) noexcept override {
    calls_.fetch_add(1, std::memory_order_relaxed);
    if (!known_ || what != TrackedPose::head) return false;
    const double s = ns_to_seconds(t_ns - t_start_);
    const Quat yaw(Eigen::AngleAxisd(deg_to_rad(30.0 + 4.0 * std::sin(0.5 * s)), Vec3::UnitY()));
    const Quat pitch(Eigen::AngleAxisd(deg_to_rad(3.0 * std::sin(0.7 * s)), Vec3::UnitX()));
    T_world_x = {yaw * pitch, Vec3(0.4 + 0.03 * std::sin(0.3 * s), 1.55 + 0.01 * std::sin(0.9 * s),
                                   -0.2 + 0.02 * std::cos(0.4 * s))};
    return true;
  }
  std::uint64_t calls() const { return calls_.load(); }

 private:
  bool known_;
  TimeNs t_start_ = MonotonicClock::instance().now_ns();
  std::atomic<std::uint64_t> calls_{0};
};

constexpr HandJoint kKeypoints[] = {HandJoint::palm, HandJoint::thumb_tip, HandJoint::index_tip, HandJoint::middle_tip};

EmulatedVistOptions test_options() {
  EmulatedVistOptions o;
  o.subject = 3;
  o.seed = 5;
  o.camera_scale = 0.5;
  return o;
}

vist::VistLiveSourceOptions source_options() {
  vist::VistLiveSourceOptions o;
  o.source.history.capacity = 2048;  // 20 s at 100 Hz: the whole run can be scored afterwards
  return o;
}

// Board driver options that notice an unplug and come back quickly.
devices::ImuGloveDeviceOptions quick_glove() {
  devices::ImuGloveDeviceOptions o;
  o.read_timeout_ns = 20 * kNsPerMillisecond;
  o.reconnect_backoff_min_ns = 5 * kNsPerMillisecond;
  o.reconnect_backoff_max_ns = 50 * kNsPerMillisecond;
  return o;
}

// The hand as the layer would ask for it now: usable and active.
bool tracked_now(vist::VistLiveSource& source, HandPose& pose) {
  const PoseLookup r = source.lookup(Handedness::right, MonotonicClock::instance().now_ns(), pose);
  return is_usable(r) && pose.active;
}

bool wait_for(const std::function<bool()>& pred, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(10ms);
  }
  return true;
}

struct Errors {
  std::vector<double> keypoint_mm, wrist_mm;
  std::vector<double> latency_ms;  // ready_time - data_time of the poses served
  double mean(const std::vector<double>& v) const {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
  }
  double p95(std::vector<double> v) const {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(0.95 * static_cast<double>(v.size() - 1))];
  }
};

// Live lookups at `now` for `seconds`, every 20 ms, against the truth at that time.
Errors score_live(vist::VistLiveSource& source, EmulatedVistRig& rig, double seconds) {
  Errors e;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    const TimeNs t = MonotonicClock::instance().now_ns();
    HandPose pose;
    const PoseLookup r = source.lookup(Handedness::right, t, pose);
    if (is_usable(r) && pose.active) {
      const HandPose truth = rig.truth_at(t);
      for (HandJoint j : kKeypoints) e.keypoint_mm.push_back(1e3 * (pose.joint(j).p - truth.joint(j).p).norm());
      e.wrist_mm.push_back(1e3 * (pose.joint(HandJoint::wrist).p - truth.joint(HandJoint::wrist).p).norm());
      if (pose.data_time_ns > 0 && pose.ready_time_ns > 0) {
        e.latency_ms.push_back(1e-6 * static_cast<double>(pose.ready_time_ns - pose.data_time_ns));
      }
    }
    std::this_thread::sleep_for(20ms);
  }
  return e;
}

TEST(EmulatedVist, TracksTheWearerWhileTheRuntimeMovesTheHead) {
  testing_support::TempDir dir;
  MovingHead head;
  EmulatedVistOptions o = test_options();
  o.truth_path = (dir / "truth.csv").string();
  auto emulated =
      start_emulated_vist(ImuGloveDescription::vist_default(), o, source_options(), vist::head_pose_provider(&head));
  ASSERT_TRUE(emulated) << emulated.error().message;
  auto& source = *emulated->source;
  auto& rig = *emulated->rig;

  HandPose pose;
  ASSERT_TRUE(wait_for([&] { return tracked_now(source, pose); }, 30s)) << source.live_stats().describe() << "\n"
                                                                        << rig.stats().describe();
  std::this_thread::sleep_for(2s);  // the filter's first calibration
  const Errors e = score_live(source, rig, 4.0);
  const EmulatedVistStats rs = rig.stats();
  const vist::VistLiveStats ls = source.live_stats();
  SCOPED_TRACE(ls.describe());
  SCOPED_TRACE(rs.describe());
  ASSERT_GT(e.keypoint_mm.size(), 100u) << "the hand was not tracked for most of the scoring";
  std::printf(
      "emulated VIST (camera %dx%d): keypoints mean %.2f mm, p95 %.2f mm; wrist mean %.2f mm; "
      "%zu poses scored; pose ready %.2f ms (mean) after its newest IMU sample\n  %s\n  %s\n",
      rig.glove().rig.camera.width_px, rig.glove().rig.camera.height_px, e.mean(e.keypoint_mm), e.p95(e.keypoint_mm),
      e.mean(e.wrist_mm), e.wrist_mm.size(), e.mean(e.latency_ms), rs.describe().c_str(), ls.describe().c_str());
  EXPECT_TRUE(rs.anchored) << "the wearer stands where the runtime's headset is";
  EXPECT_LT((rig.T_world_wearer().p - Vec3(0.4, 0.0, -0.2)).norm(), 0.1);
  EXPECT_EQ(ls.frames_without_head, 0u);
  EXPECT_GT(ls.frames, 0u);
  EXPECT_GT(head.calls(), 0u);
  // Measured on the 2-vCPU VM (lookups at "now", so predicted a little past
  // the newest IMU sample; three runs side by side): keypoints mean 2.4-2.8 mm,
  // p95 6.5-8.0 mm; wrist mean 0.5-0.6 mm. VIST's simulated evaluation (images
  // mode) reaches about 3 mm. The thresholds leave about three times that.
  EXPECT_LT(e.mean(e.keypoint_mm), 8.0);
  EXPECT_LT(e.p95(e.keypoint_mm), 20.0);
  EXPECT_LT(e.mean(e.wrist_mm), 5.0);

  // The truth file holds the same hand as truth_at.
  emulated->source.reset();
  const auto rig_alive = emulated->rig;
  std::ifstream csv(o.truth_path);
  std::string header, row;
  ASSERT_TRUE(std::getline(csv, header));
  EXPECT_EQ(header + "\n", sim::HandTruthWriter::header());
  int checked = 0;
  for (int i = 0; std::getline(csv, row) && checked < 5; ++i) {
    if (i % 300 != 299) continue;  // a few rows, after the wearer was placed
    std::stringstream ss(row);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 2u + 7u * kHandJointCount);
    const TimeNs t = std::stoll(cells[0]);
    const HandPose truth = rig_alive->truth_at(t);
    const std::size_t w = index_of(HandJoint::index_tip);
    const Vec3 p(std::stod(cells[2 + 7 * w]), std::stod(cells[3 + 7 * w]), std::stod(cells[4 + 7 * w]));
    if (t - rig_alive->time_zero_ns() < 2 * kNsPerSecond) continue;
    EXPECT_LT((p - truth.joint(HandJoint::index_tip).p).norm(), 1e-5) << "row at " << t;
    ++checked;
  }
  EXPECT_GT(checked, 0);
}

TEST(EmulatedVist, TheHandComesBackAfterTheBoardIsUnplugged) {
  MovingHead head;
  auto emulated = start_emulated_vist(ImuGloveDescription::vist_default(), test_options(), source_options(),
                                      vist::head_pose_provider(&head), quick_glove());
  ASSERT_TRUE(emulated) << emulated.error().message;
  auto& source = *emulated->source;
  auto& rig = *emulated->rig;
  HandPose pose;
  ASSERT_TRUE(wait_for([&] { return tracked_now(source, pose); }, 30s)) << source.live_stats().describe();

  rig.link().unplug_for(2 * kNsPerSecond);
  EXPECT_TRUE(wait_for([&] { return !tracked_now(source, pose); }, 5s)) << "no IMU data: the hand must go";
  EXPECT_TRUE(wait_for([&] { return source.live_stats().glove_state != hid::LinkState::streaming; }, 5s));
  ASSERT_TRUE(wait_for([&] { return tracked_now(source, pose); }, 30s)) << "the board is back: so must the hand\n"
                                                                        << source.live_stats().describe();
  std::this_thread::sleep_for(2s);
  const Errors e = score_live(source, rig, 2.0);
  const auto glove = source.input().glove_device().stats();
  SCOPED_TRACE(source.live_stats().describe());
  std::printf("after an unplug: keypoints mean %.2f mm over %zu poses; board %llu connects, %llu disconnects\n",
              e.mean(e.keypoint_mm), e.wrist_mm.size(), static_cast<unsigned long long>(glove.connects),
              static_cast<unsigned long long>(glove.disconnects));
  EXPECT_GE(glove.disconnects, 1u);
  EXPECT_GE(glove.connects, 2u);
  ASSERT_FALSE(e.keypoint_mm.empty());
  EXPECT_LT(e.mean(e.keypoint_mm), 8.0);  // measured 2.6-3.6 mm two seconds after the hand came back
}

TEST(EmulatedVist, TheHandComesBackAfterTheCameraIsUnplugged) {
  MovingHead head;
  EmulatedVistOptions o = test_options();
  o.camera_reopen_attempts = 1;
  o.camera_reopen_interval_s = 0.2;
  vist::VistLiveSourceOptions so = source_options();
  so.live.camera_retry_s = 0.2;
  auto emulated = start_emulated_vist(ImuGloveDescription::vist_default(), o, so, vist::head_pose_provider(&head));
  ASSERT_TRUE(emulated) << emulated.error().message;
  auto& source = *emulated->source;
  HandPose pose;
  ASSERT_TRUE(wait_for([&] { return tracked_now(source, pose); }, 30s)) << source.live_stats().describe();

  emulated->rig->unplug_camera_for(3 * kNsPerSecond);
  EXPECT_TRUE(wait_for([&] { return !tracked_now(source, pose); }, 5s))
      << "no frames: the hand must go (the IMUs alone drift)";
  EXPECT_TRUE(wait_for([&] { return !source.live_stats().camera_open; }, 10s)) << source.live_stats().describe();
  ASSERT_TRUE(wait_for([&] { return tracked_now(source, pose); }, 30s)) << "the camera is back: so must the hand\n"
                                                                        << source.live_stats().describe();
  EXPECT_GE(source.live_stats().camera_opens, 2u);
}

TEST(EmulatedVist, ARuntimeThatNeverKnowsTheHeadGivesNoHandAndNoCrash) {
  MovingHead head(/*known=*/false);
  auto emulated = start_emulated_vist(ImuGloveDescription::vist_default(), test_options(), source_options(),
                                      vist::head_pose_provider(&head));
  ASSERT_TRUE(emulated) << emulated.error().message;
  auto& source = *emulated->source;
  ASSERT_TRUE(wait_for([&] { return source.live_stats().frames_without_head >= 20; }, 30s))
      << source.live_stats().describe();
  HandPose pose;
  for (int i = 0; i < 50; ++i) {
    EXPECT_FALSE(tracked_now(source, pose));
    std::this_thread::sleep_for(20ms);
  }
  const auto ls = source.live_stats();
  EXPECT_EQ(ls.frames, 0u) << "frames without a head pose cannot be placed in the world";
  EXPECT_GT(ls.imu_samples, 0u);
  EXPECT_FALSE(emulated->rig->stats().anchored);
}

}  // namespace
}  // namespace proprio::vist_eval
