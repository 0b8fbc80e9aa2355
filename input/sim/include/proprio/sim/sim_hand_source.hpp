#pragma once
// The procedural hand as a live HandSource: a thread samples the hand-motion
// generator at a tracker-like rate, stamps each pose with the clock and keeps
// a PoseHistory per hand, so consumers see what they would see from a real
// tracker (latency, a finite rate, prediction, staleness).
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/sim/hand_motion.hpp"

namespace proprio::sim {

struct SimHandSourceOptions {
  int subject = 3;
  MotionProtocol protocol = MotionProtocol::free_motion;
  std::uint64_t seed = 1;
  double rate_hz = 90.0;  // 0: no thread; call produce() yourself (tests)
  std::vector<Handedness> hands{Handedness::left, Handedness::right};
  // Poses in the simulated head frame (a head-mounted camera's view; bind the
  // source to the VIEW space), instead of the simulation's world frame.
  bool relative_to_head = true;
  PoseHistoryOptions history{};

  std::string describe() const;
};

class SimHandSource final : public HandSource {
 public:
  // The motion starts at the clock's current time.
  static Result<std::unique_ptr<SimHandSource>> create(SimHandSourceOptions options,
                                                       const Clock& clock = MonotonicClock::instance());
  ~SimHandSource() override;
  SimHandSource(const SimHandSource&) = delete;
  SimHandSource& operator=(const SimHandSource&) = delete;

  std::string_view name() const noexcept override { return "sim"; }
  bool available(Handedness hand) const noexcept override;
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  // Samples every hand at `now_ns` and adds the poses to the history. The
  // thread calls this; with rate_hz = 0 a test does.
  void produce(TimeNs now_ns);
  const SimHandSourceOptions& options() const noexcept { return options_; }

 private:
  SimHandSource(SimHandSourceOptions options, const Clock& clock);
  void run();
  HandPose sample_relative_to_head(HandMotionGenerator& g, TimeNs t_since_start_ns, TimeNs stamp_ns);

  SimHandSourceOptions options_;
  const Clock& clock_;
  TimeNs start_ns_ = 0;
  std::array<std::optional<HandMotionGenerator>, 2> generators_;  // producer thread only
  mutable std::mutex mutex_;  // guards histories_
  std::array<std::optional<PoseHistory>, 2> histories_;
  std::mutex stop_mutex_;
  std::condition_variable stop_cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace proprio::sim
