// libproprio_source_ftm.so: the `ftm` hand source (the FTM glove: a board on
// USB, a simulated wearer streamed in real time, or that wearer behind the
// board emulator and the real driver), loaded only when a configured source
// needs it; it is what brings hidapi into a process serving FTM hands. The
// contract: proprio/hand_sources/plugin_abi.hpp.
#include "proprio/ftm_sources/ftm_sources.hpp"
#include "proprio/hand_sources/plugin_abi.hpp"

namespace proprio::hand_sources {
namespace {

Result<PluginStarted> start_ftm(const openxr_layer::SourceConfig& sc, DurationNs max_prediction_ns,
                                TrackedPoseProvider* /*poses*/) {
  if (sc.hands.size() != 1) {
    return make_error(Errc::invalid_argument,
                      "an ftm source is one glove: give one hand in 'hands' (\"left\" or \"right\"), and a second "
                      "[[source]] for the other glove");
  }
  std::vector<std::filesystem::path> inputs;
  if (!sc.calibration.empty()) inputs.emplace_back(sc.calibration);
  if (sc.input == "device") {
    ftm_sources::FtmDeviceSourceOptions o;
    o.hand = sc.hands.front();
    o.calibration = sc.calibration;
    o.track_abduction = sc.track_abduction;
    o.history.max_prediction_ns = max_prediction_ns;
    auto source = ftm_sources::make_device_ftm_source(o);
    if (!source) return source.error();
    return PluginStarted{std::move(*source), std::move(inputs)};
  }
  ftm_sources::FtmSimSourceOptions o;
  o.hand = sc.hands.front();
  o.subject = sc.subject;
  o.seed = sc.seed;
  o.calibration = sc.calibration;
  o.track_abduction = sc.track_abduction;
  o.truth_path = sc.truth_path;
  o.history.max_prediction_ns = max_prediction_ns;
  if (sc.input == "emulated") {
    ftm_sources::FtmEmulatedSourceOptions eo;
    eo.wearer = std::move(o);
    for (const auto& u : sc.unplugs) eo.faults.unplugs.push_back({seconds_to_ns(u.at_s), seconds_to_ns(u.duration_s)});
    auto source = ftm_sources::make_emulated_ftm_source(eo);
    if (!source) return source.error();
    return PluginStarted{std::move(*source), std::move(inputs)};
  }
  auto source = ftm_sources::make_sim_ftm_source(o);
  if (!source) return source.error();
  return PluginStarted{std::move(*source), std::move(inputs)};
}

}  // namespace
}  // namespace proprio::hand_sources

PROPRIO_DEFINE_HAND_SOURCE_PLUGIN("ftm", proprio::hand_sources::start_ftm)
