#include "proprio/openxr_layer/hand_sources.hpp"

#include <string>

#include "proprio/core/log.hpp"
#include "proprio/core/replay_source.hpp"
#include "proprio/devices/hid_transport.hpp"
#include "proprio/glove/glove_board_source.hpp"
#include "proprio/glove_eval/glove_evaluation.hpp"
#include "proprio/sim/sim_hand_source.hpp"
#include "proprio/vist/vist_hand_source.hpp"

namespace proprio::openxr_layer {
namespace {

Result<std::unique_ptr<HandSource>> start_sim(const SourceConfig& sc, DurationNs max_prediction_ns) {
  sim::SimHandSourceOptions o;
  o.subject = sc.subject;
  o.protocol = sc.protocol;
  o.seed = sc.seed;
  o.rate_hz = sc.rate_hz;
  o.hands = sc.hands;
  o.relative_to_head = sc.space == ReferenceSpace::view;
  o.history.max_prediction_ns = max_prediction_ns;
  auto s = sim::SimHandSource::create(o);
  if (!s) return s.error();
  return std::unique_ptr<HandSource>(std::move(*s));
}

Result<std::unique_ptr<HandSource>> start_replay(const SourceConfig& sc, DurationNs max_prediction_ns) {
  ReplayOptions o;
  o.loop = sc.loop;
  o.max_prediction_ns = max_prediction_ns;
  auto s = ReplayHandSource::open(sc.path, o);
  if (!s) return s.error();
  // A damaged or cut-short file still plays what could be read; say so once.
  if (const std::string problem =
          describe_replay_problem(sc.path, s->recording_summary(), s->skipped_samples());
      !problem.empty()) {
    logger().warn("Proprio layer: {}", problem);
  }
  // Play from now: the recording's first pose maps to this instant.
  s->set_time_offset_ns(MonotonicClock::instance().now_ns() - s->file_time_range().first_ns);
  return std::unique_ptr<HandSource>(std::make_unique<ReplayHandSource>(std::move(*s)));
}

// A VIST tracker fed by a recorded session replayed in real time.
Result<std::unique_ptr<HandSource>> start_vist(const SourceConfig& sc, DurationNs max_prediction_ns) {
  auto session = vist::VistSessionReader::open(sc.path);
  if (!session) return session.error();
  vist::VistHandSourceOptions o;
  o.tracker.hand = session->info().hand;
  o.tracker.nominal_hand_length_m = session->info().nominal_hand_length_m;
  o.tracker.nominal_hand_width_m = session->info().nominal_hand_width_m;
  o.history.max_prediction_ns = max_prediction_ns;
  auto source = vist::VistHandSource::create(session->info().glove, o);
  if (!source) return source.error();
  vist::VistSessionPlayerOptions po;
  po.loop = sc.loop;
  if (auto st = (*source)->play_session(sc.path, po); !st) return st.error();
  return std::unique_ptr<HandSource>(std::move(*source));
}

// The stretch glove: a read-out board on USB, or a simulated wearer streamed in real time.
Result<std::unique_ptr<HandSource>> start_glove(const SourceConfig& sc, DurationNs max_prediction_ns) {
  const std::string model_path = sc.model.empty() ? std::string(default_glove_model_path()) : sc.model;
  if (sc.input == "device") {
    auto layout = sc.layout.empty() ? Result<StretchGloveLayout>(StretchGloveLayout::thesis_default())
                                    : StretchGloveLayout::load(sc.layout);
    if (!layout) return layout.error();
    auto calibration = glove::MinMaxCalibration::load(sc.calibration);
    if (!calibration) return calibration.error();
    auto model = glove::OnnxPoseModel::load(model_path, *layout);
    if (!model) return model.error();
    glove::GloveHandSourceOptions o;
    o.tracker.hand = sc.hands.front();
    o.tracker.hand_length_m = sc.hand_length_m;
    o.tracker.hand_width_m = sc.hand_width_m;
    o.history.max_prediction_ns = max_prediction_ns;
    auto board = glove::GloveBoardSource::start(
        std::make_unique<devices::HidapiTransport>(devices::stretch_board_selector()), *layout,
        std::move(*calibration), std::move(*model), o);
    if (!board) return board.error();
    return std::unique_ptr<HandSource>(std::move(*board));
  }
  glove_eval::SimGloveSourceOptions o;
  o.subject = sc.subject;
  o.seed = sc.seed;
  o.model = model_path;
  if (!sc.layout.empty()) {
    auto layout = StretchGloveLayout::load(sc.layout);
    if (!layout) return layout.error();
    o.layout = std::move(*layout);
  }
  o.history.max_prediction_ns = max_prediction_ns;
  return glove_eval::make_sim_glove_source(o);
}

}  // namespace

const char* default_glove_model_path() noexcept { return PROPRIO_DEFAULT_GLOVE_MODEL; }

Result<std::unique_ptr<HandSource>> start_hand_source(const SourceConfig& config, DurationNs max_prediction_ns) {
  Result<std::unique_ptr<HandSource>> source = make_error(Errc::invalid_argument, "unknown source type");
  switch (config.type) {
    case SourceType::sim: source = start_sim(config, max_prediction_ns); break;
    case SourceType::replay: source = start_replay(config, max_prediction_ns); break;
    case SourceType::vist: source = start_vist(config, max_prediction_ns); break;
    case SourceType::glove: source = start_glove(config, max_prediction_ns); break;
  }
  if (!source) return source.error().with_context(std::string(to_string(config.type)) + " source");
  return source;
}

}  // namespace proprio::openxr_layer
