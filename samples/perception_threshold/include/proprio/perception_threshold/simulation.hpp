#pragma once
// The whole perception-threshold study with simulated participants, headless
// and in simulated time: each participant's finger follows the protocol
// (swipes the cylinder while adapting, follows the arrows while blind, swipes
// with each sphere while answering) with motor noise; the contact force goes
// through a safety gate and the device model to an emulated fingertip device
// every simulated millisecond; the observer model (observer.hpp) answers from
// what it feels and sees. Trials are written by proprio::study::Session, so
// the files, the resume and the analysis are those of a real study.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "proprio/perception_threshold/protocol.hpp"

namespace proprio::perception {

struct SimulatedStudyOptions {
  std::filesystem::path out_dir;
  int participants = 8;
  std::optional<std::uint64_t> seed;  // replaces the design's seed
  int threads = 0;                    // 0: one per core
  bool force = false;                 // overwrite existing session files (otherwise they are resumed)
  std::filesystem::path device_model; // the emulated fingertip device (config/haptics/*.toml)
  bool sync_each_trial = true;        // fsync every row, as for a real participant
  // Tests: each participant stops after this many trials of this run (a crash).
  int stop_after_trials = -1;
  // Called after each trial from the participants' threads (serialised).
  std::function<void(int completed_trials, int total_trials)> progress;
  std::string describe() const;
};

struct SimulatedParticipant {
  std::string id;
  int index = 0;
  std::uint64_t seed = 0;
  double proprioceptive_noise_cm = 0;
  // The model's ground truth for this participant (cm).
  double true_threshold_none_cm = 0, true_threshold_true_sphere_cm = 0, true_threshold_false_sphere_cm = 0;
  double true_max_allowable_error_cm = 0;
  int trials_run = 0;        // in this run
  int trials_recovered = 0;  // found on disk (resumed)
  // Over all of the session's trials (a resumed run replays the recorded ones).
  int haptic_answers = 0;    // answers in haptic conditions
  int correct_attributions = 0;  // of those, the felt force attributed to the haptic sphere
  double peak_device_force_n = 0;
  std::filesystem::path csv;
};

struct SimulatedStudy {
  std::vector<SimulatedParticipant> participants;
  std::uint64_t seed = 0;
  double simulated_s = 0;
  double wall_s = 0;
  std::uint64_t servo_ticks = 0;
  std::filesystem::path ground_truth_json;  // out_dir/ground_truth.json
};

Result<SimulatedStudy> run_simulated_study(const PerceptionProtocol& protocol, const study::StudyDesign& design,
                                           const SimulatedStudyOptions& options);

}  // namespace proprio::perception
