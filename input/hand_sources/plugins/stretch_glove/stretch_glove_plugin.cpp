// libproprio_source_stretch_glove.so: the `glove` hand source (the stretch
// glove: its read-out board on USB, a simulated wearer streamed in real
// time, or that wearer behind an emulated board and the real driver), loaded
// only when a configured source needs it; it is what brings OpenCV DNN and
// hidapi into a process. The contract: proprio/hand_sources/plugin_abi.hpp.
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/hand_sources/plugin_abi.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_glove/glove_board_source.hpp"
#include "proprio/stretch_glove/onnx_pose_model.hpp"
#include "proprio/stretch_glove_eval/glove_evaluation.hpp"

namespace proprio::hand_sources {
namespace {

// sc.model is always set: the host fills in the shipped model (hand_sources.cpp).
Result<PluginStarted> start_glove(const openxr_layer::SourceConfig& sc, DurationNs max_prediction_ns,
                                  TrackedPoseProvider* /*poses*/) {
  if (sc.hands.size() != 1) {
    return make_error(Errc::invalid_argument,
                      "a glove source is one glove: give one hand in 'hands' (\"left\" or \"right\"), and a second "
                      "[[source]] for the other glove");
  }
  const std::string& model_path = sc.model;
  std::vector<std::filesystem::path> inputs{model_path, stretch_glove::sidecar_path_for(model_path)};
  if (!sc.layout.empty()) inputs.emplace_back(sc.layout);
  if (sc.input == "device") {
    auto layout = sc.layout.empty() ? Result<StretchGloveLayout>(StretchGloveLayout::thesis_default())
                                    : StretchGloveLayout::load(sc.layout);
    if (!layout) return layout.error();
    auto calibration = stretch_glove::MinMaxCalibration::load(sc.calibration);
    if (!calibration) return calibration.error();
    inputs.emplace_back(sc.calibration);
    auto model = stretch_glove::OnnxPoseModel::load(model_path, *layout);
    if (!model) return model.error();
    stretch_glove::GloveHandSourceOptions o;
    o.tracker.hand = sc.hands.front();
    o.tracker.hand_length_m = sc.hand_length_m;
    o.tracker.hand_width_m = sc.hand_width_m;
    o.history.max_prediction_ns = max_prediction_ns;
    auto board = stretch_glove::GloveBoardSource::start(
        std::make_unique<hid::HidapiTransport>(devices::stretch_board_selector()), *layout,
        std::move(*calibration), std::move(*model), o);
    if (!board) return board.error();
    return PluginStarted{std::move(*board), std::move(inputs)};
  }
  stretch_glove_eval::SimGloveSourceOptions o;
  o.subject = sc.subject;
  o.seed = sc.seed;
  o.hand = sc.hands.front();
  o.model = model_path;
  if (!sc.layout.empty()) {
    auto layout = StretchGloveLayout::load(sc.layout);
    if (!layout) return layout.error();
    o.layout = std::move(*layout);
  }
  o.history.max_prediction_ns = max_prediction_ns;
  if (sc.input == "emulated") {
    // The same wearer behind the read-out board's emulator and the real driver.
    stretch_glove_eval::EmulatedGloveSourceOptions eo;
    eo.wearer = std::move(o);
    eo.wearer.truth_path = sc.truth_path;
    for (const auto& u : sc.unplugs) eo.faults.unplugs.push_back({seconds_to_ns(u.at_s), seconds_to_ns(u.duration_s)});
    auto source = stretch_glove_eval::make_emulated_glove_source(eo);
    if (!source) return source.error();
    return PluginStarted{std::move(*source), std::move(inputs)};
  }
  auto source = stretch_glove_eval::make_sim_glove_source(o);
  if (!source) return source.error();
  return PluginStarted{std::move(*source), std::move(inputs)};
}

}  // namespace
}  // namespace proprio::hand_sources

PROPRIO_DEFINE_HAND_SOURCE_PLUGIN("stretch_glove", proprio::hand_sources::start_glove)
