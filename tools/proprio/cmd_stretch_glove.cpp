// proprio bench glove: the stretch glove's pipeline on held-out simulated subjects.
// proprio calibrate glove: the per-user min-max exploration, saved for later sessions.
#include <algorithm>
#include <cstdio>
#include <chrono>
#include <ctime>
#include <future>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include <csignal>
#include <filesystem>

#include "proprio/core/data_dir.hpp"
#include "proprio/core/replay_source.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_glove/dataset_recorder.hpp"
#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_glove/readout.hpp"
#include "proprio/stretch_glove_eval/glove_evaluation.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::cli {
namespace {

Result<StretchGloveLayout> load_layout(const std::string& path) {
  if (path.empty()) return StretchGloveLayout::thesis_default();
  return StretchGloveLayout::load(path);
}

struct BenchGloveArgs {
  std::string model = data_path("models/stretch_glove_generic.onnx");
  std::string global_model;  // trained with --calibration global (the thesis's scenario 3)
  std::string layout;
  int subjects = 5;  // held-out subjects 10..14
  double minutes = 2.0;
  double exploration_s = 60.0;
  std::uint64_t seed = 1;
  int threads = 0;
  std::vector<std::string> without;  // simulator effects off in every case
  bool realism_ablation = false;     // every effect on, each off in turn, all off
  bool json = false;
};

int run_bench_glove(const BenchGloveArgs& a) {
  auto layout = load_layout(a.layout);
  if (!layout) {
    std::fprintf(stderr, "error: %s\n", layout.error().message.c_str());
    return 1;
  }
  using stretch_glove_eval::GloveRealismEffect;
  std::vector<GloveRealismEffect> off;
  for (const std::string& w : a.without) {
    auto e = stretch_glove_eval::parse_glove_realism_effect(w);
    if (!e) return std::fprintf(stderr, "error: --without: '%s' is not a simulator effect\n", w.c_str()), 2;
    off.push_back(*e);
  }
  // The simulator variants: one (with --without), or the realism ablation.
  struct Variant {
    std::string name;
    std::vector<GloveRealismEffect> off;
  };
  std::vector<Variant> variants;
  if (a.realism_ablation) {
    variants.push_back({"all effects", off});
    for (auto e : stretch_glove_eval::kGloveRealismEffects) {
      if (std::find(off.begin(), off.end(), e) != off.end()) continue;
      auto v = off;
      v.push_back(e);
      variants.push_back({"without " + std::string(to_string(e)), v});
    }
    variants.push_back({"ideal glove", {stretch_glove_eval::kGloveRealismEffects.begin(),
                                        stretch_glove_eval::kGloveRealismEffects.end()}});
  } else {
    variants.push_back({"", off});
  }
  struct Job {
    stretch_glove_eval::GloveSessionSpec spec;
    std::size_t variant = 0;
  };
  std::vector<Job> jobs;
  std::vector<stretch_glove_eval::CalibrationMode> modes = {stretch_glove_eval::CalibrationMode::session};
  if (!a.global_model.empty()) modes.push_back(stretch_glove_eval::CalibrationMode::global);
  for (std::size_t v = 0; v < variants.size(); ++v) {
    for (auto mode : modes) {
      for (int i = 0; i < a.subjects; ++i) {
        stretch_glove_eval::GloveSessionSpec s;
        s.subject = stretch_glove_eval::kFirstHeldOutSubject + i;
        s.task_s = a.minutes * 60.0;
        s.exploration_s = a.exploration_s;
        s.seed = a.seed;
        s.calibration = mode;
        for (auto e : variants[v].off) s.switch_off(e);
        jobs.push_back({s, v});
      }
    }
  }
  const unsigned threads = a.threads > 0 ? static_cast<unsigned>(a.threads)
                                         : std::max(1u, std::thread::hardware_concurrency());
  ProgressBar progress("bench glove", static_cast<double>(jobs.size()), "sessions");
  std::size_t done = 0;
  std::vector<Result<stretch_glove_eval::GloveSessionResult>> results(jobs.size(),
                                                              make_error(Errc::unavailable, "not run"));
  std::vector<std::future<void>> running;
  std::size_t next = 0;
  while (next < jobs.size() || !running.empty()) {
    while (next < jobs.size() && running.size() < threads) {
      const std::size_t j = next++;
      running.push_back(std::async(std::launch::async, [&, j] {
        const bool global = jobs[j].spec.calibration == stretch_glove_eval::CalibrationMode::global;
        results[j] = stretch_glove_eval::run_glove_session(*layout, global ? a.global_model : a.model, jobs[j].spec);
      }));
    }
    running.front().get();
    running.erase(running.begin());
    progress.update(static_cast<double>(++done));
  }
  progress.finish();

  int failures = 0;
  nlohmann::json out = {{"model", a.model},
                        {"layout", layout->name},
                        {"held_out_subjects", a.subjects},
                        {"task_minutes", a.minutes},
                        {"exploration_s", a.exploration_s},
                        {"seed", a.seed},
                        {"note", "simulated subjects; simulated accuracy is not real-world accuracy"}};
  if (!a.json) {
    std::printf("\nStretch glove on held-out simulated subjects (%d..%d), %.1f min of free motion each\n",
                stretch_glove_eval::kFirstHeldOutSubject, stretch_glove_eval::kFirstHeldOutSubject + a.subjects - 1, a.minutes);
    if (!off.empty() && !a.realism_ablation) {
      std::printf("simulator effects off:");
      for (auto e : off) std::printf(" %s", std::string(to_string(e)).c_str());
      std::printf("\n");
    }
    std::printf("%-40s %8s %10s %10s %12s\n", "calibration", "mean deg", "p95 deg", "1€ mean", "us/frame");
  }
  for (std::size_t c = 0; c < variants.size() * modes.size(); ++c) {
    const std::size_t v = c / modes.size();
    const auto mode = modes[c % modes.size()];
    std::vector<stretch_glove_eval::GloveSessionResult> ok;
    nlohmann::json per_subject = nlohmann::json::array();
    for (std::size_t j = 0; j < jobs.size(); ++j) {
      if (jobs[j].spec.calibration != mode || jobs[j].variant != v) continue;
      if (!results[j]) {
        ++failures;
        std::fprintf(stderr, "subject %d (%s): %s\n", jobs[j].spec.subject, std::string(to_string(mode)).c_str(),
                     results[j].error().message.c_str());
        continue;
      }
      ok.push_back(*results[j]);
      per_subject.push_back({{"subject", jobs[j].spec.subject},
                             {"mean_deg", results[j]->mean_deg},
                             {"filtered_mean_deg", results[j]->filtered_mean_deg},
                             {"calibration_coverage", results[j]->calibration_coverage}});
    }
    if (ok.empty()) continue;
    const auto agg = stretch_glove_eval::aggregate(ok);
    nlohmann::json dofs;
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      dofs[std::string(to_string(static_cast<HandDof>(d)))] = agg.dof_mean_deg[d];
    }
    nlohmann::json effects_off = nlohmann::json::array();
    for (auto e : variants[v].off) effects_off.push_back(std::string(to_string(e)));
    out["cases"].push_back({{"calibration", std::string(to_string(mode))},
                            {"simulator_effects_off", effects_off},
                            {"sessions", agg.sessions},
                            {"frames", agg.frames},
                            {"mean_deg", agg.mean_deg},
                            {"p95_deg", agg.p95_deg},
                            {"filtered_mean_deg", agg.filtered_mean_deg},
                            {"pipeline_us_per_frame", agg.pipeline_us_per_frame},
                            {"per_dof_mean_deg", dofs},
                            {"per_subject", per_subject}});
    if (!a.json) {
      std::string name(to_string(mode));
      if (!variants[v].name.empty()) name += ", " + variants[v].name;
      std::printf("%-40s %8.2f %10.2f %10.2f %12.1f\n", name.c_str(), agg.mean_deg, agg.p95_deg,
                  agg.filtered_mean_deg, agg.pipeline_us_per_frame);
    }
  }
  if (a.json) std::printf("%s\n", out.dump(2).c_str());
  return failures == 0 ? 0 : 1;
}

struct CalibrateGloveArgs {
  std::string layout;
  std::string out;
  int sim_subject = -1;
  double seconds = 60.0;
  std::uint64_t seed = 1;
  bool force = false;
};

// The exploration phase on a live read-out board: measurements through the
// same read-out and calibrator as the run-time pipeline, with advice every 5 s.
Result<stretch_glove::MinMaxCalibration> calibrate_from_board(const StretchGloveLayout& layout, double seconds,
                                                      stretch_glove::CalibrationProgress& progress) {
  devices::StretchDeviceOptions o;
  o.stream.expected_top_strips = static_cast<std::uint8_t>(layout.top_strips);
  o.stream.expected_bottom_strips = static_cast<std::uint8_t>(layout.bottom_strips);
  devices::StretchDevice device(std::make_unique<hid::HidapiTransport>(devices::stretch_board_selector()), o);
  if (auto st = device.start(); !st) return st.error();
  auto readout = stretch_glove::make_readout(layout);
  if (!readout) return readout.error();
  auto calibrator = stretch_glove::MinMaxCalibrator::create(layout);
  if (!calibrator) return calibrator.error();
  stretch_glove::CellFrame frame = readout->make_frame();
  const TimeNs start = MonotonicClock::instance().now_ns();
  TimeNs next_report = start + 5 * kNsPerSecond;
  devices::StretchSample m;
  while (MonotonicClock::instance().now_ns() < start + static_cast<TimeNs>(seconds * 1e9)) {
    if (!device.pop(m)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      continue;
    }
    if (readout->push(m.combination, m.capacitance_pf, m.time_ns, frame) && frame.all_valid()) calibrator->add(frame);
    if (MonotonicClock::instance().now_ns() >= next_report) {
      next_report += 5 * kNsPerSecond;
      const auto st = device.stats();
      std::printf("  %3.0f s: %s (board: %s, %llu measurements)\n",
                  1e-9 * static_cast<double>(MonotonicClock::instance().now_ns() - start),
                  calibrator->progress().advice().c_str(), hid::to_string(st.state),
                  static_cast<unsigned long long>(st.samples_delivered));
    }
  }
  device.stop();
  progress = calibrator->progress();
  char created[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(created, sizeof created, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return calibrator->finish("proprio calibrate glove (read-out board)", created);
}

int run_calibrate_glove(const CalibrateGloveArgs& a) {
  auto layout = load_layout(a.layout);
  if (!layout) {
    std::fprintf(stderr, "error: %s\n", layout.error().message.c_str());
    return 1;
  }
  if (!a.force && std::filesystem::exists(a.out)) {
    std::fprintf(stderr, "error: %s exists; pass --force to overwrite it\n", a.out.c_str());
    return 1;
  }
  std::printf("Explore for %.0f s: make a fist, spread and close the fingers, bend each finger on its own, move the "
              "thumb across the palm and out\n",
              a.seconds);
  Result<stretch_glove::MinMaxCalibration> cal = make_error(Errc::unavailable, "not run");
  stretch_glove::CalibrationProgress progress;
  if (a.sim_subject >= 0) {
    auto r = stretch_glove_eval::calibrate_simulated(*layout, a.sim_subject, a.seed, a.seconds,
                                             "proprio calibrate glove --sim-subject " + std::to_string(a.sim_subject));
    if (r) {
      progress = r->progress;
      cal = std::move(r->calibration);
    } else {
      cal = r.error();
    }
  } else {
    cal = calibrate_from_board(*layout, a.seconds, progress);
  }
  if (!cal) {
    std::fprintf(stderr, "error: %s\n", cal.error().message.c_str());
    return 1;
  }
  if (auto st = cal->save(a.out); !st) {
    std::fprintf(stderr, "error: %s\n", st.error().message.c_str());
    return 1;
  }
  std::printf("%s\nCalibration of %zu cells from %zu frames written to %s\n", progress.advice().c_str(),
              cal->cell_count(), cal->frames, a.out.c_str());
  return 0;
}

struct RecordGloveArgs {
  std::string out;
  std::string truth;
  std::string truth_stream;
  std::string layout;
  std::string hand = "right";
  int subject = 0, session = 0, donning = -1;
  double hand_length_m = 0.19, hand_width_m = 0.09;
  double exploration_s = 60.0;
  double seconds = 360.0;
  bool force = false;
};

// Captures the board's frames, then pairs them with the ground-truth
// recording (made at the same time, on CLOCK_MONOTONIC) into a dataset.
int run_record_glove(const RecordGloveArgs& a) {
  auto layout = load_layout(a.layout);
  if (!layout) return report_error(layout.error());
  if (!a.force && std::filesystem::exists(a.out)) {
    return report_error(Error{Errc::invalid_argument, a.out + " exists; pass --force to replace it"});
  }
  auto recorder = stretch_glove::DatasetRecorder::create(*layout);
  if (!recorder) return report_error(recorder.error());
  devices::StretchDeviceOptions o;
  o.stream.expected_top_strips = static_cast<std::uint8_t>(layout->top_strips);
  o.stream.expected_bottom_strips = static_cast<std::uint8_t>(layout->bottom_strips);
  devices::StretchDevice device(std::make_unique<hid::HidapiTransport>(devices::stretch_board_selector()), o);
  if (auto st = device.start(); !st) return report_error(st.error());

  std::printf("Recording %.0f s: first %.0f s of exploration (make a fist, spread and close the fingers, bend each "
              "finger on its own, move the thumb across the palm and out), then the task. Ctrl-C ends early.\n",
              a.seconds, a.exploration_s);
  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  const TimeNs start = MonotonicClock::instance().now_ns();
  const TimeNs exploration_end = start + seconds_to_ns(a.exploration_s);
  TimeNs next_report = start + 5 * kNsPerSecond;
  devices::StretchSample m;
  while (!g_sigint_stop.load() && MonotonicClock::instance().now_ns() < start + seconds_to_ns(a.seconds)) {
    bool got = false;
    while (device.pop(m)) {
      recorder->push(m);
      got = true;
    }
    if (!got) std::this_thread::sleep_for(std::chrono::milliseconds(2));
    if (const TimeNs now = MonotonicClock::instance().now_ns(); now >= next_report) {
      next_report += 5 * kNsPerSecond;
      const auto st = device.stats();
      std::printf("  %4.0f s %-11s board %s, %zu frames (%zu incomplete)\n", 1e-9 * static_cast<double>(now - start),
                  now < exploration_end ? "exploring" : "task", hid::to_string(st.state), recorder->frames(),
                  recorder->stats().frames_invalid);
      std::fflush(stdout);
    }
  }
  device.stop();
  std::signal(SIGINT, previous);
  if (recorder->frames() == 0) {
    return report_error(Error{Errc::unavailable, "no complete frame came from the read-out board; is it plugged in? "
                                                 "'proprio stretch-board list' and 'monitor' check it"});
  }

  ReplayOptions ro;
  ro.stream_name_filter = a.truth_stream;
  auto truth = ReplayHandSource::open(a.truth, ro);
  if (!truth) return report_error(truth.error());
  stretch_glove::DatasetSessionInfo info;
  info.subject = a.subject;
  info.session = a.session;
  info.donning = a.donning >= 0 ? a.donning : a.session;
  info.hand = *parse_handedness(a.hand);
  info.hand_length_m = a.hand_length_m;
  info.hand_width_m = a.hand_width_m;
  info.exploration_end_ns = exploration_end;
  auto session = recorder->finish(*truth, info);
  if (!session) return report_error(session.error());
  auto writer = stretch_glove::DatasetWriter::create(a.out, *layout, 60.0, a.force);
  if (!writer) return report_error(writer.error());
  if (auto st = writer->add_session(*session); !st) return report_error(st.error());
  nlohmann::json generator = {{"tool", "proprio record glove"}, {"truth", a.truth}, {"truth_stream", a.truth_stream}};
  if (auto st = writer->finish(generator.dump()); !st) return report_error(st.error());
  const auto& st = recorder->stats();
  std::printf("wrote %s: %zu frames (%zu exploration, %zu task); %zu frames without ground truth dropped, %zu "
              "incomplete; the truth fits the hand model to %.1f mm\n",
              a.out.c_str(), st.paired, st.exploration, st.task, st.without_truth, st.frames_invalid,
              1e3 * st.ik_residual_max_m);
  return 0;
}

}  // namespace

void add_stretch_glove_commands(CLI::App& app, int& exit_code) {
  auto rargs = std::make_shared<RecordGloveArgs>();
  auto* r = add_command(app, "record glove");
  r->add_option("--out", rargs->out, "dataset directory to write")->required();
  r->add_option("--truth", rargs->truth, "ground-truth hand recording (.prec), made during this recording")
      ->required()
      ->check(CLI::ExistingFile);
  r->add_option("--truth-stream", rargs->truth_stream, "which HandPose stream of --truth (default: the tracker's)");
  r->add_option("--layout", rargs->layout, "glove layout TOML (default: the thesis-like glove)");
  r->add_option("--hand", rargs->hand, "which hand wears the glove")
      ->check(CLI::IsMember({"left", "right"}))
      ->capture_default_str();
  r->add_option("--subject", rargs->subject, "subject id in the dataset")->capture_default_str();
  r->add_option("--session", rargs->session, "session number in the dataset")->capture_default_str();
  r->add_option("--donning", rargs->donning, "donning number (default: the session number)");
  r->add_option("--hand-length", rargs->hand_length_m, "wrist crease to middle fingertip, m")
      ->check(CLI::Range(0.12, 0.26))
      ->capture_default_str();
  r->add_option("--hand-width", rargs->hand_width_m, "across the knuckles, m")
      ->check(CLI::Range(0.06, 0.13))
      ->capture_default_str();
  r->add_option("--exploration-seconds", rargs->exploration_s, "calibration exploration at the start")
      ->check(CLI::Range(5.0, 600.0))
      ->capture_default_str();
  r->add_option("--seconds", rargs->seconds, "whole recording")->check(CLI::Range(10.0, 7200.0))->capture_default_str();
  r->add_flag("--force", rargs->force, "replace --out");
  r->callback([rargs, &exit_code] { exit_code = run_record_glove(*rargs); });

  auto args = std::make_shared<BenchGloveArgs>();
  auto* g = add_command(app, "bench glove");
  g->add_option("--model", args->model, "pose model (.onnx with its .json sidecar)")->capture_default_str();
  g->add_option("--global-model", args->global_model,
                "also score a model trained with the training data's min-max (train.py --calibration global)");
  g->add_option("--layout", args->layout, "glove layout TOML (default: the thesis-like glove)");
  g->add_option("--subjects", args->subjects, "held-out simulated subjects (10, 11, ...)")
      ->check(CLI::Range(1, sim::kSimSubjectCount - stretch_glove_eval::kFirstHeldOutSubject))
      ->capture_default_str();
  g->add_option("--minutes", args->minutes, "minutes of free motion per subject")
      ->check(CLI::Range(0.1, 60.0))
      ->capture_default_str();
  g->add_option("--exploration-seconds", args->exploration_s, "calibration exploration per session")
      ->check(CLI::Range(5.0, 600.0))
      ->capture_default_str();
  g->add_option("--seed", args->seed, "seed (1: the glove the shipped model was trained on)")->capture_default_str();
  g->add_option("--threads", args->threads, "sessions in parallel (0: one per core)")->capture_default_str();
  std::vector<std::string> glove_effects;
  for (auto e : stretch_glove_eval::kGloveRealismEffects) glove_effects.emplace_back(to_string(e));
  g->add_option("--without", args->without,
                "switch these simulator effects off (comma-separated): " + CLI::detail::join(glove_effects))
      ->delimiter(',')
      ->check(CLI::IsMember(glove_effects));
  g->add_flag("--realism-ablation", args->realism_ablation,
              "score every simulator effect on, each off in turn, and all off (the ideal glove)");
  g->add_flag("--json", args->json, "print the metrics as JSON");
  g->callback([args, &exit_code] { exit_code = run_bench_glove(*args); });

  auto cargs = std::make_shared<CalibrateGloveArgs>();
  // The description is the command table's (command_table.cpp): `calibrate` spans programs.
  auto* c = add_command(app, "calibrate glove");
  c->add_option("--out", cargs->out, "calibration file to write (TOML)")->required();
  c->add_option("--layout", cargs->layout, "glove layout TOML (default: the thesis-like glove)");
  c->add_option("--sim-subject", cargs->sim_subject,
                "calibrate the simulated glove on this subject (0-14) instead of a read-out board on USB")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1));
  c->add_option("--seconds", cargs->seconds, "exploration length")->check(CLI::Range(5.0, 600.0))->capture_default_str();
  c->add_option("--seed", cargs->seed, "simulation seed")->capture_default_str();
  c->add_flag("--force", cargs->force, "overwrite --out");
  c->callback([cargs, &exit_code] { exit_code = run_calibrate_glove(*cargs); });
}

}  // namespace proprio::cli
