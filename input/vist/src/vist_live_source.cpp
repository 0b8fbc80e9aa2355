#include "proprio/vist/vist_live_source.hpp"

#include <fmt/format.h>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <system_error>

#include "proprio/core/log.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/vist/stereo_calibration.hpp"

namespace proprio::vist {

Status VistLiveSourceOptions::validate() const {
  if (auto s = live.validate(); !s) return s;
  if (!std::isfinite(vision_timeout_s) || vision_timeout_s < 0.05 || vision_timeout_s > 60.0) {
    return make_error(Errc::invalid_argument,
                      fmt::format("VIST live source: vision_timeout_s = {} must be in [0.05, 60] s", vision_timeout_s));
  }
  return {};
}

std::string VistLiveSourceOptions::describe() const {
  return fmt::format("{}\n{}\nthe hand is inactive {:g} s after the newest stereo frame", source.describe(),
                     live.describe(), vision_timeout_s);
}

// ---------------------------------------------------------------------------

Result<std::unique_ptr<VistLiveSource>> VistLiveSource::start(const ImuGloveDescription& glove,
                                                              std::unique_ptr<devices::ImuGloveDevice> glove_device,
                                                              StereoCameraOpener open_camera,
                                                              VistLiveSourceOptions options, HeadPoseProvider head,
                                                              std::shared_ptr<void> keep_alive, const Clock& clock) {
  if (auto s = options.validate(); !s) return s.error();
  auto tracker = VistHandSource::create(glove, options.source);
  if (!tracker) return tracker.error();
  std::unique_ptr<VistLiveSource> source(new VistLiveSource(options, std::move(*tracker), std::move(keep_alive)));
  auto input = VistLiveInput::create_with_opener(*source->tracker_, glove, std::move(glove_device),
                                                 std::move(open_camera), options.live, std::move(head), clock);
  if (!input) return input.error();
  source->input_ = std::move(*input);
  if (auto s = source->input_->start(); !s) return s.error();
  return source;
}

VistLiveSource::VistLiveSource(VistLiveSourceOptions options, std::unique_ptr<VistHandSource> tracker,
                               std::shared_ptr<void> keep_alive)
    : options_(std::move(options)), tracker_(std::move(tracker)), keep_alive_(std::move(keep_alive)) {}

VistLiveSource::~VistLiveSource() {
  // The device threads push into the tracker and use what keep_alive holds.
  if (input_) input_->stop();
  input_.reset();
  keep_alive_.reset();
}

bool VistLiveSource::vision_lost(TimeNs t_ns) const noexcept {
  const TimeNs last = tracker_->last_vision_fix_ns();
  return last == 0 || t_ns - last > seconds_to_ns(options_.vision_timeout_s);
}

Result<HandPose> VistLiveSource::pose_at(Handedness hand, TimeNs t_ns) {
  auto pose = tracker_->pose_at(hand, t_ns);
  if (pose && pose->active && vision_lost(t_ns)) pose->active = false;
  return pose;
}

PoseLookup VistLiveSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  const PoseLookup found = tracker_->lookup(hand, t_ns, out);
  if ((is_usable(found) || found == PoseLookup::stale) && out.active && vision_lost(t_ns)) out.active = false;
  return found;
}

// ---------------------------------------------------------------------------

hid::HidDeviceSelector imu_glove_selector() {
  hid::HidDeviceSelector sel;
  sel.vendor_id = devices::kImuGloveUsbVendorId;
  sel.product_id = devices::kImuGloveUsbProductId;
  return sel;
}

namespace {

bool is_device_name(const std::string& s) {
  const bool digits =
      !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return c >= '0' && c <= '9'; });
  return digits || s.rfind("/dev/", 0) == 0;
}

// A calibration rectifies to the camera it computed; the tracker works with
// the glove file's rig. If the two differ, every triangulated marker is off.
Status check_calibration_matches_rig(const StereoCalibration& cal, const std::string& cal_path,
                                     const ImuGloveDescription& glove) {
  const StereoRig rectified = cal.rectified_rig(glove.rig.rate_hz, glove.rig.T_head_leftcam);
  const PinholeCamera& c = rectified.camera;
  const PinholeCamera& r = glove.rig.camera;
  const bool same_size = c.width_px == r.width_px && c.height_px == r.height_px;
  const bool same_focal =
      std::abs(c.fx_px - r.fx_px) <= 0.005 * r.fx_px && std::abs(c.fy_px - r.fy_px) <= 0.005 * r.fy_px;
  const bool same_centre = std::abs(c.cx_px - r.cx_px) <= 1.0 && std::abs(c.cy_px - r.cy_px) <= 1.0;
  const bool same_baseline = std::abs(rectified.baseline_m - glove.rig.baseline_m) <= 0.001;
  if (same_size && same_focal && same_centre && same_baseline) return {};
  const std::string glove_name = glove.origin.empty() ? "the built-in thesis glove" : glove.origin;
  return make_error(
      Errc::invalid_argument,
      fmt::format("stereo calibration '{}' rectifies to {}x{} px, fx {:.1f}, fy {:.1f}, cx {:.1f}, cy {:.1f}, "
                  "baseline {:.1f} mm, but the rig of {} is {}x{} px, fx {:.1f}, fy {:.1f}, cx {:.1f}, cy {:.1f}, "
                  "baseline {:.1f} mm: put the [rig] table that 'proprio calibrate stereo --glove <glove file>' "
                  "prints into the glove file and name it in 'glove' (docs/stereo-camera.md)",
                  cal_path, c.width_px, c.height_px, c.fx_px, c.fy_px, c.cx_px, c.cy_px, 1e3 * rectified.baseline_m,
                  glove_name, r.width_px, r.height_px, r.fx_px, r.fy_px, r.cx_px, r.cy_px, 1e3 * glove.rig.baseline_m));
}

}  // namespace

bool VistDeviceOptions::camera_is_file() const {
  std::error_code ec;
  return !is_device_name(camera) || std::filesystem::is_regular_file(camera, ec);
}

Status VistDeviceOptions::validate() const {
  if (camera.empty()) return make_error(Errc::invalid_argument, "VIST devices: no camera given (e.g. /dev/video0)");
  std::error_code ec;
  for (const std::string* name : {&camera, &camera_right}) {
    if (name->empty() || is_device_name(*name)) continue;
    if (!std::filesystem::is_regular_file(*name, ec)) {
      return make_error(Errc::not_found, "VIST devices: camera '" + *name +
                                             "' is neither a camera (/dev/videoN) nor an existing video file");
    }
  }
  if (!camera_right.empty() && is_device_name(camera) != is_device_name(camera_right)) {
    return make_error(Errc::invalid_argument, "VIST devices: camera '" + camera + "' and camera_right '" +
                                                  camera_right + "' must both be cameras or both video files");
  }
  return {};  // the calibration file is read (and its errors named) by start_vist_devices
}

std::string VistDeviceOptions::describe() const {
  std::string s = camera_is_file() ? "video '" + camera + "'" : "camera " + camera;
  if (!camera_right.empty()) s += " + " + camera_right + " (right)";
  s += stereo_calibration.empty() ? ", not rectified" : ", rectified with '" + stereo_calibration + "'";
  return s + "; IMU board " + imu.describe();
}

Result<std::unique_ptr<VistLiveSource>> start_vist_devices(const ImuGloveDescription& glove,
                                                           const VistDeviceOptions& devices,
                                                           VistLiveSourceOptions options, HeadPoseProvider head) {
  if (auto s = devices.validate(); !s) return s.error();
  // A node that is not there yet is a board not plugged in yet (hidraw nodes
  // appear on plugging in): the driver keeps looking. One that is there but is
  // not a hidraw node is a configuration error.
  if (!devices.imu.path.empty()) {
    if (auto s = hid::check_hidraw_node(devices.imu.path); !s && s.error().code != Errc::not_found) return s.error();
  }
  // The rectification maps are built once here (a bad file is a
  // configuration error) and shared by every camera opened later.
  std::optional<StereoRectifier> rectifier;
  if (!devices.stereo_calibration.empty()) {
    auto cal = StereoCalibration::load(devices.stereo_calibration);
    if (!cal) return cal.error();
    if (auto s = check_calibration_matches_rig(*cal, devices.stereo_calibration, glove); !s) return s.error();
    auto r = StereoRectifier::create(*cal);
    if (!r) return r.error().with_context("rectifying with '" + devices.stereo_calibration + "'");
    rectifier = std::move(*r);
  }

  StereoCameraOptions co;
  const bool file = devices.camera_is_file();
  co.input = file ? StereoInput::file : StereoInput::device;
  co.left = devices.camera;
  co.right = devices.camera_right;
  co.side_by_side = devices.camera_right.empty();
  co.width_px = glove.rig.camera.width_px;
  co.height_px = glove.rig.camera.height_px;
  co.fps = glove.rig.rate_hz;
  co.reader_thread = !file;  // a live camera is drained continuously; a file is paced by VistLiveInput
  if (auto s = co.validate(); !s) return s.error().with_context("VIST devices");
  StereoCameraOpener opener = [co, rectifier]() mutable -> Result<std::unique_ptr<StereoCamera>> {
    if (co.input == StereoInput::file) co.file_t0_ns = MonotonicClock::instance().now_ns();
    auto camera = StereoCamera::open(co);
    if (!camera) return camera.error();
    if (rectifier) {
      if (auto s = (*camera)->set_rectifier(rectifier); !s) return s.error();
    }
    return std::move(*camera);
  };
  if (file) {
    // A file is there or not, and decodes or not, at start: a configuration error, not one to retry.
    auto probe = opener();
    if (!probe) return probe.error().with_context("VIST devices");
  }

  auto glove_device = std::make_unique<devices::ImuGloveDevice>(std::make_unique<hid::HidapiTransport>(devices.imu));
  // Each change once: a glove that is not there is retried for as long as
  // the app runs, and its log must not fill up with that.
  glove_device->set_state_callback([last = std::string()](hid::LinkState state, std::string_view detail) mutable {
    if (state == hid::LinkState::connecting) return;
    std::string line = fmt::format("{}: {}", hid::to_string(state), detail);
    if (line == last) return;
    logger().info("VIST glove {}", line);
    last = std::move(line);
  });
  logger().info("VIST live: {}; the glove and the camera are picked up whenever they are there", devices.describe());
  return VistLiveSource::start(glove, std::move(glove_device), std::move(opener), std::move(options), std::move(head));
}

HeadPoseProvider head_pose_provider(TrackedPoseProvider* poses) {
  if (!poses) return nullptr;
  return [poses](TimeNs t_ns, Pose& T_world_head) { return poses->locate(TrackedPose::head, t_ns, T_world_head); };
}

}  // namespace proprio::vist
