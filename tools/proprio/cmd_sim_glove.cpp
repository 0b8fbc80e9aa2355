// proprio sim-glove: simulated stretch-glove sessions written as a training
// dataset for the pose network; the pipeline is stretch_glove_eval's
// write_sim_dataset (proprio/stretch_glove_eval/sim_dataset.hpp).
#include <cstdio>
#include <string>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/log.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/stretch_glove_eval/sim_dataset.hpp"

namespace proprio::cli {

namespace {

using SimGloveArgs = stretch_glove_eval::SimDatasetOptions;

int run_sim_glove(const SimGloveArgs& a) {
  SimGloveArgs o = a;
  o.version = PROPRIO_VERSION;
  ProgressBar progress("sim-glove", o.total_simulated_minutes(), "simulated minutes");
  stretch_glove_eval::SimDatasetCallbacks callbacks;
  callbacks.on_progress = [&progress](double minutes) { progress.update(minutes); };
  callbacks.on_sessions_written = [&progress] { progress.finish(); };
  auto r = stretch_glove_eval::write_sim_dataset(o, callbacks);
  if (!r) return logger().error("{}", r.error().message), 1;
  std::printf("wrote %s: %zu frames at %.0f Hz (%zu exploration, %zu task) from %zu sessions of %d subjects "
              "(seed %llu) in %.1f s on %zu threads\n",
              a.out.c_str(), r->frames, r->frame_rate_hz, r->exploration_frames, r->task_frames, r->sessions,
              a.subjects, static_cast<unsigned long long>(a.seed), r->elapsed_s, r->threads);
  std::printf("calibration coverage: mean %.0f %%, lowest %.0f %% (%s)\n", 100.0 * r->coverage_mean,
              100.0 * r->coverage_min, r->worst_advice.c_str());
  return 0;
}

}  // namespace

void add_sim_glove_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SimGloveArgs>();
  CLI::App* cmd = add_command(app, "sim-glove");
  cmd->add_option("--subjects", args->subjects, "How many simulated subjects")
      ->check(CLI::Range(1, sim::kSimSubjectCount))
      ->capture_default_str();
  cmd->add_option("--first-subject", args->first_subject, "First subject id (the pool is 0-14)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  cmd->add_option("--sessions", args->sessions, "Sessions (donnings) per subject")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  cmd->add_option("--minutes", args->task_minutes, "Task motion per session, minutes")
      ->check(CLI::Range(0.01, 600.0))
      ->capture_default_str();
  cmd->add_option("--exploration-seconds", args->exploration_s,
                  "Calibration exploration before the task, seconds (thesis: under a minute)")
      ->check(CLI::Range(2.0, 3600.0))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "Random seed; the same seed gives identical files")->capture_default_str();
  cmd->add_option("--layout", args->layout_file,
                  "Glove layout TOML (docs/stretch-glove-layout.md); default: the built-in thesis-like glove, "
                  "identical to config/stretch_glove.toml")
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", args->out, "Dataset directory to write")->required();
  cmd->add_option("--threads", args->threads, "Worker threads (0: one per core)")
      ->check(CLI::Range(0, 256))
      ->capture_default_str();
  cmd->add_flag("--force", args->force, "Replace a dataset already in --out");
  cmd->callback([args, &exit_code] { exit_code = run_sim_glove(*args); });
}

}  // namespace proprio::cli
