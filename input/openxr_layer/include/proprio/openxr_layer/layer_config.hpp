#pragma once
// Configuration of the OpenXR layer: which hand sources feed it and how their
// tracking origins are bound to OpenXR reference spaces. Read from
// $PROPRIO_LAYER_CONFIG, else $XDG_CONFIG_HOME/proprio/layer.toml, else
// ~/.config/proprio/layer.toml. Documented in docs/openxr-layer.md.
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

enum class SourceType { sim, replay, vist, glove };
enum class ReferenceSpace { view, local, stage };
// What to do when the runtime implements XR_EXT_hand_tracking itself.
enum class RuntimeHandTracking {
  automatic,     // override when a Proprio source is configured, else pass through
  override_it,   // always serve Proprio's hands
  pass_through,  // always let the runtime's hand tracking through untouched
};

std::string_view to_string(SourceType t) noexcept;
std::string_view to_string(ReferenceSpace s) noexcept;
std::string_view to_string(RuntimeHandTracking m) noexcept;

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

  // replay: a recorded session, played from when the layer starts.
  // vist: a recorded VIST session (proprio sim-vist, or a live recording)
  // replayed through the VIST tracker in real time.
  std::string path;
  bool loop = true;

  // glove: the stretch-sensing glove. input "sim" = simulated subject
  // (subject, seed above); "device" = a read-out board on USB, with the
  // wearer's min-max calibration file. The model and layout default to the
  // shipped ones.
  std::string input = "sim";
  std::string model;        // .onnx with its .json sidecar
  std::string layout;       // glove layout TOML; empty: the built-in thesis-like glove
  std::string calibration;  // input "device": from `proprio calibrate glove`
  double hand_length_m = 0.19, hand_width_m = 0.10;  // input "device": the wearer's hand

  std::string describe() const;
};

struct LayerConfig {
  RuntimeHandTracking runtime_hand_tracking = RuntimeHandTracking::automatic;
  DurationNs max_prediction_ns = 50 * kNsPerMillisecond;  // furthest extrapolation past the newest pose
  // Past the prediction horizon the newest pose is still reported as valid but
  // not tracked for this long; after that the hand is inactive.
  DurationNs stale_timeout_ns = 500 * kNsPerMillisecond;
  std::vector<SourceConfig> sources;
  std::string origin;  // the file it came from, for messages

  std::string describe() const;
};

// $PROPRIO_LAYER_CONFIG, else $XDG_CONFIG_HOME/proprio/layer.toml, else ~/.config/proprio/layer.toml.
std::filesystem::path default_layer_config_path();
// A layer config is a few hundred bytes; this bounds what an app reads at start-up.
inline constexpr std::uint64_t kMaxLayerConfigBytes = 1024 * 1024;
Result<LayerConfig> load_layer_config(const std::filesystem::path& path);
Result<LayerConfig> parse_layer_config(std::string_view toml_text, const std::string& source_name);
// A complete, commented configuration using the simulated hand (or a replay
// when recording_path is given), for `proprio layer init-config` and the docs.
std::string example_layer_config(const std::string& recording_path = {});

}  // namespace proprio::openxr_layer
