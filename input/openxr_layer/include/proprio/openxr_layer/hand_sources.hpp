#pragma once
// Starts the hand source a SourceConfig describes: the OpenXR layer's
// [[source]] tables and `proprio run --hands sim|replay|vist|glove` go
// through this one function, so a source behaves the same in both.
//
// Every source it returns runs on CLOCK_MONOTONIC in real time (its own
// threads, or a replay mapped to now): callers that step simulated time
// cannot use them.
#include <memory>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/openxr_layer/layer_config.hpp"

namespace proprio::openxr_layer {

// max_prediction_ns: furthest a lookup extrapolates past the newest pose.
// Errors name the source and what is missing (a file, a calibration, a board).
Result<std::unique_ptr<HandSource>> start_hand_source(const SourceConfig& config, DurationNs max_prediction_ns);

// The stretch glove's pose network shipped with Proprio (config/models).
const char* default_glove_model_path() noexcept;

}  // namespace proprio::openxr_layer
