// proprio run peg-in-hole --participant sim|ID: the thesis's peg-in-hole
// haptic manipulation study (docs/peg-in-hole.md), with simulated
// participants stepping simulated time, or with a real participant on the
// engine (HMD, window or headless render).
#include <fmt/format.h>

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <mutex>

#include "commands.hpp"
#include "proprio/peg_in_hole/live.hpp"
#include "proprio/peg_in_hole/study_runner.hpp"
#include "proprio/study/completion_time.hpp"
#include "proprio/study/session.hpp"
#include "run_args.hpp"

namespace proprio::cli {
// Named, not anonymous: the CLI is a unity build, and the sibling study
// commands define helpers with the same names.
namespace peg_run {

namespace fs = std::filesystem;
using namespace proprio::peg_in_hole;

int analyse_and_print(const fs::path& dir) {
  auto a = study::analyze_completion_time_study(dir);
  if (!a) return report_error(a.error());
  auto files = study::write_completion_time_report(*a, dir / "report", "Peg-in-hole: normalised completion time");
  if (!files) return report_error(files.error());
  std::printf("\n%s\nReport in %s/report/: anova.txt, summary.json, normalised_times.csv, normalised_time.svg\n",
              study::completion_time_text(*a).c_str(), dir.c_str());
  return 0;
}

int run_simulated(const RunArgs& a, const PegInHoleConfig& config, const fs::path& out) {
  // For the whole command, the report included: a second run on the same
  // --out fails here, before it deletes (--force) or appends anything.
  auto folder_lock = study::StudyFolderLock::acquire(out);
  if (!folder_lock) return report_error(folder_lock.error());
  SimulatedStudyOptions o;
  o.out_dir = out;
  o.participants = a.participants;
  o.seed = a.seed_given ? a.seed : config.seed;
  o.resume = a.resume;
  o.force = a.force;
  std::mutex print;
  o.progress = [&](const std::string& line) {
    std::lock_guard<std::mutex> lock(print);
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  };
  std::printf("peg-in-hole, %d simulated participants, seed %llu: %s\n", o.participants,
              static_cast<unsigned long long>(o.seed), config.describe().c_str());
  auto r = run_simulated_study(config, o);
  if (!r) return report_error(r.error());
  std::printf("\n%d trials run (%d recovered from an earlier run) in %.1f s wall time, %.0f s simulated; servo: %llu "
              "ticks, tick p50 %.0f us, p99 %.0f us, max %.0f us (stepped in simulated time, no sleeping)\n",
              r->trials_run, r->trials_recovered, r->wall_s, r->simulated_s, static_cast<unsigned long long>(r->ticks),
              r->tick_p50_us, r->tick_p99_us, r->tick_max_us);
  if (config.tracker == SimTracker::ftm) {
    // Means over the trials this invocation ran (the per-trial figures are in the CSV).
    std::printf("\nFTM glove (tracked hand = the FTM's estimate; compass: max |device field| at each IMU, fraction of "
                "compass samples the detector flagged):\n");
    std::printf("  setting        trials  max uT dorsum/thumb-mc/index-pp/middle-pp   flagged %% (mean)            "
                "truly disturbed (max)  angle err  wrist err\n");
    for (int s = 1; s <= 4; ++s) {
      const auto& f = r->ftm_by_setting[static_cast<std::size_t>(s - 1)];
      if (f.trials == 0) continue;
      const double n = f.trials;
      std::printf("  %d %-10s  %6d  %8.3f %8.3f %8.3f %8.3f   %5.2f %5.2f %5.2f %5.2f   %8.2f %%     %6.2f deg  %6.2f mm\n",
                  s, setting_from_number(s).label().c_str(), f.trials, f.max_disturbance_uT[0], f.max_disturbance_uT[1],
                  f.max_disturbance_uT[2], f.max_disturbance_uT[3], 100.0 * f.flagged_fraction_sum[0] / n,
                  100.0 * f.flagged_fraction_sum[1] / n, 100.0 * f.flagged_fraction_sum[2] / n,
                  100.0 * f.flagged_fraction_sum[3] / n, 100.0 * f.disturbed_fraction_max, f.angle_error_deg_sum / n,
                  f.wrist_error_mm_sum / n);
    }
  }
  return analyse_and_print(out);
}

int run_peg_in_hole_impl(const RunArgs& a) {
  PegInHoleConfig config;
  if (!a.design.empty()) {
    auto c = PegInHoleConfig::load_file(a.design);
    if (!c) return report_error(c.error());
    config = *c;
  }
  if (a.seed_given) config.seed = a.seed;
  if (!a.tracker.empty()) {
    auto kind = parse_sim_tracker(a.tracker);
    if (!kind) return report_error(kind.error().with_context("--tracker"));
    config.tracker = *kind;
  }
  const fs::path out = a.out_given ? fs::path(a.out) : fs::path("peg-in-hole-data");
  if (a.participant.empty()) {
    return report_error(make_error(Errc::invalid_argument,
                                   "peg-in-hole needs --participant: 'sim' (simulated participants) or the id of a "
                                   "real participant (letters, digits, '_' and '-')"));
  }
  if (a.participant == "sim") return run_simulated(a, config, out);
  if (config.tracker != SimTracker::ideal) {
    // A real participant's glove is a hand source: --hands ftm [sim|device].
    return report_error(make_error(Errc::invalid_argument,
                                   "--tracker (or [study] tracker) is for simulated participants; a real participant "
                                   "wearing the FTM runs with --hands ftm"));
  }

  // A real participant: the engine renders, the hand source and devices are
  // the flags' (defaults for this study: thumb, index and middle on 3-DOF
  // devices, unless --fingers/--device say otherwise).
  RunArgs live = a;
  if (live.fingers == std::vector<std::string>{"index"}) live.fingers = {"thumb", "index", "middle"};
  if (live.device == data_path("haptics/band_2dof.toml")) {
    live.device = config.devices.model.empty() ? data_path("haptics/platform_3dof.toml")
                                               : config.devices.model.string();
  }
  LiveRunner runner = [&live](engine::Scene scene, engine::AppInputs extra) -> Result<engine::AppReport> {
    live.scene = scene.name;
    auto options = app_options_from(live);
    if (!options) return options.error();
    // Until the trial's frame hook stops it (headless counts frames, so give
    // it more than any trial needs); the study folder is for data, not PNGs.
    options->frames = options->output == engine::OutputMode::headless ? std::numeric_limits<int>::max() / 2 : 0;
    options->out_dir.clear();
    auto inputs = app_inputs_from(live, scene, *options);
    if (!inputs) return inputs.error();
    inputs->on_frame = std::move(extra.on_frame);
    // The study's setting and physics; the CLI's own servo choices (priority, timing) stay.
    inputs->servo_options.remove_finger_abduction = extra.servo_options.remove_finger_abduction;
    inputs->servo_options.haptics_enabled = extra.servo_options.haptics_enabled;
    inputs->servo_options.force_scale = extra.servo_options.force_scale;
    inputs->contact_options = extra.contact_options;
    auto app = engine::App::create(std::move(scene), std::move(*inputs), *options);
    if (!app) return app.error();
    return run_app_until_done(**app);
  };
  LiveStudyOptions lo;
  lo.out_dir = out;
  lo.participant = a.participant;
  lo.resume = a.resume;
  lo.force = a.force;
  lo.progress = [](const std::string& line) { std::printf("%s\n", line.c_str()); };
  auto r = run_live_session(config, lo, runner);
  if (!r) return report_error(r.error());
  std::printf("\n%d trials recorded in %s\n", *r, out.c_str());
  return 0;
}

}  // namespace peg_run

int run_peg_in_hole(const RunArgs& a) { return peg_run::run_peg_in_hole_impl(a); }

}  // namespace proprio::cli
