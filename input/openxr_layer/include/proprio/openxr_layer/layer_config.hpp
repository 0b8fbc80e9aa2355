#pragma once
// Configuration of the OpenXR layer: which hand sources feed it and how their
// tracking origins are bound to OpenXR reference spaces. Read from
// $PROPRIO_LAYER_CONFIG, else $XDG_CONFIG_HOME/proprio/layer.toml, else
// ~/.config/proprio/layer.toml. Documented in docs/openxr-layer.md.
#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/sim/hand_motion.hpp"

namespace proprio::openxr_layer {

enum class SourceType { sim, replay, vist, glove, ftm };
enum class ReferenceSpace { view, local, stage };
// Where the wrist of a source's hands comes from (docs/openxr-layer.md, "The
// wrist"). `source`: the source's own (VIST and sim track it; the stretch
// glove's is its fixed pose). The others take the wrist from the app's XR
// runtime at each xrLocateHandJointsEXT and keep the source's fingers.
enum class WristSource { source, controller, tracker, runtime_hand };
// What to do when the runtime implements XR_EXT_hand_tracking itself.
enum class RuntimeHandTracking {
  automatic,     // override when a Proprio source is configured, else pass through
  override_it,   // always serve Proprio's hands
  pass_through,  // always let the runtime's hand tracking through untouched
};

std::string_view to_string(SourceType t) noexcept;
std::string_view to_string(ReferenceSpace s) noexcept;
std::string_view to_string(RuntimeHandTracking m) noexcept;
std::string_view to_string(WristSource w) noexcept;

struct SourceConfig {
  SourceType type = SourceType::sim;
  std::vector<Handedness> hands{Handedness::left, Handedness::right};
  // The reference space the source's tracking origin is bound to: VIEW for a
  // head-mounted camera, LOCAL or STAGE for a fixed setup.
  ReferenceSpace space = ReferenceSpace::view;
  Pose T_space_source;  // calibrated offset of the source origin in that space

  // sim: the procedural hand, expressed relative to the simulated head.
  sim::MotionProtocol protocol = sim::MotionProtocol::free_motion;
  int subject = 3;
  std::uint64_t seed = 1;
  double rate_hz = 90.0;  // how often the simulated tracker produces a pose

  // The wrist, for any source: where it comes from and, for a controller or
  // a tracker, the wrist in that device's pose frame (grip pose): from
  // `wrist_calibration` (proprio calibrate wrist) when given, else inline.
  WristSource wrist = WristSource::source;
  Pose T_device_wrist;
  std::string wrist_calibration;
  // wrist "tracker": the XR_HTCX_vive_tracker_interaction role per hand
  // (left, right), e.g. "left_wrist" for /user/vive_tracker_htcx/role/left_wrist.
  std::array<std::string, 2> tracker_role{"left_wrist", "right_wrist"};

  // replay: a recorded session, played from when the layer starts.
  // vist input "replay": a recorded VIST session (proprio sim-vist, or a live
  // recording) replayed through the VIST tracker in real time.
  std::string path;
  bool loop = true;

  // vist input "device": the IMU board on USB HID and a stereo camera
  // (/dev/videoN, or a side-by-side video file played in real time), with the
  // head pose at each capture time from the runtime (the source's space must
  // not be "view": the tracker works in a world that stays still).
  // vist input "emulated": a simulated wearer behind the same code paths (the
  // IMU board emulator speaking the real HID bytes, a camera rendering the
  // marker images from the runtime's head pose).
  std::string camera = "/dev/video0";
  std::string camera_right;        // a second camera (or video) for the right eye
  std::string stereo_calibration;  // from `proprio calibrate stereo`: rectification
  std::string glove_description;   // VIST glove TOML; empty: the thesis glove
  std::string imu_path, imu_serial;  // which IMU board, when several are plugged in

  // Emulated inputs (vist and glove "emulated"): a CSV of the simulated
  // wearer's true joints, written as the emulator runs, for tests and
  // benchmarks; the tracker never sees it. Empty: not written.
  std::string truth_path;
  // Emulated inputs: the board's cable pulled at each `at` (s after the source
  // starts) for `duration` (s), to rehearse a live unplug in an app.
  struct Unplug {
    double at_s = 0.0, duration_s = 0.0;
  };
  std::vector<Unplug> unplugs;

  // glove: the stretch-sensing glove. input "sim" = simulated subject
  // (subject, seed above); "emulated" = the same wearer behind the read-out
  // board's emulator and the real driver; "device" = a read-out board on USB,
  // with the wearer's min-max calibration file. The model and layout default
  // to the shipped ones.
  // vist: "replay" (path), "device" or "emulated" (above).
  std::string input = "sim";
  std::string model;        // .onnx with its .json sidecar
  std::string layout;       // glove layout TOML; empty: the built-in thesis-like glove
  std::string calibration;  // input "device": from `proprio calibrate glove`
  double hand_length_m = 0.19, hand_width_m = 0.10;  // input "device": the wearer's hand
  // ftm: the FTM glove (IMUs + bend sensors, issue 27), one hand. input
  // "sim" / "emulated" as for the glove (subject, seed, truth_path, unplugs;
  // calibrated from the wearer's own figure-eight and poses unless
  // `calibration` names a file); "device" = an FTM board on USB with the
  // file from `proprio calibrate ftm`. false: abduction held at 0 (the
  // thesis's "without AA").
  bool track_abduction = true;

  std::string describe() const;
};

// [haptics]: fingertip devices the layer drives for XR_PROPRIO_fingertip_haptics
// and the apps' xrApplyHapticFeedback (docs/xr-proprio-fingertip-haptics.md).
enum class HapticDevices { emulated, hid };
std::string_view to_string(HapticDevices d) noexcept;

struct HapticsConfig {
  bool enabled = false;  // a [haptics] table is present
  // emulated: in-process device emulators speaking the real wire bytes (no
  // hardware); hid: fingertip devices on USB HID.
  HapticDevices devices = HapticDevices::emulated;
  // The device model: a name under config/haptics ("platform_3dof",
  // "band_2dof", "force_vector") or a path to a model file. hid: empty
  // takes the shipped model for the kind each device reports.
  std::string model = "platform_3dof";
  // Which fingers carry a device, per hand (left, right).
  std::array<std::vector<Finger>, 2> fingers;
  // hid: "FINGER=SERIAL" or "FINGER=/dev/hidrawN" per hand (as proprio run --bind).
  std::array<std::vector<std::string>, 2> bindings;
  // The contact simulation's forces x this (an app's own forces are not scaled).
  double force_scale = 1.0;
  // Whether apps may run the contact simulation (it costs one core's
  // fraction at 1 kHz while a contact-mode XrFingertipHapticsPROPRIO lives).
  bool contact = true;
  // xrApplyHapticFeedback on /user/hand/{left,right}: a press of
  // amplitude x this x the device's largest normal force, for the duration.
  // 0 turns the mapping off.
  double vibration_gain = 0.5;

  std::size_t device_count() const noexcept { return fingers[0].size() + fingers[1].size(); }
  std::string describe() const;
};

struct LayerConfig {
  RuntimeHandTracking runtime_hand_tracking = RuntimeHandTracking::automatic;
  DurationNs max_prediction_ns = 50 * kNsPerMillisecond;  // furthest extrapolation past the newest pose
  // Past the prediction horizon the newest pose is still reported as valid but
  // not tracked for this long; after that the hand is inactive.
  DurationNs stale_timeout_ns = 500 * kNsPerMillisecond;
  std::vector<SourceConfig> sources;
  HapticsConfig haptics;
  std::string origin;  // the file it came from, for messages

  std::string describe() const;
};

// $PROPRIO_LAYER_CONFIG, else $XDG_CONFIG_HOME/proprio/layer.toml, else ~/.config/proprio/layer.toml.
std::filesystem::path default_layer_config_path();
// A layer config is a few hundred bytes; this bounds what an app reads at start-up.
inline constexpr std::uint64_t kMaxLayerConfigBytes = 1024 * 1024;
Result<LayerConfig> load_layer_config(const std::filesystem::path& path);
Result<LayerConfig> parse_layer_config(std::string_view toml_text, const std::string& source_name);
// The tracker-to-wrist offset `proprio calibrate wrist` writes: a small TOML
// file ([wrist] position_m = [x, y, z], rotation_deg = [rx, ry, rz], the wrist
// in the device's grip frame). Errors name the file and key.
Result<Pose> load_wrist_calibration(const std::filesystem::path& path);
std::string format_wrist_calibration(const Pose& T_device_wrist, std::string_view comment);

// A complete, commented configuration using the simulated hand (or a replay
// when recording_path is given), for `proprio layer init-config` and the docs.
std::string example_layer_config(const std::string& recording_path = {});

}  // namespace proprio::openxr_layer
