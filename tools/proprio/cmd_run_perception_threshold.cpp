// proprio run perception-threshold --participant sim|ID: the thesis's
// perception-threshold study (docs/perception-threshold.md), simulated or
// with a real participant on the engine.
#include <fmt/format.h>

#include <cctype>
#include <cstdio>
#include <filesystem>

#include "commands.hpp"
#include "proprio/core/random.hpp"
#include "progress.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/hmd_calibration/calibration.hpp"
#include "proprio/perception_threshold/live.hpp"
#include "proprio/perception_threshold/report.hpp"
#include "proprio/perception_threshold/simulation.hpp"
#include "proprio/study/session.hpp"
#include "run_args.hpp"

namespace proprio::cli {
// Named, not anonymous: the CLI is a unity build, and the sibling study
// commands define helpers with the same names.
namespace perception_run {

namespace fs = std::filesystem;
using namespace proprio::perception;

// "P07" -> 6: the counterbalancing position comes from the id's number.
int participant_index_of(const std::string& id) {
  std::size_t i = id.size();
  while (i > 0 && std::isdigit(static_cast<unsigned char>(id[i - 1]))) --i;
  if (i == id.size()) return 0;
  return std::max(0, std::atoi(id.c_str() + i) - 1);
}

int analyse_and_print(const fs::path& dir) {
  std::printf("\nAnalysing %s (psychometric fits with 999 bootstrap samples each)...\n", dir.c_str());
  auto report = analyze_perception_study(dir, {});
  if (!report) return report_error(report.error());
  auto files = write_perception_report(*report, dir / "report");
  if (!files) return report_error(files.error());
  std::printf("\n%s\n", report->summary_markdown.c_str());
  std::printf("Report in %s/report/: summary.md, thesis_summary.json, summary.json, thresholds.csv,\n"
              "  all_participants.svg (thesis Fig. 2.8), chose_haptic.svg (Fig. 2.9), participant_*.svg\n",
              dir.c_str());
  return 0;
}

int run_simulated(const RunArgs& a, const PerceptionProtocol& protocol, const study::StudyDesign& design,
                  const fs::path& out) {
  // For the whole command, the report included: a second run on the same
  // --out fails here, before it deletes (--force) or appends anything.
  auto folder_lock = study::StudyFolderLock::acquire(out);
  if (!folder_lock) return report_error(folder_lock.error());
  SimulatedStudyOptions o;
  o.out_dir = out;
  o.participants = a.participants;
  if (a.seed_given) o.seed = a.seed;
  o.force = a.force;
  o.device_model = a.device;
  // Simulated participants do not need a disk flush per row (docs/study.md).
  o.sync_each_trial = false;
  std::printf("%s\n%s\n", protocol.describe().c_str(), o.describe().c_str());
  ProgressBar bar("simulating trials", 1.0, "trials");
  bool first = true;
  o.progress = [&](int done, int total) {
    if (first) {
      bar = ProgressBar("simulating trials", total, "trials");
      first = false;
    }
    bar.update(done);
  };
  auto study = run_simulated_study(protocol, design, o);
  bar.finish();
  if (!study) return report_error(study.error());
  std::printf("\n%zu participants, %.0f s of simulated time (%llu servo ticks at 1 kHz through the gate and the "
              "emulated %s) in %.1f s wall time; seed %llu\n",
              study->participants.size(), study->simulated_s, static_cast<unsigned long long>(study->servo_ticks),
              fs::path(a.device).stem().c_str(), study->wall_s, static_cast<unsigned long long>(study->seed));
  std::printf("\n%-4s %9s %9s | ground truth (cm): %6s %6s %6s %8s | %s\n", "id", "trials", "resumed", "none",
              "true", "false", "max err", "force attributed to the haptic sphere");
  for (const auto& p : study->participants) {
    std::printf("%-4s %9d %9d | %26.2f %6.2f %6.2f %8.2f | %d of %d\n", p.id.c_str(), p.trials_run,
                p.trials_recovered, p.true_threshold_none_cm, p.true_threshold_true_sphere_cm,
                p.true_threshold_false_sphere_cm, p.true_max_allowable_error_cm, p.correct_attributions,
                p.haptic_answers);
  }
  std::printf("Ground truth written to %s\n", study->ground_truth_json.c_str());
  return analyse_and_print(out);
}

int run_live(const RunArgs& a, const PerceptionProtocol& protocol, const study::StudyDesign& design,
             const fs::path& out) {
  const engine::Scene scene = live_scene(protocol);
  auto o = app_options_from(a);
  if (!o) return report_error(o.error());
  o->hud = false;  // the participant sees only the experiment's prompts
  RunArgs no_servo = a;
  no_servo.haptics = "none";  // the force comes from the analytic law below, not the contact simulation
  auto in = app_inputs_from(no_servo, scene, *o);
  if (!in) return report_error(in.error());
  std::unique_ptr<ForceChannel> channel;
  if (a.haptics == "sim") {
    auto model = haptics::load_device_model(a.device);
    if (!model) return report_error(model.error());
    std::shared_ptr<const haptics::FingertipDeviceModel> shared(std::move(*model));
    auto sink = haptics::EmulatedFingertip::create(shared);
    if (!sink) return report_error(sink.error());
    channel = std::make_unique<ForceChannel>(shared, std::shared_ptr<haptics::FingertipSink>(std::move(*sink)));
  } else if (a.haptics == "hid") {
    RunArgs one = a;  // the experiment renders on one fingertip: the first of --fingers
    one.fingers.resize(1);
    auto channels = open_hid_haptics(one);
    if (!channels) return report_error(channels.error());
    channel = std::make_unique<ForceChannel>(channels->front().model, channels->front().sink);
  } else if (a.haptics != "none") {
    return report_error(make_error(Errc::invalid_argument, "--haptics: sim, hid or none"));
  }
  study::SessionOptions so;
  so.out_dir = out;
  so.participant = a.participant;
  so.participant_index = participant_index_of(a.participant);
  so.device_json = fmt::format(R"({{"fingertip_device": "{}", "hands": "{}", "output": "{}"}})",
                               channel ? channel->describe() : "none", a.hands.front(), to_string(o->output));
  Pose T_hmd_graphics;
  if (!a.calibration.empty()) {
    auto c = hmd_calibration::load_calibration(a.calibration);
    if (!c) return report_error(c.error());
    T_hmd_graphics = *c;
    so.calibration_json = fmt::format(R"J({{"file": "{}", "translation_m": [{}, {}, {}], "rotation_xyzw": [{}, {}, {}, {}]}})J",
                                      a.calibration, c->p.x(), c->p.y(), c->p.z(), c->q.x(), c->q.y(), c->q.z(), c->q.w());
  }
  auto experiment = LiveExperiment::create(protocol, design, so, std::move(channel));
  if (!experiment) return report_error(experiment.error());
  (*experiment)->set_hmd_calibration(T_hmd_graphics);
  std::printf("%s\nParticipant %s (counterbalancing position %d): %d of %d trials done; data in %s\n",
              protocol.describe().c_str(), a.participant.c_str(), so.participant_index + 1,
              (*experiment)->completed_trials(), (*experiment)->planned_trials(), out.c_str());
  LiveExperiment* e = experiment->get();
  in->on_frame = [e](engine::FrameContext& f) { e->on_frame(f); };
  auto app = engine::App::create(scene, std::move(*in), *o);
  if (!app) return report_error(app.error());
  auto report = run_app_until_done(**app);
  if (!report) return report_error(report.error());
  if (auto s = (*experiment)->status(); !s) return report_error(s.error());
  std::printf("%d of %d trials recorded in %s (run again with the same --participant and --out to continue)\n",
              (*experiment)->completed_trials(), (*experiment)->planned_trials(), out.c_str());
  return 0;
}

// The simulated participants' graphics frame: a few centimetres off the
// tracked HMD frame and slightly pitched, the kind of offset the thesis found
// (the rendering appeared too close).
const Pose kSimulatedHmdGraphics{Quat(Eigen::AngleAxisd(2.0 * kPi / 180.0, Vec3::UnitX())), Vec3(0.005, -0.01, 0.04)};
constexpr double kSimulatedReachSdM = 0.015;  // proprioceptive error per axis of one blind reach

int calibrate_simulated(const RunArgs& a, const fs::path& out) {
  std::vector<Vec3> cmd, finger;
  for (int p = 0; p < a.participants; ++p) {
    hmd_calibration::TargetOptions t;
    t.seed = mix_seed(a.seed, static_cast<std::uint64_t>(p));
    const auto targets = hmd_calibration::calibration_targets(t);
    const auto reaches = hmd_calibration::simulate_reaching(kSimulatedHmdGraphics, targets, kSimulatedReachSdM,
                                                            mix_seed(t.seed, 1));
    cmd.insert(cmd.end(), targets.begin(), targets.end());
    finger.insert(finger.end(), reaches.begin(), reaches.end());
  }
  auto fit = hmd_calibration::fit_hmd_graphics(cmd, finger);
  if (!fit) return report_error(fit.error());
  const Pose err = kSimulatedHmdGraphics.inverse() * fit->T_hmd_graphics;
  std::printf("%d simulated participants x 100 blind reaches (proprioceptive error %.1f cm per axis)\n"
              "fitted: %s\ntrue:   translation (%.1f, %.1f, %.1f) mm, 2.00 deg about x\n"
              "error of the fit: %.2f mm, %.3f deg\n",
              a.participants, kSimulatedReachSdM * 100, fit->describe().c_str(), kSimulatedHmdGraphics.p.x() * 1e3,
              kSimulatedHmdGraphics.p.y() * 1e3, kSimulatedHmdGraphics.p.z() * 1e3, err.p.norm() * 1e3,
              Eigen::AngleAxisd(err.q).angle() * 180 / kPi);
  if (auto s = hmd_calibration::save_calibration(out, *fit); !s) return report_error(s.error());
  std::printf("Saved to %s (use: proprio run perception-threshold --participant ID --calibration %s)\n", out.c_str(),
              out.c_str());
  return 0;
}

// A real participant: a grey sphere at each target, the finger not drawn;
// Space records the fingertip where the participant believes the sphere is.
int calibrate_live(const RunArgs& a, const fs::path& out) {
  hmd_calibration::TargetOptions t;
  t.seed = a.seed;
  const auto targets = hmd_calibration::calibration_targets(t);
  engine::Scene scene;
  scene.name = "hmd-calibration";
  auto o = app_options_from(a);
  if (!o) return report_error(o.error());
  o->hud = false;
  RunArgs no_servo = a;
  no_servo.haptics = "none";
  auto in = app_inputs_from(no_servo, scene, *o);
  if (!in) return report_error(in.error());
  std::vector<Vec3> finger;
  in->on_frame = [&](engine::FrameContext& f) {
    f.show_hands = false;
    if (finger.size() >= targets.size()) {
      f.stop = true;
      return;
    }
    const Vec3& p_cmd = targets[finger.size()];
    f.markers.push_back({engine::FrameContext::Marker::Shape::sphere, Pose{Quat::Identity(), f.T_world_head * p_cmd},
                         Vec3::Constant(0.01), {0.6f, 0.6f, 0.6f, 1.0f}});
    const bool tracked = f.tracked && f.tracked->active;
    f.prompt = fmt::format("Reach {} of {}: touch the grey sphere with your index fingertip, then press Space{}",
                           finger.size() + 1, targets.size(), tracked ? "" : "\n(hand not tracked)");
    for (const auto& k : f.keys) {
      if (k == "space" && tracked) {
        finger.push_back(f.T_world_head.inverse() * f.tracked->joint(HandJoint::index_tip).p);
        break;
      }
    }
  };
  auto app = engine::App::create(scene, std::move(*in), *o);
  if (!app) return report_error(app.error());
  auto report = run_app_until_done(**app);
  if (!report) return report_error(report.error());
  std::vector<Vec3> cmd(targets.begin(), targets.begin() + static_cast<std::ptrdiff_t>(finger.size()));
  auto fit = hmd_calibration::fit_hmd_graphics(cmd, finger);
  if (!fit) return report_error(fit.error());
  std::printf("%s\n", fit->describe().c_str());
  if (auto s = hmd_calibration::save_calibration(out, *fit); !s) return report_error(s.error());
  std::printf("Saved to %s\n", out.c_str());
  return 0;
}

int run_hmd_calibration_impl(const RunArgs& a) {
  const fs::path out = a.out_given ? fs::path(a.out) : fs::path("hmd_calibration.toml");
  if (a.participant == "sim") return calibrate_simulated(a, out);
  return calibrate_live(a, out);
}

int run_perception_threshold_impl(const RunArgs& a) {
  auto protocol = a.design.empty() ? Result<PerceptionProtocol>(PerceptionProtocol::defaults())
                                   : PerceptionProtocol::load_file(a.design);
  if (!protocol) return report_error(protocol.error());
  auto design = study::StudyDesign::load_file(protocol->design_file);
  if (!design) return report_error(design.error());
  const fs::path out = a.out_given ? fs::path(a.out) : fs::path("perception-threshold-data");
  if (a.participant == "sim") return run_simulated(a, *protocol, *design, out);
  return run_live(a, *protocol, *design, out);
}

}  // namespace perception_run

int run_hmd_calibration(const RunArgs& a) { return perception_run::run_hmd_calibration_impl(a); }
int run_perception_threshold(const RunArgs& a) { return perception_run::run_perception_threshold_impl(a); }

}  // namespace proprio::cli
