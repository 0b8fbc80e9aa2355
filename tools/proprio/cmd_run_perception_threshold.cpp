// proprio run perception-threshold --participant sim|ID: the thesis's
// perception-threshold study (docs/perception-threshold.md), simulated or
// with a real participant on the engine.
#include <fmt/format.h>

#include <cctype>
#include <cstdio>
#include <filesystem>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/perception_threshold/live.hpp"
#include "proprio/perception_threshold/report.hpp"
#include "proprio/perception_threshold/simulation.hpp"
#include "run_args.hpp"

namespace proprio::cli {
namespace {

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
  } else if (a.haptics != "none") {
    return report_error(make_error(Errc::invalid_argument, "--haptics: sim or none (a HID fingertip device is not "
                                                           "wired into the live experiment yet)"));
  }
  study::SessionOptions so;
  so.out_dir = out;
  so.participant = a.participant;
  so.participant_index = participant_index_of(a.participant);
  so.device_json = fmt::format(R"({{"fingertip_device": "{}", "hands": "{}", "output": "{}"}})",
                               channel ? channel->describe() : "none", a.hands.front(), to_string(o->output));
  auto experiment = LiveExperiment::create(protocol, design, so, std::move(channel));
  if (!experiment) return report_error(experiment.error());
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

}  // namespace

int run_perception_threshold(const RunArgs& a) {
  auto protocol = a.design.empty() ? Result<PerceptionProtocol>(PerceptionProtocol::defaults(PROPRIO_SOURCE_DIR))
                                   : PerceptionProtocol::load_file(a.design);
  if (!protocol) return report_error(protocol.error());
  auto design = study::StudyDesign::load_file(protocol->design_file);
  if (!design) return report_error(design.error());
  const fs::path out = a.out_given ? fs::path(a.out) : fs::path("perception-threshold-data");
  if (a.participant == "sim") return run_simulated(a, *protocol, *design, out);
  return run_live(a, *protocol, *design, out);
}

}  // namespace proprio::cli
