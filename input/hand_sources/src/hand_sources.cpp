#include "proprio/hand_sources/hand_sources.hpp"

#include <string>

#include "proprio/core/data_dir.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/replay_source.hpp"
#include "proprio/hand_sources/plugin_loader.hpp"
#include "proprio/sim/sim_hand_source.hpp"

// Duplicated static state. proprio::core is a static library, so a plugin
// carries its own copy of core's globals next to the host's (the layer or the
// CLI). What each means for a source started in a plugin:
//  - logger(): both copies return the one "proprio" logger from spdlog's
//    registry in the shared libspdlog, so a plugin's warnings go where the
//    host's go, at the host's level (checked when a plugin loads).
//  - MonotonicClock: stateless, CLOCK_MONOTONIC read from the kernel in both.
//  - file_io's input registry (what check_output_path protects): a plugin
//    remembers what it read in its own copy, so the plugin reports those files
//    and the host remembers them too (remember_inputs below).
//  - data_dir(): a plugin sits one level deeper than the layer, so the host
//    resolves the default glove model and passes the path in the config.

namespace proprio::hand_sources {
namespace {

using openxr_layer::ReferenceSpace;

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

// The host's file_io registry learns the plugin's inputs by opening each once
// (regular files only, nothing read), as the plugin's own copy did.
void remember_inputs(const std::vector<std::filesystem::path>& inputs) {
  for (const auto& p : inputs) (void)open_input_file(p, "input");
}

// vist: a VIST tracker fed by a recorded session; glove: the stretch glove
// (a read-out board on USB, or a simulated wearer); ftm: the FTM glove.
Result<std::unique_ptr<HandSource>> start_in_plugin(const char* family, SourceConfig sc,
                                                    DurationNs max_prediction_ns, TrackedPoseProvider* poses) {
  auto plugin = load_plugin(family);
  if (!plugin) return plugin.error();
  if (sc.type == SourceType::glove && sc.model.empty()) sc.model = default_glove_model_path();
  auto started = (*plugin)->start(sc, max_prediction_ns, poses);
  if (!started) return started.error();
  if (!started->source) return make_error(Errc::unavailable, std::string(family) + " plugin started no source");
  remember_inputs(started->inputs);
  return std::move(started->source);
}

}  // namespace

std::string default_glove_model_path() { return data_path("models/stretch_glove_generic.onnx"); }

Result<std::unique_ptr<HandSource>> start_hand_source(const SourceConfig& config, DurationNs max_prediction_ns,
                                                      TrackedPoseProvider* poses) {
  Result<std::unique_ptr<HandSource>> source = make_error(Errc::invalid_argument, "unknown source type");
  switch (config.type) {
    case SourceType::sim: source = start_sim(config, max_prediction_ns); break;
    case SourceType::replay: source = start_replay(config, max_prediction_ns); break;
    case SourceType::vist: source = start_in_plugin("vist", config, max_prediction_ns, poses); break;
    case SourceType::glove: source = start_in_plugin("stretch_glove", config, max_prediction_ns, poses); break;
    case SourceType::ftm: source = start_in_plugin("ftm", config, max_prediction_ns, poses); break;
  }
  if (!source) return source.error().with_context(std::string(to_string(config.type)) + " source");
  return source;
}

}  // namespace proprio::hand_sources
