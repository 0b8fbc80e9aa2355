// VistLiveSource over the real devices (start_vist_devices): it starts
// without the board or the camera and keeps looking for them, with the hand
// inactive meanwhile; only configuration errors fail the start, among them a
// stereo calibration that does not rectify to the glove description's rig.
#include <gtest/gtest.h>

#include <fstream>

#include <chrono>
#include <functional>
#include <string>
#include <thread>

#include "proprio/vist/stereo_calibration.hpp"
#include "proprio/vist/vist_live_source.hpp"
#include "support/temp_dir.hpp"

namespace proprio::vist {
namespace {

using namespace std::chrono_literals;
using testing_support::TempDir;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

bool eventually(const std::function<bool()>& pred, std::chrono::seconds timeout = 20s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(5ms);
  }
  return true;
}

// A calibration that rectifies to `camera` with this baseline: no rotation, no
// distortion (the rectification maps are then the identity).
StereoCalibration calibration_for(const PinholeCamera& camera, double baseline_m) {
  StereoCalibration c;
  c.image_size = cv::Size(camera.width_px, camera.height_px);
  c.left.K = cv::Matx33d(camera.fx_px, 0, camera.cx_px, 0, camera.fy_px, camera.cy_px, 0, 0, 1);
  c.right.K = c.left.K;
  c.t_rightcam_leftcam_m = cv::Vec3d(-baseline_m, 0, 0);
  c.P_left = cv::Matx34d(camera.fx_px, 0, camera.cx_px, 0, 0, camera.fy_px, camera.cy_px, 0, 0, 0, 1, 0);
  c.P_right = c.P_left;
  c.P_right(0, 3) = -camera.fx_px * baseline_m;
  return c;
}

VistDeviceOptions absent_devices() {
  VistDeviceOptions d;
  d.camera = "/dev/video_proprio_test_absent";
  d.imu.serial = "proprio-test-no-such-board";  // whatever is plugged in, not this one
  return d;
}

VistLiveSourceOptions quick_retries() {
  VistLiveSourceOptions o;
  o.live.camera_retry_s = 0.05;
  return o;
}

TEST(VistLiveSource, StartsWithoutTheBoardOrTheCameraAndKeepsLookingForThem) {
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  auto source = start_vist_devices(glove, absent_devices(), quick_retries());
  ASSERT_TRUE(source) << source.error().message;
  EXPECT_TRUE((*source)->available(Handedness::right));
  EXPECT_FALSE((*source)->available(Handedness::left));
  ASSERT_TRUE(eventually([&] { return (*source)->live_stats().camera_open_failures >= 3; }))
      << "the camera is retried on its thread: " << (*source)->live_stats().describe();
  const VistLiveStats st = (*source)->live_stats();
  EXPECT_FALSE(st.camera_open);
  EXPECT_TRUE(contains(st.camera_error, "/dev/video_proprio_test_absent")) << st.camera_error;
  EXPECT_NE(st.glove_state, hid::LinkState::streaming);
  EXPECT_NE(st.glove_state, hid::LinkState::stopped) << "the glove's reader thread is looking for it";
  HandPose pose;
  const PoseLookup r = (*source)->lookup(Handedness::right, MonotonicClock::instance().now_ns(), pose);
  EXPECT_FALSE(is_usable(r) && pose.active);
  source->reset();  // stops both threads (the test would hang otherwise)
}

TEST(VistLiveSource, ConfigurationErrorsFailTheStart) {
  TempDir dir;
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();

  VistDeviceOptions d = absent_devices();
  d.camera = (dir / "recording.avi").string();
  auto missing_video = start_vist_devices(glove, d);
  ASSERT_FALSE(missing_video);
  EXPECT_TRUE(contains(missing_video.error().message, "neither a camera")) << missing_video.error().message;

  d = absent_devices();
  d.camera_right = (dir / "right.avi").string();
  EXPECT_FALSE(start_vist_devices(glove, d));

  d = absent_devices();
  d.stereo_calibration = (dir / "nope.yaml").string();
  auto missing_cal = start_vist_devices(glove, d);
  ASSERT_FALSE(missing_cal);
  EXPECT_TRUE(contains(missing_cal.error().message, "nope.yaml")) << missing_cal.error().message;

  d = absent_devices();
  d.imu.path = (dir / "not_hidraw").string();
  std::ofstream(d.imu.path) << "a regular file";
  EXPECT_FALSE(start_vist_devices(glove, d)) << "an explicit HID node that is there must be a hidraw device";

  // A hidraw node appears when the board is plugged in: one not there yet is waited for.
  d = absent_devices();
  d.imu.path = (dir / "hidraw97").string();
  EXPECT_TRUE(start_vist_devices(glove, d)) << "a board not plugged in yet does not fail the start";

  VistLiveSourceOptions bad;
  bad.vision_timeout_s = 0.0;
  EXPECT_FALSE(start_vist_devices(glove, absent_devices(), bad));
}

TEST(VistLiveSource, TheCalibrationMustRectifyToTheGloveDescriptionsRig) {
  TempDir dir;
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  const auto matching = dir / "matching.yaml";
  ASSERT_TRUE(calibration_for(glove.rig.camera, glove.rig.baseline_m).save(matching));
  VistDeviceOptions d = absent_devices();
  d.stereo_calibration = matching.string();
  auto ok = start_vist_devices(glove, d, quick_retries());
  EXPECT_TRUE(ok) << ok.error().message;

  PinholeCamera other = glove.rig.camera;
  other.fx_px *= 1.1;
  other.fy_px *= 1.1;
  const auto wrong = dir / "other_camera.yaml";
  ASSERT_TRUE(calibration_for(other, glove.rig.baseline_m).save(wrong));
  d.stereo_calibration = wrong.string();
  auto refused = start_vist_devices(glove, d);
  ASSERT_FALSE(refused);
  EXPECT_TRUE(contains(refused.error().message, "[rig] table")) << refused.error().message;

  const auto wider = dir / "wider_baseline.yaml";
  ASSERT_TRUE(calibration_for(glove.rig.camera, glove.rig.baseline_m + 0.01).save(wider));
  d.stereo_calibration = wider.string();
  EXPECT_FALSE(start_vist_devices(glove, d));
}

}  // namespace
}  // namespace proprio::vist
