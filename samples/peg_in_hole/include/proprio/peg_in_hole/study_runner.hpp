#pragma once
// Running the study with simulated participants: each participant is a
// SimulatedUser with its own seed, familiarised (spring, then ground), then
// the 20 main trials of its plan through a proprio::study::Session (one
// fsync'ed CSV row per trial, JSON sidecar, resume after a crash), each trial
// also written as a session recording (.prec: tracked and proxy hand, peg
// pose, events). Participants run in parallel on worker threads; simulated
// time is stepped, never slept.
#include <atomic>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/haptics/servo_loop.hpp"
#include "proprio/peg_in_hole/config.hpp"
#include "proprio/peg_in_hole/ftm_glove.hpp"
#include "proprio/peg_in_hole/protocol.hpp"
#include "proprio/peg_in_hole/simulated_user.hpp"
#include "proprio/peg_in_hole/world.hpp"

namespace proprio::peg_in_hole {

struct TrialResult {
  double completion_time_s = 0.0;  // the clock runs through breaks and respawns
  bool completed = false;          // inserted before the timeout
  int breaks = 0, drops = 0, regrasps = 0;
  double peak_force_n = 0.0, mean_force_n = 0.0;
  haptics::ServoTiming timing;
  std::optional<FtmTrialFigures> ftm;  // with SimulatedTrialOptions::ftm_glove
};

struct SimulatedTrialOptions {
  WorldPhase phase = WorldPhase::trial;
  double time_limit_s = 120.0;       // trial timeout, or the familiarisation phase's length
  std::filesystem::path recording;   // empty: no recording
  double recording_rate_hz = 100.0;
  std::string recording_meta;        // JSON for the recording's event stream
  // Called at each break, respawn, drop and insertion with the user's phase
  // then ("lift", "align", ...): where a policy fails (peg_probe WHY=1).
  std::function<void(PegEvent::Kind, std::string_view user_phase)> on_event;
  // The participant wears this simulated FTM glove (config.tracker == ftm):
  // the world gets its tracked hand, its compasses feel the devices.
  SimulatedFtmGlove* ftm_glove = nullptr;
};

// What a participant in `w` sees (the peg, its colour, the rendered hand,
// the hole) and feels (each device's force sensors), this tick.
Percept perceive(const PegWorld& w);

// One trial (or familiarisation phase) of a simulated participant.
Result<TrialResult> run_simulated_trial(const PegInHoleConfig& config, const TrialLayout& layout, Setting setting,
                                        SimulatedUser& user, const HandModel& hand_model,
                                        std::shared_ptr<const haptics::FingertipDeviceModel> device_model,
                                        const SimulatedTrialOptions& options);

struct SimulatedStudyOptions {
  std::filesystem::path out_dir;
  int participants = 10;
  std::uint64_t seed = 1;   // the study seed (overrides config.seed)
  int threads = 2;
  bool resume = false;      // continue sessions already in out_dir
  bool force = false;       // delete existing session data first
  bool familiarisation = true;
  // Progress lines ("P03 trial 7/20: setting 2, 14.2 s, 1 break"); may be
  // called from worker threads (the caller serialises output).
  std::function<void(const std::string&)> progress;
  // Test hook: stop (as if killed) after this many trials in total; < 0 = never.
  int stop_after_trials = -1;
};

struct SimulatedStudyReport {
  int participants = 0;
  int trials_run = 0;        // this invocation (resumed trials excluded)
  int trials_recovered = 0;  // found on resume
  double wall_s = 0.0;
  double simulated_s = 0.0;
  // Servo timing over every trial this invocation ran (worst of each).
  std::uint64_t ticks = 0, overruns = 0;
  double tick_p50_us = 0, tick_p99_us = 0, tick_max_us = 0;
  std::vector<std::filesystem::path> csv_files;
  // --tracker ftm: per setting (index number()-1) over the trials run, the
  // compass figures' means and maxima (docs/peg-in-hole.md).
  struct FtmSettingSummary {
    int trials = 0;
    std::array<double, kFtmCompassCount> max_disturbance_uT{};  // max over trials
    std::array<double, kFtmCompassCount> flagged_fraction_sum{};
    double disturbed_fraction_max = 0.0;
    double angle_error_deg_sum = 0.0, wrist_error_mm_sum = 0.0;
  };
  std::array<FtmSettingSummary, 4> ftm_by_setting{};
};

Result<SimulatedStudyReport> run_simulated_study(const PegInHoleConfig& config, const SimulatedStudyOptions& options);

// Participant ids of simulated runs: "sim01", "sim02", ...
std::string simulated_participant_id(int index);

}  // namespace proprio::peg_in_hole
