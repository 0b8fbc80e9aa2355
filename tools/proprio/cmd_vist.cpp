// proprio bench vist: the VIST evaluation protocol on simulated subjects.
// proprio sim-vist: one simulated subject's session, recorded for replay.
// proprio track vist: the VIST tracker on a recorded session, or live on a
// glove (USB HID IMU board) and a stereo camera (or a video file).
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <future>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/log.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/vist_live_source.hpp"
#include "proprio/vist_eval/evaluation.hpp"

namespace proprio::cli {
namespace {

using vist_eval::Ablation;
using vist_eval::Challenge;

struct BenchVistArgs {
  int subjects = 5;
  int first_subject = 7;  // with --subjects 1: which one
  double minutes = 5.0;
  double challenge_minutes = 1.0;
  std::uint64_t seed = 1;
  std::string mode = "detections";
  std::string suite = "all";
  std::string glove;
  int threads = 0;
  std::vector<std::string> without;  // realism effects switched off in every case
  bool idealised = false;            // every realism effect off: the first wave's simulator
  bool json = false;
};

nlohmann::json to_json(const vist_eval::ErrorSummary& e) {
  return {{"samples", e.samples}, {"mean_mm", e.mean_mm}, {"median_mm", e.median_mm}, {"p95_mm", e.p95_mm},
          {"pck20", e.pck20},     {"pck35", e.pck35},     {"auc_0_50mm", e.auc50}};
}

nlohmann::json to_json(const vist_eval::Aggregate& a) {
  nlohmann::json j = {
      {"name", a.name},
      {"sessions", a.sessions},
      {"keypoints", to_json(a.keypoints)},
      {"all_joints", to_json(a.all_joints)},
      {"keypoint_mean_mm",
       {{"dorsum", a.keypoint_mean_mm[0]},
        {"thumb_tip", a.keypoint_mean_mm[1]},
        {"index_tip", a.keypoint_mean_mm[2]},
        {"middle_tip", a.keypoint_mean_mm[3]}}},
      {"nees_mean", a.nees_mean},
      {"nees_fraction_in_95", a.nees_in_95},
      {"realtime_factor", a.realtime_factor},
      {"tracker_realtime_factor", a.tracker_realtime_factor},
      {"acquisitions_failed", a.acquisitions_failed},
  };
  if (a.scale_error_max >= 0.0) {
    j["calibration"] = {{"scale_error_max", a.scale_error_max}, {"mounting_error_max_deg", a.mounting_error_max_deg}};
  }
  if (!a.recovery_s.empty()) {
    j["recovery_s"] = a.recovery_s;
    j["recovery_max_s"] = *std::max_element(a.recovery_s.begin(), a.recovery_s.end());
  }
  return j;
}

struct Case {
  std::string name;
  Challenge challenge;
  Ablation ablation;
  double minutes;
  std::vector<vist_eval::RealismEffect> off;  // on top of --without
};

// "all effects on" or "without sliding, wobble".
std::string describe_realism(const std::vector<vist_eval::RealismEffect>& off) {
  if (off.empty()) return "every realism effect on";
  if (off.size() == vist_eval::kRealismEffects.size()) return "idealised (every realism effect off)";
  std::string s = "without ";
  for (std::size_t i = 0; i < off.size(); ++i) s += (i ? ", " : "") + std::string(vist_eval::to_string(off[i]));
  return s;
}

int run_bench_vist(const BenchVistArgs& a) {
  auto mode = vist_eval::parse_frame_mode(a.mode);
  ImuGloveDescription glove = ImuGloveDescription::vist_default();
  if (!a.glove.empty()) {
    auto g = ImuGloveDescription::load(a.glove);
    if (!g) return logger().error("{}", g.error().message), 1;
    glove = std::move(*g);
  }
  std::vector<vist_eval::RealismEffect> off;
  for (const std::string& w : a.without) {
    auto e = vist_eval::parse_realism_effect(w);
    if (!e) return logger().error("--without: '{}' is not a realism effect", w), 2;
    if (std::find(off.begin(), off.end(), *e) == off.end()) off.push_back(*e);
  }
  if (a.idealised) off.assign(vist_eval::kRealismEffects.begin(), vist_eval::kRealismEffects.end());
  std::vector<Case> cases;
  const bool all = a.suite == "all";
  if (all || a.suite == "free") {
    const bool natural = std::find(off.begin(), off.end(), vist_eval::RealismEffect::natural_motion) == off.end();
    cases.push_back({natural ? "natural_motion" : "free_motion", Challenge::none, Ablation::full, a.minutes, {}});
  }
  if (a.suite == "realism") {
    // The ablation of the simulator's realism: everything on, each effect off
    // in turn, everything off (the first wave's idealised simulator).
    cases.push_back({"all_effects", Challenge::none, Ablation::full, a.minutes, {}});
    for (auto e : vist_eval::kRealismEffects) {
      if (e == vist_eval::RealismEffect::camera && *mode != vist_eval::FrameMode::images) continue;
      const bool natural = std::find(off.begin(), off.end(), vist_eval::RealismEffect::natural_motion) == off.end();
      if ((e == vist_eval::RealismEffect::tremor || e == vist_eval::RealismEffect::flicks) && !natural) continue;
      if (std::find(off.begin(), off.end(), e) != off.end()) continue;
      cases.push_back({"without_" + std::string(vist_eval::to_string(e)), Challenge::none, Ablation::full, a.minutes, {e}});
    }
    cases.push_back({"idealised", Challenge::none, Ablation::full, a.minutes,
                     {vist_eval::kRealismEffects.begin(), vist_eval::kRealismEffects.end()}});
  }
  if (all || a.suite == "challenges") {
    for (auto c : {Challenge::occlude_half, Challenge::out_of_view, Challenge::distractors, Challenge::dropped_frames,
                   Challenge::imu_unplug}) {
      cases.push_back({std::string(vist_eval::to_string(c)), c, Ablation::full, a.challenge_minutes, {}});
    }
  }
  if (all || a.suite == "ablations") {
    for (auto b : {Ablation::imu_only, Ablation::vision_only, Ablation::no_imu_priors}) {
      cases.push_back({"ablation_" + std::string(vist_eval::to_string(b)), Challenge::none, b, a.challenge_minutes, {}});
    }
  }
  struct Job {
    std::size_t case_index;
    vist_eval::SessionSpec spec;
  };
  std::vector<Job> jobs;
  double total_s = 0.0;
  for (std::size_t c = 0; c < cases.size(); ++c) {
    for (int s = 0; s < a.subjects; ++s) {
      vist_eval::SessionSpec spec;
      // Subjects spread over the pool (hand lengths 17-20.5 cm).
      spec.subject = a.subjects == 1 ? a.first_subject : (s * (sim::kSimSubjectCount - 1)) / std::max(1, a.subjects - 1);
      spec.duration_s = cases[c].minutes * 60.0;
      spec.seed = a.seed;
      spec.challenge = cases[c].challenge;
      spec.ablation = cases[c].ablation;
      spec.mode = *mode;
      for (auto e : off) spec.switch_off(e);
      for (auto e : cases[c].off) spec.switch_off(e);
      jobs.push_back({c, spec});
      total_s += spec.duration_s;
    }
  }
  const int threads = a.threads > 0 ? a.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  logger().info("bench vist: {} case(s) x {} subject(s), {:.0f} simulated seconds on {} thread(s), seed {}, {} mode, "
                "simulator {}",
                cases.size(), a.subjects, total_s, threads, a.seed, a.mode, describe_realism(off));
  std::vector<std::vector<vist_eval::SessionResult>> results(cases.size());
  ProgressBar progress("bench vist", total_s, "s simulated");
  double done_s = 0.0;
  std::size_t next = 0;
  int failures = 0;
  std::vector<std::string> case_error(cases.size());  // the first session error of each case
  std::vector<std::future<Result<vist_eval::SessionResult>>> running;
  std::vector<std::size_t> running_job;
  auto launch = [&] {
    const Job& j = jobs[next];
    running.push_back(std::async(std::launch::async, [&glove, spec = j.spec] { return vist_eval::run_session(glove, spec); }));
    running_job.push_back(next);
    ++next;
  };
  while (next < jobs.size() || !running.empty()) {
    while (next < jobs.size() && static_cast<int>(running.size()) < threads) launch();
    // Collect the oldest job (jobs are similar in length).
    auto r = running.front().get();
    const Job& j = jobs[running_job.front()];
    running.erase(running.begin());
    running_job.erase(running_job.begin());
    done_s += j.spec.duration_s;
    progress.update(done_s);
    std::string error = r ? std::string() : r.error().message;
    if (r && r->keypoints.samples == 0) {
      char why[160];
      std::snprintf(why, sizeof why, "nothing was scored (the tracker produced no pose after the %.1f s warm-up of a "
                    "%.1f s session)", j.spec.warmup_s, j.spec.duration_s);
      error = why;
    }
    if (!error.empty()) {
      logger().error("{} subject {}: {}", cases[j.case_index].name, j.spec.subject, error);
      if (case_error[j.case_index].empty()) case_error[j.case_index] = error;
      ++failures;
      continue;
    }
    logger().debug("{} subject {}: keypoint mean {:.2f} mm; {}", cases[j.case_index].name, j.spec.subject,
                   r->keypoints.mean_mm, r->stats.describe());
    results[j.case_index].push_back(std::move(*r));
  }
  progress.finish();

  nlohmann::json out = {{"machine_threads", std::thread::hardware_concurrency()},
                        {"seed", a.seed},
                        {"mode", a.mode},
                        {"subjects", a.subjects},
                        {"glove", glove.name},
                        {"realism", describe_realism(off)},
                        {"glove_build", sim::GloveBuildErrors{}.describe()},
                        {"soft_tissue", sim::SoftTissueOptions{}.describe()},
                        {"keypoints", {"dorsum (palm joint)", "thumb_tip", "index_tip", "middle_tip"}},
                        {"warmup_s_not_scored", vist_eval::SessionSpec{}.warmup_s},
                        {"camera_latency_s", vist_eval::SessionSpec{}.camera_latency_s}};
  std::printf("%s", a.json ? "" : "\nVIST on simulated subjects (errors after a 5 s warm-up; keypoints: dorsum, thumb/index/middle tips)\n");
  if (!a.json) {
    std::printf("%-26s %8s %8s %8s %8s %8s %9s %8s %8s\n", "case", "kp mean", "kp p95", "PCK@20", "PCK@35", "AUC50",
                "all26 mm", "NEES", "x RT");
  }
  for (std::size_t c = 0; c < cases.size(); ++c) {
    // A case with no session that ran has no figures: it says so, never 0.0 mm.
    if (results[c].empty()) {
      out["cases"].push_back({{"name", cases[c].name}, {"ran", false}, {"error", case_error[c]}});
      if (!a.json) std::printf("%-26s did not run: %s\n", cases[c].name.c_str(), case_error[c].c_str());
      continue;
    }
    const auto agg = vist_eval::aggregate(cases[c].name, results[c]);
    nlohmann::json jc = to_json(agg);
    jc["ran"] = true;
    {
      auto case_off = off;
      for (auto e : cases[c].off) {
        if (std::find(case_off.begin(), case_off.end(), e) == case_off.end()) case_off.push_back(e);
      }
      jc["realism_off"] = nlohmann::json::array();
      for (auto e : case_off) jc["realism_off"].push_back(std::string(vist_eval::to_string(e)));
    }
    const auto failed = static_cast<std::size_t>(a.subjects) - results[c].size();
    if (failed > 0) {
      jc["sessions_failed"] = failed;
      jc["error"] = case_error[c];
    }
    out["cases"].push_back(std::move(jc));
    if (!a.json) {
      if (failed > 0) {
        std::printf("%-26s %zu of %d session(s) did not run (%s); the figures are the others'\n", cases[c].name.c_str(),
                    failed, a.subjects, case_error[c].c_str());
      }
      std::printf("%-26s %8.2f %8.2f %7.1f%% %7.1f%% %8.3f %9.2f %8.2f %8.1f\n", cases[c].name.c_str(),
                  agg.keypoints.mean_mm, agg.keypoints.p95_mm, 100 * agg.keypoints.pck20, 100 * agg.keypoints.pck35,
                  agg.keypoints.auc50, agg.all_joints.mean_mm, agg.nees_mean, agg.realtime_factor);
      if (agg.scale_error_max >= 0.0 && c == 0) {
        std::printf("%-26s scale error max %.2f %%, IMU mounting error max %.2f deg (at 30 s)\n", "",
                    100 * agg.scale_error_max, agg.mounting_error_max_deg);
      }
      if (!agg.recovery_s.empty()) {
        std::printf("%-26s recovery after re-entry: max %.2f s over %zu events\n", "",
                    *std::max_element(agg.recovery_s.begin(), agg.recovery_s.end()), agg.recovery_s.size());
      }
    }
  }
  if (a.json) std::printf("%s\n", out.dump(2).c_str());
  return failures == 0 ? 0 : 1;
}

struct SimVistArgs {
  int subject = 3;
  double seconds = 60.0;
  std::uint64_t seed = 1;
  std::string challenge = "none";
  std::string mode = "detections";
  std::string glove;
  std::string out;
  bool force = false;
};

Result<ImuGloveDescription> load_glove(const std::string& path) {
  if (path.empty()) return ImuGloveDescription::vist_default();
  return ImuGloveDescription::load(path);
}

int run_sim_vist(const SimVistArgs& a) {
  auto glove = load_glove(a.glove);
  if (!glove) return report_error(glove.error());
  vist_eval::SessionSpec spec;
  spec.subject = a.subject;
  spec.duration_s = a.seconds;
  spec.seed = a.seed;
  spec.mode = *vist_eval::parse_frame_mode(a.mode);
  for (auto c : {Challenge::none, Challenge::occlude_half, Challenge::out_of_view, Challenge::distractors,
                 Challenge::dropped_frames, Challenge::imu_unplug}) {
    if (vist_eval::to_string(c) == a.challenge) spec.challenge = c;
  }
  spec.record_path = a.out;
  spec.overwrite_record = a.force;
  std::printf("Simulating subject %d wearing '%s' for %.0f s (%s, challenge %s) -> %s\n", a.subject,
              glove->name.c_str(), a.seconds, a.mode.c_str(), a.challenge.c_str(), a.out.c_str());
  auto r = vist_eval::run_session(*glove, spec);
  if (!r) {
    std::fprintf(stderr, "error: %s\n", r.error().message.c_str());
    return 1;
  }
  std::printf("live tracking: keypoint error mean %.2f mm (p95 %.2f), all 26 joints %.2f mm; %llu frames fused\n",
              r->keypoints.mean_mm, r->keypoints.p95_mm, r->all_joints.mean_mm,
              static_cast<unsigned long long>(r->stats.frames_fused));
  std::printf("Replay it with: proprio track vist --session %s\n", a.out.c_str());
  return 0;
}

struct TrackVistArgs {
  std::string session;
  std::string out;
  bool force = false;
  double warmup_s = 5.0;
  bool json = false;
  // --live
  bool live = false;
  std::string glove;
  std::string hand = "right";
  std::string vid = hex4(devices::kImuGloveUsbVendorId);
  std::string pid = hex4(devices::kImuGloveUsbProductId);
  std::string imu_serial, imu_path;
  std::string camera = "/dev/video0";
  std::string camera_right;
  std::string calibration;
  double seconds = 0.0;
  double interval_s = 1.0;
};

// The glove and the camera feed the tracker until Ctrl-C or --seconds; a
// status line each interval says what arrives and where the hand is. The
// wiring is the layer's own (vist::start_vist_devices): devices that are not
// there yet are waited for.
int run_track_vist_live(const TrackVistArgs& a) {
  auto glove = a.glove.empty() ? Result<ImuGloveDescription>(ImuGloveDescription::vist_default())
                               : ImuGloveDescription::load(a.glove);
  if (!glove) return report_error(glove.error());
  vist::VistLiveSourceOptions so;
  so.source.tracker.hand = *parse_handedness(a.hand);  // CLI11 checked the name
  vist::VistDeviceOptions d;
  d.imu.vendor_id = parse_hex_id(a.vid);
  d.imu.product_id = parse_hex_id(a.pid);
  d.imu.serial = a.imu_serial;
  d.imu.path = a.imu_path;
  d.camera = a.camera;
  d.camera_right = a.camera_right;
  d.stereo_calibration = a.calibration;
  std::printf("%s\nglove: %s\ndevices: %s\n", glove->name.c_str(),
              glove->origin.empty() ? "built-in thesis glove" : glove->origin.c_str(), d.describe().c_str());
  std::printf("the camera is taken as fixed (no HMD pose): the head at (0, 1.6, 0) m looking along -Z\n");
  std::fflush(stdout);
  auto source = vist::start_vist_devices(*glove, d, so);
  if (!source) return report_error(source.error());

  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  std::printf(a.seconds > 0 ? "tracking for %g s (Ctrl-C stops early)\n" : "tracking (Ctrl-C to stop)\n", a.seconds);
  const auto start = std::chrono::steady_clock::now();
  auto next_print = start + std::chrono::duration<double>(a.interval_s);
  HandPose pose;
  while (!g_sigint_stop.load()) {
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = std::chrono::duration<double>(now - start).count();
    if (a.seconds > 0 && elapsed >= a.seconds) break;
    if (now >= next_print) {
      const auto st = (*source)->live_stats();
      const PoseLookup found = (*source)->lookup(so.source.tracker.hand, MonotonicClock::instance().now_ns(), pose);
      std::printf("%7.1fs glove %s, %llu IMU samples; camera %s, %llu frames, %.1f markers/frame; ", elapsed,
                  hid::to_string(st.glove_state), static_cast<unsigned long long>(st.imu_samples),
                  st.camera_open ? vist::to_string(st.camera_state) : "not open",
                  static_cast<unsigned long long>(st.frames),
                  st.frames ? static_cast<double>(st.markers_detected) / static_cast<double>(st.frames) : 0.0);
      if (is_usable(found) && pose.active) {
        const Vec3 p = pose.joint(HandJoint::wrist).p;
        std::printf("wrist at (%.3f, %.3f, %.3f) m\n", p.x(), p.y(), p.z());
      } else {
        std::printf("%s\n", found == PoseLookup::empty ? "no hand yet" : "no hand now");
      }
      std::fflush(stdout);
      next_print += std::chrono::duration<double>(a.interval_s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::signal(SIGINT, previous);
  const auto st = (*source)->live_stats();
  const auto tracker = (*source)->tracker_stats();
  source->reset();
  std::printf("\n%s\n%s\n", st.describe().c_str(), tracker.describe().c_str());
  return st.imu_samples > 0 && st.frames > 0 ? 0 : 1;
}

int run_track_vist(const TrackVistArgs& a) {
  if (a.live) return run_track_vist_live(a);
  vist_eval::TrackSessionOptions o;
  o.warmup_s = a.warmup_s;
  o.output_path = a.out;
  o.overwrite_output = a.force;
  auto r = vist_eval::track_session(a.session, o);
  if (!r) {
    std::fprintf(stderr, "error: %s\n", r.error().message.c_str());
    return 1;
  }
  const double rt = r->tracker_seconds > 0.0 ? r->session_seconds / r->tracker_seconds : 0.0;
  nlohmann::json j = {{"session", a.session},
                      {"glove", r->info.glove.name},
                      {"hand", std::string(to_string(r->info.hand))},
                      {"session_seconds", r->session_seconds},
                      {"imu_samples", r->imu_samples},
                      {"stereo_frames", r->stereo_frames},
                      {"poses", r->poses},
                      {"frames_fused", r->stats.frames_fused},
                      {"acquisitions", r->stats.acquisitions},
                      {"reacquisitions", r->stats.reacquisitions},
                      {"skipped_records", r->skipped_records},
                      {"recording_end", to_string(r->recording.end)},
                      {"tracker_realtime_factor", rt},
                      {"scored", r->scored}};
  if (r->scored) {
    j["keypoints"] = to_json(r->keypoints);
    j["all_joints"] = to_json(r->all_joints);
    j["keypoint_mean_mm"] = r->keypoint_mean_mm;
  }
  // Damaged data is reported, never passed off as a complete session.
  const bool corrupt = r->recording.end == RecordingEnd::corrupt;
  const int exit_status = corrupt ? 3 : 0;
  j["recording_detail"] = printable(r->recording.detail, 1000);
  j["corrupt_regions"] = r->recording.corrupt_regions;
  j["skipped_bytes"] = r->recording.skipped_bytes;
  j["lost_records"] = r->recording.lost_records;
  j["imu_rejected_out_of_order"] = r->stats.imu_rejected_out_of_order;
  j["imu_rejected_time_jump"] = r->stats.imu_rejected_time_jump;
  if (a.json) {
    std::printf("%s\n", j.dump(2).c_str());
    if (corrupt) std::fprintf(stderr, "error: %s\n", printable(r->recording.detail, 1000).c_str());
    return exit_status;
  }
  std::printf("%s: %.1f s, %llu IMU samples, %llu stereo frames (%llu fused), %llu poses, %.0fx real time\n",
              a.session.c_str(), r->session_seconds, static_cast<unsigned long long>(r->imu_samples),
              static_cast<unsigned long long>(r->stereo_frames), static_cast<unsigned long long>(r->stats.frames_fused),
              static_cast<unsigned long long>(r->poses), rt);
  if (r->recording.end != RecordingEnd::clean || r->skipped_records > 0) {
    std::printf("recording: %s, %llu records with bad content skipped (%s)\n", to_string(r->recording.end),
                static_cast<unsigned long long>(r->skipped_records), printable(r->recording.detail, 1000).c_str());
  }
  if (r->stats.imu_rejected_out_of_order > 0 || r->stats.imu_rejected_time_jump > 0) {
    std::printf("IMU samples rejected for their time stamps: %llu out of order, %llu isolated time jumps\n",
                static_cast<unsigned long long>(r->stats.imu_rejected_out_of_order),
                static_cast<unsigned long long>(r->stats.imu_rejected_time_jump));
  }
  if (r->scored) {
    std::printf("vs ground truth (after %.0f s): keypoints mean %.2f mm, p95 %.2f mm, PCK@20 %.1f%%; all 26 joints "
                "%.2f mm\n",
                a.warmup_s, r->keypoints.mean_mm, r->keypoints.p95_mm, 100 * r->keypoints.pck20,
                r->all_joints.mean_mm);
  } else if (r->ground_truth_poses == 0) {
    std::printf(corrupt ? "no ground truth could be read from the damaged session: nothing to score\n"
                        : "no ground truth in the session: nothing to score\n");
  } else {
    std::printf("the session's %llu ground-truth poses do not cover the tracker's output (after the %.0f s "
                "warm-up): nothing to score\n",
                static_cast<unsigned long long>(r->ground_truth_poses), a.warmup_s);
  }
  if (!a.out.empty()) {
    std::printf("tracked hand written to %s (proprio replay %s --summary)\n", printable(a.out, 300).c_str(),
                printable(a.out, 300).c_str());
  }
  if (corrupt) {
    std::fprintf(stderr, "error: the session recording is damaged: %s\n", printable(r->recording.detail, 1000).c_str());
  }
  return exit_status;
}

const std::vector<std::string> kChallengeNames = {"none", "occlude_half", "out_of_view", "distractors",
                                                  "dropped_frames", "imu_unplug"};

}  // namespace

void add_vist_commands(CLI::App& app, int& exit_code) {
  auto sargs = std::make_shared<SimVistArgs>();
  auto* simv = add_command(app, "sim-vist");
  simv->add_option("--subject", sargs->subject, "simulated subject (0-14)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  simv->add_option("--seconds", sargs->seconds, "session length")->check(CLI::Range(1.0, 7200.0))->capture_default_str();
  simv->add_option("--seed", sargs->seed, "seed of the simulation")->capture_default_str();
  simv->add_option("--challenge", sargs->challenge, "what goes wrong during the session")
      ->check(CLI::IsMember(kChallengeNames))
      ->capture_default_str();
  simv->add_option("--mode", sargs->mode, "detections: simulated blob centroids; images: rendered images + detector")
      ->check(CLI::IsMember({"detections", "images"}))
      ->capture_default_str();
  simv->add_option("--glove", sargs->glove, "glove description TOML (default: the thesis glove)");
  simv->add_option("--out", sargs->out, "session recording to write")->required();
  simv->add_flag("--force", sargs->force, "overwrite --out if it exists");
  simv->callback([sargs, &exit_code] { exit_code = run_sim_vist(*sargs); });

  auto* track = add_command(app, "track");
  auto targs = std::make_shared<TrackVistArgs>();
  auto* tv = track->add_subcommand(
      "vist",
      "Replay a recorded VIST session (from 'proprio sim-vist' or a live VIST source) through the tracker,\n"
      "in the order the data arrived; score it against the session's ground truth when it has one.\n"
      "Exit status: 0 done, 1 cannot read or track, 3 the recording is damaged (results cover what could be read).\n"
      "With --live: track a real glove (IMU board over USB HID) seen by a stereo camera.");
  auto* session = tv->add_option("--session", targs->session, "VIST session recording")->check(CLI::ExistingFile);
  auto* live = tv->add_flag("--live", targs->live,
                            "track live: the IMU board over USB HID and a stereo camera (or a video file)\n"
                            "(docs/vist.md, 'With a real glove')");
  session->excludes(live);
  live->excludes(session);
  tv->add_option("--glove", targs->glove, "--live: glove description TOML (default: the thesis glove)")
      ->check(CLI::ExistingFile);
  tv->add_option("--hand", targs->hand, "--live: which hand wears the glove")
      ->check(CLI::IsMember({"left", "right"}))
      ->capture_default_str();
  tv->add_option("--vid", targs->vid, "--live: the IMU board's USB vendor ID, hexadecimal")
      ->check(check_hex_id)
      ->capture_default_str();
  tv->add_option("--pid", targs->pid, "--live: the IMU board's USB product ID, hexadecimal")
      ->check(check_hex_id)
      ->capture_default_str();
  tv->add_option("--imu-serial", targs->imu_serial, "--live: open the IMU board with this USB serial number");
  tv->add_option("--imu-path", targs->imu_path, "--live: open this HID node (e.g. /dev/hidraw3)");
  tv->add_option("--camera", targs->camera,
                 "--live: side-by-side stereo camera (/dev/videoN) or video file; the left camera with --camera-right")
      ->capture_default_str();
  tv->add_option("--camera-right", targs->camera_right, "--live: the right camera or video, for two separate ones");
  tv->add_option("--calibration", targs->calibration, "--live: rectify with this 'proprio calibrate stereo' file")
      ->check(CLI::ExistingFile);
  tv->add_option("--seconds", targs->seconds, "--live: stop after this long (0: at Ctrl-C)")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  tv->add_option("--interval", targs->interval_s, "--live: seconds between status lines")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
  tv->add_option("--out", targs->out, "write the tracked hand (and the ground truth) to this recording");
  tv->add_flag("--force", targs->force, "overwrite --out if it exists");
  tv->add_option("--warmup", targs->warmup_s, "seconds from the start not scored (acquisition, calibration)")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  tv->add_flag("--json", targs->json, "print the result as JSON");
  tv->callback([targs, &exit_code] {
    if (!targs->live && targs->session.empty()) throw CLI::RequiredError::Option(1, 1, 0, "--session or --live");
    exit_code = run_track_vist(*targs);
  });

  auto args = std::make_shared<BenchVistArgs>();
  auto* vist = add_command(app, "bench vist");
  vist->add_option("--subjects", args->subjects, "simulated subjects per case, spread over hand sizes")
      ->check(CLI::Range(1, sim::kSimSubjectCount))
      ->capture_default_str();
  vist->add_option("--subject", args->first_subject, "with --subjects 1: the subject id (0-14)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  vist->add_option("--minutes", args->minutes, "minutes of motion per subject (natural, or free with --without natural_motion)")
      ->check(CLI::Range(0.1, 120.0))
      ->capture_default_str();
  vist->add_option("--challenge-minutes", args->challenge_minutes, "minutes per subject of each challenge and ablation")
      ->check(CLI::Range(0.1, 120.0))
      ->capture_default_str();
  vist->add_option("--seed", args->seed, "seed of the simulated sessions")->capture_default_str();
  vist->add_option("--mode", args->mode, "detections: simulated blob centroids; images: rendered images + OpenCV detector")
      ->check(CLI::IsMember({"detections", "images"}))
      ->capture_default_str();
  vist->add_option("--suite", args->suite,
                   "which cases to run (realism: every simulator effect on, each off in turn, all off)")
      ->check(CLI::IsMember({"all", "free", "challenges", "ablations", "realism"}))
      ->capture_default_str();
  vist->add_option("--glove", args->glove, "glove description TOML (default: the thesis glove)");
  vist->add_option("--threads", args->threads, "sessions run in parallel (0: one per core)")->capture_default_str();
  std::vector<std::string> effects;
  for (auto e : vist_eval::kRealismEffects) effects.emplace_back(vist_eval::to_string(e));
  vist->add_option("--without", args->without,
                   "switch these simulator effects off in every case (comma-separated): " + CLI::detail::join(effects))
      ->delimiter(',')
      ->check(CLI::IsMember(effects));
  vist->add_flag("--idealised", args->idealised,
                 "every simulator effect off: the glove as drawn on rigid skin, the idealised camera and the thesis's "
                 "free-motion protocol (the first wave's figures)");
  vist->add_flag("--json", args->json, "print the metrics as JSON");
  vist->callback([args, &exit_code] { exit_code = run_bench_vist(*args); });
}

}  // namespace proprio::cli
