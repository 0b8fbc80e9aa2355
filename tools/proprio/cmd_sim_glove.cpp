// proprio sim-glove: simulated stretch-glove sessions written as a training
// dataset for the pose network (format: input/glove/include/proprio/glove/dataset.hpp).
// Each session is a new donning: a calibration exploration phase, then free
// motion, measured one strip combination at a time, recovered by the matrix
// read-out and min-max calibrated from its own exploration, as at run time.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/log.hpp"
#include "proprio/glove/calibration.hpp"
#include "proprio/glove/dataset.hpp"
#include "proprio/glove/readout.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::cli {

namespace {

struct SimGloveArgs {
  int subjects = sim::kSimSubjectCount;
  int first_subject = 0;
  int sessions = 3;
  double minutes = 5.0;
  double exploration_s = 60.0;
  std::uint64_t seed = 1;
  std::string layout;
  std::string out;
  bool force = false;
  int threads = 0;
};

struct Job {
  sim::SimSubject subject;
  int session = 0;
};

struct JobResult {
  glove::DatasetSession data;
  std::size_t skipped_frames = 0;  // before the first full cycle: some cells not yet known
  double coverage = 0.0;
  std::string advice;
  std::optional<Error> error;
};

// Per-session seed: the same (seed, subject, session) gives the same bytes
// whatever else is simulated alongside.
std::uint64_t session_seed(std::uint64_t seed, int subject, int session) {
  return mix_seed(mix_seed(seed, 1000 + static_cast<std::uint64_t>(subject)), static_cast<std::uint64_t>(session));
}

sim::StretchGloveSimOptions simulator_options(const SimGloveArgs& a) {
  sim::StretchGloveSimOptions o;
  o.glove_seed = a.seed;  // one physical glove for the whole dataset
  return o;
}

sim::StretchSessionOptions session_options(const SimGloveArgs& a, Handedness hand) {
  sim::StretchSessionOptions so;
  so.exploration_s = a.exploration_s;
  so.task_s = a.minutes * 60.0;
  so.task_motion.hand = hand;
  return so;
}

JobResult simulate(const Job& job, const SimGloveArgs& a, const StretchGloveLayout& layout,
                   std::atomic<std::uint64_t>& measurements_done, const std::atomic<bool>& abort) {
  JobResult r;
  auto fail = [&](Error e) {
    r.error = e.with_context("subject " + std::to_string(job.subject.id) + " session " + std::to_string(job.session));
    return std::move(r);
  };
  auto shape = job.subject.shape();
  if (!shape) return fail(shape.error());
  sim::StretchGloveSimOptions opts = simulator_options(a);
  opts.seed = session_seed(a.seed, job.subject.id, job.session);
  auto simulator = sim::StretchGloveSimulator::create(layout, *shape, opts, job.session);
  if (!simulator) return fail(simulator.error());
  sim::StretchGloveSession session(std::move(*simulator), session_options(a, job.subject.dominant_hand));
  auto readout = glove::MatrixReadout::create(layout);
  if (!readout) return fail(readout.error());
  auto calibrator = glove::MinMaxCalibrator::create(layout);
  if (!calibrator) return fail(calibrator.error());

  auto& d = r.data;
  d.subject = job.subject.id;
  d.session = job.session;
  d.donning = job.session;
  d.hand_length_m = job.subject.hand_length_m;
  d.hand_width_m = job.subject.hand_width_m;
  const auto frames = static_cast<std::size_t>(session.total_measurements() / 16 + 1);
  d.cells.reserve(frames * layout.cell_count());
  d.angles.reserve(frames * kHandDofCount);
  d.phase.reserve(frames);

  glove::CellFrame frame = readout->make_frame();
  sim::StretchSample s;
  std::uint64_t local = 0;
  while (session.next(s)) {
    if (++local % 4096 == 0) {
      measurements_done += 4096;
      if (abort) return fail(make_error(Errc::unavailable, "stopped"));
    }
    const auto& m = s.measurement;
    if (!readout->push(m.combination, m.capacitance_pf, m.time_ns, frame)) continue;
    // The first frames of a session come before every combination has been
    // measured once; a network never sees those at run time either.
    if (!frame.all_valid()) {
      ++r.skipped_frames;
      continue;
    }
    const bool exploring = s.phase == sim::StretchPhase::exploration;
    if (exploring) calibrator->add(frame);
    d.cells.insert(d.cells.end(), frame.cells_pf.begin(), frame.cells_pf.end());
    // Ground truth at the frame's time: the measurement that completed it.
    for (double v : s.angles) d.angles.push_back(static_cast<float>(v));
    d.phase.push_back(exploring ? 0 : 1);
  }
  measurements_done += local % 4096;
  const auto progress = calibrator->progress();
  r.coverage = progress.overall;
  r.advice = progress.advice();
  auto calibration = calibrator->finish("proprio sim-glove: subject " + std::to_string(job.subject.id) + " session " +
                                        std::to_string(job.session) + " exploration");
  if (!calibration) {
    return fail(calibration.error().with_context("calibration from " + std::to_string(a.exploration_s) +
                                                 " s of exploration failed; use a longer --exploration-seconds"));
  }
  d.calibration = std::move(*calibration);
  return r;
}

int run_sim_glove(const SimGloveArgs& a) {
  if (a.first_subject + a.subjects > sim::kSimSubjectCount) {
    logger().error("subjects {}-{} do not all exist: the simulated pool is subjects 0-{}; lower --subjects or "
                   "--first-subject",
                   a.first_subject, a.first_subject + a.subjects - 1, sim::kSimSubjectCount - 1);
    return 1;
  }
  StretchGloveLayout layout = StretchGloveLayout::thesis_default();
  if (!a.layout.empty()) {
    auto loaded = StretchGloveLayout::load(a.layout);
    if (!loaded) return logger().error("{}", loaded.error().message), 1;
    layout = std::move(*loaded);
  }
  std::vector<Job> jobs;
  for (int k = 0; k < a.subjects; ++k) {
    auto subject = sim::sim_subject(a.first_subject + k);
    if (!subject) return logger().error("{}", subject.error().message), 1;
    for (int s = 0; s < a.sessions; ++s) jobs.push_back({*subject, s});
  }

  const glove::ReadoutOptions readout_options;
  const sim::StretchGloveSimOptions sim_options = simulator_options(a);
  const double frame_rate = sim_options.measurement_rate_hz / readout_options.solve_every;
  auto writer = glove::DatasetWriter::create(a.out, layout, frame_rate, a.force);
  if (!writer) return logger().error("{}", writer.error().message), 1;

  logger().info("layout: {}", layout.describe());
  logger().info("simulator: {} (seed per session from --seed, subject and session)", sim_options.describe());
  logger().info("sessions: {} (per session: the subject's dominant hand; motion seeds from the session seed)",
                session_options(a, Handedness::right).describe());
  logger().info("read-out: {}", readout_options.describe());

  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const std::size_t thread_count =
      std::min<std::size_t>(jobs.size(), a.threads > 0 ? static_cast<std::size_t>(a.threads) : hw);
  const double seconds_per_session = a.exploration_s + a.minutes * 60.0;
  const double total_measurements =
      static_cast<double>(jobs.size()) * seconds_per_session * sim_options.measurement_rate_hz;

  std::vector<std::optional<JobResult>> results(jobs.size());
  std::mutex mutex;
  std::condition_variable ready;
  std::atomic<std::size_t> next_job{0};
  std::atomic<std::uint64_t> measurements_done{0};
  std::atomic<bool> abort{false};
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> workers;
  for (std::size_t t = 0; t < thread_count; ++t) {
    workers.emplace_back([&] {
      for (std::size_t i; (i = next_job++) < jobs.size() && !abort;) {
        JobResult r = simulate(jobs[i], a, layout, measurements_done, abort);
        std::lock_guard lock(mutex);
        results[i] = std::move(r);
        ready.notify_all();
      }
    });
  }

  // Sessions are written in order as they complete, so memory holds only
  // the sessions in flight.
  int exit_code = 0;
  ProgressBar progress("sim-glove", total_measurements / sim_options.measurement_rate_hz / 60.0,
                       "simulated minutes");
  std::size_t exploration_frames = 0, task_frames = 0, skipped = 0;
  double coverage_sum = 0.0, coverage_min = 1.0;
  std::string worst_advice;
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    JobResult r;
    {
      std::unique_lock lock(mutex);
      while (!results[i]) {
        ready.wait_for(lock, std::chrono::milliseconds(200));
        progress.update(static_cast<double>(measurements_done) / sim_options.measurement_rate_hz / 60.0);
      }
      r = std::move(*results[i]);
      results[i].reset();
    }
    if (r.error) {
      logger().error("{}", r.error->message);
      exit_code = 1;
      break;
    }
    for (auto p : r.data.phase) (p == 0 ? exploration_frames : task_frames)++;
    skipped += r.skipped_frames;
    coverage_sum += r.coverage;
    if (r.coverage < coverage_min) {
      coverage_min = r.coverage;
      worst_advice = "subject " + std::to_string(r.data.subject) + " session " + std::to_string(r.data.session) +
                     ": " + r.advice;
    }
    logger().debug("subject {} session {}: {} frames, calibration coverage {:.0f} %", r.data.subject, r.data.session,
                   r.data.frames(), r.coverage * 100.0);
    if (r.coverage < glove::MinMaxCalibratorOptions{}.good_coverage) {
      logger().warn("subject {} session {}: the exploration phase covers the cells' ranges poorly ({}); its "
                    "calibration will squash the task data. Use a longer --exploration-seconds",
                    r.data.subject, r.data.session, r.advice);
    }
    if (auto st = writer->add_session(r.data); !st) {
      logger().error("writing {} failed: {}", a.out, st.error().message);
      exit_code = 1;
      break;
    }
  }
  abort = exit_code != 0;
  for (auto& w : workers) w.join();
  if (exit_code != 0) return exit_code;
  progress.finish();

  std::vector<int> subject_ids;
  for (int k = 0; k < a.subjects; ++k) subject_ids.push_back(a.first_subject + k);
  const nlohmann::json generator = {
      {"tool", "proprio sim-glove"},
      {"version", PROPRIO_VERSION},
      {"seed", a.seed},
      {"session_seed_rule", "mix_seed(mix_seed(seed, 1000 + subject), session); glove_seed = seed"},
      {"subjects", subject_ids},
      {"sessions_per_subject", a.sessions},
      {"task_minutes", a.minutes},
      {"exploration_seconds", a.exploration_s},
      {"layout_file", a.layout.empty() ? std::string("built-in thesis_default()") : a.layout},
      {"simulator", sim_options.describe()},
      {"session", session_options(a, Handedness::right).describe()},
      {"readout", readout_options.describe()},
      {"calibrator", glove::MinMaxCalibratorOptions{}.describe()},
      {"skipped_startup_frames", skipped},
  };
  if (auto st = writer->finish(generator.dump(2)); !st) {
    logger().error("finishing {} failed: {}", a.out, st.error().message);
    return 1;
  }
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("wrote %s: %zu frames at %.0f Hz (%zu exploration, %zu task) from %zu sessions of %d subjects "
              "(seed %llu) in %.1f s on %zu threads\n",
              a.out.c_str(), writer->frames(), frame_rate, exploration_frames, task_frames, jobs.size(), a.subjects,
              static_cast<unsigned long long>(a.seed), elapsed, thread_count);
  std::printf("calibration coverage: mean %.0f %%, lowest %.0f %% (%s)\n",
              100.0 * coverage_sum / static_cast<double>(jobs.size()), 100.0 * coverage_min, worst_advice.c_str());
  return 0;
}

}  // namespace

void add_sim_glove_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SimGloveArgs>();
  CLI::App* cmd = app.add_subcommand(
      "sim-glove",
      "Simulate stretch-glove sessions and write a training dataset (cells.npy, angles.npy, session.npy, "
      "subject.npy, phase.npy, calib_min.npy, calib_max.npy, meta.json).\n"
      "Each session is a new donning: an exploration phase for the min-max calibration, then free motion.");
  cmd->add_option("--subjects", args->subjects, "How many simulated subjects")
      ->check(CLI::Range(1, sim::kSimSubjectCount))
      ->capture_default_str();
  cmd->add_option("--first-subject", args->first_subject, "First subject id (the pool is 0-14)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  cmd->add_option("--sessions", args->sessions, "Sessions (donnings) per subject")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  cmd->add_option("--minutes", args->minutes, "Task motion per session, minutes")
      ->check(CLI::Range(0.01, 600.0))
      ->capture_default_str();
  cmd->add_option("--exploration-seconds", args->exploration_s,
                  "Calibration exploration before the task, seconds (thesis: under a minute)")
      ->check(CLI::Range(2.0, 3600.0))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "Random seed; the same seed gives identical files")->capture_default_str();
  cmd->add_option("--layout", args->layout,
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
