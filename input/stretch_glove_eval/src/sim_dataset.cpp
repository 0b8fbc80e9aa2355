#include "proprio/stretch_glove_eval/sim_dataset.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "proprio/core/log.hpp"
#include "proprio/core/random.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_glove/dataset.hpp"
#include "proprio/stretch_glove/readout.hpp"

namespace proprio::stretch_glove_eval {
namespace {

struct Job {
  sim::SimSubject subject;
  int session = 0;
};

struct JobResult {
  stretch_glove::DatasetSession data;
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

sim::StretchGloveSimOptions simulator_options(const SimDatasetOptions& a) {
  sim::StretchGloveSimOptions o;
  o.glove_seed = a.seed;  // one physical glove for the whole dataset
  return o;
}

sim::StretchSessionOptions session_options(const SimDatasetOptions& a, Handedness hand) {
  sim::StretchSessionOptions so;
  so.exploration_s = a.exploration_s;
  so.task_s = a.task_minutes * 60.0;
  so.task_motion.hand = hand;
  return so;
}

JobResult simulate(const Job& job, const SimDatasetOptions& a, const StretchGloveLayout& layout,
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
  auto readout = stretch_glove::make_readout(layout);
  if (!readout) return fail(readout.error());
  auto calibrator = stretch_glove::MinMaxCalibrator::create(layout);
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

  stretch_glove::CellFrame frame = readout->make_frame();
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
  auto calibration = calibrator->finish(a.tool + ": subject " + std::to_string(job.subject.id) + " session " +
                                        std::to_string(job.session) + " exploration");
  if (!calibration) {
    return fail(calibration.error().with_context("calibration from " + std::to_string(a.exploration_s) +
                                                 " s of exploration failed; use a longer --exploration-seconds"));
  }
  d.calibration = std::move(*calibration);
  return r;
}

}  // namespace

double SimDatasetOptions::total_simulated_minutes() const {
  const double seconds_per_session = exploration_s + task_minutes * 60.0;
  return static_cast<double>(subjects) * static_cast<double>(sessions) * seconds_per_session / 60.0;
}

Result<SimDatasetReport> write_sim_dataset(const SimDatasetOptions& a, const SimDatasetCallbacks& callbacks) {
  if (a.first_subject + a.subjects > sim::kSimSubjectCount) {
    return make_error(Errc::invalid_argument,
                      "subjects " + std::to_string(a.first_subject) + "-" +
                          std::to_string(a.first_subject + a.subjects - 1) +
                          " do not all exist: the simulated pool is subjects 0-" +
                          std::to_string(sim::kSimSubjectCount - 1) + "; lower --subjects or --first-subject");
  }
  StretchGloveLayout layout = StretchGloveLayout::thesis_default();
  if (!a.layout_file.empty()) {
    auto loaded = StretchGloveLayout::load(a.layout_file);
    if (!loaded) return loaded.error();
    layout = std::move(*loaded);
  }
  std::vector<Job> jobs;
  for (int k = 0; k < a.subjects; ++k) {
    auto subject = sim::sim_subject(a.first_subject + k);
    if (!subject) return subject.error();
    for (int s = 0; s < a.sessions; ++s) jobs.push_back({*subject, s});
  }

  const stretch_glove::ReadoutOptions readout_options;
  const sim::StretchGloveSimOptions sim_options = simulator_options(a);
  const double frame_rate = sim_options.measurement_rate_hz / readout_options.solve_every;
  auto writer = stretch_glove::DatasetWriter::create(a.out, layout, frame_rate, a.force);
  if (!writer) return writer.error();

  logger().info("layout: {}", layout.describe());
  logger().info("simulator: {} (seed per session from --seed, subject and session)", sim_options.describe());
  logger().info("sessions: {} (per session: the subject's dominant hand; motion seeds from the session seed)",
                session_options(a, Handedness::right).describe());
  logger().info("read-out: {}", readout_options.describe());

  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const std::size_t thread_count =
      std::min<std::size_t>(jobs.size(), a.threads > 0 ? static_cast<std::size_t>(a.threads) : hw);

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
  std::optional<Error> failure;
  SimDatasetReport report;
  std::size_t skipped = 0;
  double coverage_sum = 0.0;
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    JobResult r;
    {
      std::unique_lock lock(mutex);
      while (!results[i]) {
        ready.wait_for(lock, std::chrono::milliseconds(200));
        if (callbacks.on_progress) {
          callbacks.on_progress(static_cast<double>(measurements_done) / sim_options.measurement_rate_hz / 60.0);
        }
      }
      r = std::move(*results[i]);
      results[i].reset();
    }
    if (r.error) {
      failure = std::move(*r.error);
      break;
    }
    for (auto p : r.data.phase) (p == 0 ? report.exploration_frames : report.task_frames)++;
    skipped += r.skipped_frames;
    coverage_sum += r.coverage;
    if (r.coverage < report.coverage_min) {
      report.coverage_min = r.coverage;
      report.worst_advice = "subject " + std::to_string(r.data.subject) + " session " +
                            std::to_string(r.data.session) + ": " + r.advice;
    }
    logger().debug("subject {} session {}: {} frames, calibration coverage {:.0f} %", r.data.subject, r.data.session,
                   r.data.frames(), r.coverage * 100.0);
    if (r.coverage < stretch_glove::MinMaxCalibratorOptions{}.good_coverage) {
      logger().warn("subject {} session {}: the exploration phase covers the cells' ranges poorly ({}); its "
                    "calibration will squash the task data. Use a longer --exploration-seconds",
                    r.data.subject, r.data.session, r.advice);
    }
    if (auto st = writer->add_session(r.data); !st) {
      failure = make_error(st.error().code, "writing " + a.out + " failed: " + st.error().message);
      break;
    }
  }
  abort = failure.has_value();
  for (auto& w : workers) w.join();
  if (failure) return *failure;
  if (callbacks.on_sessions_written) callbacks.on_sessions_written();

  std::vector<int> subject_ids;
  for (int k = 0; k < a.subjects; ++k) subject_ids.push_back(a.first_subject + k);
  const nlohmann::json generator = {
      {"tool", a.tool},
      {"version", a.version},
      {"seed", a.seed},
      {"session_seed_rule", "mix_seed(mix_seed(seed, 1000 + subject), session); glove_seed = seed"},
      {"subjects", subject_ids},
      {"sessions_per_subject", a.sessions},
      {"task_minutes", a.task_minutes},
      {"exploration_seconds", a.exploration_s},
      {"layout_file", a.layout_file.empty() ? std::string("built-in thesis_default()") : a.layout_file},
      {"simulator", sim_options.describe()},
      {"session", session_options(a, Handedness::right).describe()},
      {"readout", readout_options.describe()},
      {"calibrator", stretch_glove::MinMaxCalibratorOptions{}.describe()},
      {"skipped_startup_frames", skipped},
  };
  if (auto st = writer->finish(generator.dump(2)); !st) {
    return make_error(st.error().code, "finishing " + a.out + " failed: " + st.error().message);
  }
  report.frames = writer->frames();
  report.frame_rate_hz = frame_rate;
  report.sessions = jobs.size();
  report.threads = thread_count;
  report.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  report.coverage_mean = coverage_sum / static_cast<double>(jobs.size());
  return report;
}

}  // namespace proprio::stretch_glove_eval
