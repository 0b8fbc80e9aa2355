// libproprio_source_vist.so: the `vist` hand source, loaded only when a
// configured source needs it. The contract: proprio/hand_sources/plugin_abi.hpp.
//   input "replay":   a recorded VIST session replayed through the tracker in real time
//   input "device":   the IMU board on USB HID and a stereo camera (vist::start_vist_devices)
//   input "emulated": a simulated wearer behind the same drivers (vist_eval::start_emulated_vist)
// Live inputs take the head pose at each capture time from `poses` (the
// layer: the headset's VIEW pose in the source's space).
#include "proprio/hand_sources/plugin_abi.hpp"
#include "proprio/vist/vist_hand_source.hpp"
#include "proprio/vist/vist_live_source.hpp"
#include "proprio/vist_eval/emulated_vist.hpp"

namespace proprio::hand_sources {
namespace {

Result<PluginStarted> start_replay(const openxr_layer::SourceConfig& sc, DurationNs max_prediction_ns) {
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

Result<PluginStarted> start_live(const openxr_layer::SourceConfig& sc, DurationNs max_prediction_ns,
                                 TrackedPoseProvider* poses) {
  if (sc.hands.size() != 1) {
    return make_error(Errc::invalid_argument,
                      "a live vist source tracks one glove: give one hand in 'hands' (\"left\" or \"right\")");
  }
  std::vector<std::filesystem::path> inputs;
  auto glove = sc.glove_description.empty() ? Result<ImuGloveDescription>(ImuGloveDescription::vist_default())
                                            : ImuGloveDescription::load(sc.glove_description);
  if (!glove) return glove.error();
  if (!sc.glove_description.empty()) inputs.emplace_back(sc.glove_description);

  vist::VistLiveSourceOptions o;
  o.source.tracker.hand = sc.hands.front();
  o.source.history.max_prediction_ns = max_prediction_ns;
  vist::HeadPoseProvider head = vist::head_pose_provider(poses);

  if (sc.input == "device") {
    vist::VistDeviceOptions d;
    d.camera = sc.camera;
    d.camera_right = sc.camera_right;
    d.stereo_calibration = sc.stereo_calibration;
    d.imu.serial = sc.imu_serial;
    d.imu.path = sc.imu_path;
    auto source = vist::start_vist_devices(*glove, d, o, std::move(head));
    if (!source) return source.error();
    if (!d.stereo_calibration.empty()) inputs.emplace_back(d.stereo_calibration);
    if (d.camera_is_file()) inputs.emplace_back(d.camera);
    if (!d.camera_right.empty() && d.camera_is_file()) inputs.emplace_back(d.camera_right);
    return PluginStarted{std::move(*source), std::move(inputs)};
  }
  vist_eval::EmulatedVistOptions e;
  e.subject = sc.subject;
  e.seed = sc.seed;
  e.hand = sc.hands.front();
  e.truth_path = sc.truth_path;
  auto emulated = vist_eval::start_emulated_vist(*glove, e, o, std::move(head));
  if (!emulated) return emulated.error();
  const TimeNs started_ns = MonotonicClock::instance().now_ns();
  for (const auto& u : sc.unplugs) {
    emulated->rig->link().schedule_unplug(started_ns + seconds_to_ns(u.at_s), seconds_to_ns(u.duration_s));
  }
  return PluginStarted{std::move(emulated->source), std::move(inputs)};
}

Result<PluginStarted> start_vist(const openxr_layer::SourceConfig& sc, DurationNs max_prediction_ns,
                                 TrackedPoseProvider* poses) {
  if (sc.input == "device" || sc.input == "emulated") return start_live(sc, max_prediction_ns, poses);
  return start_replay(sc, max_prediction_ns);
}

}  // namespace
}  // namespace proprio::hand_sources

PROPRIO_DEFINE_HAND_SOURCE_PLUGIN("vist", proprio::hand_sources::start_vist)
