// A stand-in for libproprio_source_vist.so that shows what the layer's head
// provider answers: a thread asks it for the head every 5 ms (as a live VIST
// camera thread does at each capture) and serves a "hand" whose every joint is
// that head pose, in the source's frame. test_layer_live_gloves.cpp compares it
// with the mock runtime's VIEW motion at the same instants.
#include <atomic>
#include <mutex>
#include <thread>

#include "proprio/core/pose_history.hpp"
#include "proprio/hand_sources/plugin_abi.hpp"

namespace {

using namespace proprio;

class HeadProbeSource final : public HandSource {
 public:
  explicit HeadProbeSource(TrackedPoseProvider* poses) : poses_(poses), thread_([this] { run(); }) {}
  ~HeadProbeSource() override {
    stop_ = true;
    thread_.join();
  }
  std::string_view name() const noexcept override { return "head-probe"; }
  bool available(Handedness) const noexcept override { return true; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override {
    HandPose p;
    if (!is_usable(lookup(hand, t_ns, p))) return make_error(Errc::unavailable, "no head pose");
    return p;
  }
  PoseLookup lookup(Handedness, TimeNs t_ns, HandPose& out) noexcept override {
    std::lock_guard lock(mutex_);
    // The app locates at "now", past the newest sample: with one sample the
    // history predicts with zero velocity, and the swaying head has moved on.
    if (history_.size() < 2) return PoseLookup::empty;
    return history_.lookup(t_ns, out);
  }

 private:
  void run() {
    while (!stop_) {
      const TimeNs t = MonotonicClock::instance().now_ns();
      Pose T_source_head;
      if (poses_ && poses_->locate(TrackedPose::head, t, T_source_head)) {
        HandPose p;
        p.time_ns = t;
        p.hand = Handedness::right;
        p.active = true;
        p.T_world_joint.fill(T_source_head);
        p.radius_m.fill(0.01);
        p.set_all_flags(0xF);
        std::lock_guard lock(mutex_);
        (void)history_.push(p);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  TrackedPoseProvider* poses_;
  std::mutex mutex_;
  // Short horizons: on a starved machine this thread can sleep for tens of
  // milliseconds, and a long extrapolation or interpolation of the swaying head
  // is then off by millimetres for reasons that have nothing to do with the
  // provider. Past them the lookup is stale, and the test skips the frame.
  PoseHistory history_{PoseHistoryOptions{256, 10 * kNsPerMillisecond, 20 * kNsPerMillisecond}};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

Result<hand_sources::PluginStarted> start(const openxr_layer::SourceConfig&, DurationNs,
                                          TrackedPoseProvider* poses) {
  return hand_sources::PluginStarted{std::make_unique<HeadProbeSource>(poses), {}};
}

}  // namespace

PROPRIO_DEFINE_HAND_SOURCE_PLUGIN("vist", start)
