#pragma once
// The study with a real participant on the engine: for each trial of the
// participant's plan an engine App renders the trial's scene (HMD, window or
// headless) while the servo loop couples the tracked hand to the proxy and
// drives the fingertip devices under the trial's setting. The per-frame hook
// applies the task's rules: the peg's colour follows the filtered grasp force,
// a break shows red, then the App is restarted with the peg back at its start
// (the trial clock keeps running through it), insertion ends the trial. Each trial is one
// fsync'ed CSV row (proprio::study::Session; resume after a crash).
#include <filesystem>
#include <functional>
#include <string>

#include "proprio/engine/app.hpp"
#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/monitor.hpp"

namespace proprio::peg_in_hole {

// Builds and runs an App for `scene` with the caller's hand source, devices
// and output, plus what `extra` carries (the per-frame hook and the setting's
// servo options). The CLI supplies it (tools/proprio/cmd_run_peg_in_hole.cpp).
using LiveRunner = std::function<Result<engine::AppReport>(engine::Scene scene, engine::AppInputs extra)>;

struct LiveStudyOptions {
  std::filesystem::path out_dir;
  std::string participant;
  int participant_index = -1;   // < 0: from the id's trailing number ("P07" -> 6)
  bool resume = false, force = false;
  bool familiarisation = true;
  std::function<void(const std::string&)> progress;
};

// Runs familiarisation (unless resuming) and the remaining trials; returns
// the number of trials recorded by this call.
Result<int> run_live_session(const PegInHoleConfig& config, const LiveStudyOptions& options, const LiveRunner& run);

// The per-frame rules of one live trial, separated from the App so tests can
// drive them with synthetic frames.
class LiveTrial {
 public:
  LiveTrial(const PegInHoleConfig& config, const engine::Scene& scene, const std::string& instruction,
            double time_limit_s, bool finish_on_insert, const Vec3& p_hole_in_world, const Vec3& p_peg_start_in_world);
  void on_frame(engine::FrameContext& c);
  bool done() const noexcept { return done_; }
  bool needs_respawn() const noexcept { return respawn_pending_; }
  // The next App run after a respawn: the clock continues from here.
  void continue_after_respawn() noexcept;
  bool inserted() const noexcept { return inserted_; }
  double elapsed_s() const noexcept { return elapsed_s_; }
  int breaks() const noexcept { return breaks_; }
  double peak_force_n() const noexcept { return peak_; }
  double mean_force_n() const noexcept { return contact_frames_ ? force_sum_ / contact_frames_ : 0.0; }

 private:
  PegInHoleConfig config_;
  std::string instruction_;
  double limit_s_;
  bool finish_on_insert_;
  int peg_entity_ = -1, peg_object_ = 0;
  Vec3 p_hole_, p_peg_start_;
  TimeNs start_ns_ = -1, broken_at_ns_ = 0;
  double elapsed_s_ = 0.0, peak_ = 0.0, force_sum_ = 0.0;
  int contact_frames_ = 0, breaks_ = 0;
  bool done_ = false, inserted_ = false, respawn_pending_ = false;
  BreakMonitor monitor_;
  double carried_s_ = 0.0;  // time of earlier App runs of this trial
};

}  // namespace proprio::peg_in_hole
