#pragma once
// Starts the hand source a SourceConfig describes: the OpenXR layer's
// [[source]] tables and `proprio run --hands sim|replay|vist|glove` go
// through this one function, so a source behaves the same in both.
//
// `sim` and `replay` are built in. `vist` and `glove` live in plugins
// (libproprio_source_vist.so, libproprio_source_stretch_glove.so) that are
// loaded the first time a configured source needs one, so a process serving
// simulated or recorded hands never maps OpenCV or hidapi. Where the plugins
// are looked for: plugin_loader.hpp.
//
// Every source it returns runs on CLOCK_MONOTONIC in real time (its own
// threads, or a replay mapped to now): callers that step simulated time
// cannot use them.
#include <memory>
#include <string>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/core/tracked_pose_provider.hpp"
#include "proprio/openxr_layer/layer_config.hpp"

namespace proprio::hand_sources {

using openxr_layer::SourceConfig;
using openxr_layer::SourceType;

// max_prediction_ns: furthest a lookup extrapolates past the newest pose.
// poses: what the host tracks (the OpenXR layer: the headset), for sources
// that need it (a live vist source's head-mounted camera); may be null, and
// must outlive the source.
// Errors name the source and what is missing (a file, a calibration, a board,
// a plugin and every folder it was looked for in).
Result<std::unique_ptr<HandSource>> start_hand_source(const SourceConfig& config, DurationNs max_prediction_ns,
                                                      TrackedPoseProvider* poses = nullptr);

// The stretch glove's pose network shipped with Proprio, in the data folder
// (proprio/core/data_dir.hpp): what a glove source uses without `model`.
std::string default_glove_model_path();

}  // namespace proprio::hand_sources
