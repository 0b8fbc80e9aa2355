// libproprio_source_vist.so: the `vist` hand source (a VIST tracker fed by a
// recorded session replayed in real time), loaded only when a configured
// source needs it. The contract: proprio/hand_sources/plugin_abi.hpp.
#include "proprio/hand_sources/plugin_abi.hpp"
#include "proprio/vist/vist_hand_source.hpp"

namespace proprio::hand_sources {
namespace {

Result<PluginStarted> start_vist(const openxr_layer::SourceConfig& sc, DurationNs max_prediction_ns) {
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
  return PluginStarted{std::move(*source), {sc.path}};
}

}  // namespace
}  // namespace proprio::hand_sources

PROPRIO_DEFINE_HAND_SOURCE_PLUGIN("vist", proprio::hand_sources::start_vist)
