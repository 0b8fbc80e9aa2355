// proprio sim-array and bench array: the stretch sensor arrays' simulated
// datasets and their benchmark (issue 30, docs/stretch-arrays.md). The
// pipelines are stretch_array_eval's (sim_array.hpp, array_bench.hpp).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/log.hpp"
#include "proprio/stretch_array_eval/array_bench.hpp"
#include "proprio/stretch_array_eval/sim_array.hpp"

namespace proprio::cli {

namespace {

namespace sae = stretch_array_eval;
namespace sas = stretch_array_sim;

const std::vector<std::string> kBoardEffects = {"resistance", "parasitic", "timing",       "jitter",
                                                "quantisation", "over-stretch", "donning"};
const std::vector<std::string> kMocapEffects = {"occlusion", "swaps", "ghosts", "marker-noise"};

void switch_off(sas::BoardOptions& b, const std::vector<std::string>& effects) {
  for (const auto& e : effects) {
    if (e == "resistance") b.resistance.enabled = false;
    if (e == "parasitic") b.parasitic.enabled = false;
    if (e == "timing") b.timing.enabled = false;
    if (e == "jitter") b.jitter.enabled = false;
    if (e == "quantisation") b.quantise = false;
    if (e == "over-stretch") b.over_stretch.enabled = false;
    if (e == "donning") b.donning.enabled = false;
  }
}

void switch_off(sas::MocapOptions& m, const std::vector<std::string>& effects) {
  for (const auto& e : effects) {
    if (e == "occlusion") m.p_lose = 0.0;
    if (e == "swaps") m.p_swap = 0.0;
    if (e == "ghosts") m.p_ghost = 0.0;
    if (e == "marker-noise") m.noise_std_m = 0.0;
  }
}

// "top:3:60" -> strip 3 of the top layer disconnected from t = 60 s.
Status parse_broken_lead(const std::string& text, sas::BoardOptions& b) {
  std::stringstream in(text);
  std::string layer, strip, from;
  if (!std::getline(in, layer, ':') || !std::getline(in, strip, ':') || !std::getline(in, from) ||
      (layer != "top" && layer != "bottom")) {
    return make_error(Errc::invalid_argument, "--broken-lead wants LAYER:STRIP:SECONDS, e.g. top:3:60");
  }
  try {
    b.broken_lead.enabled = true;
    b.broken_lead.top = layer == "top";
    b.broken_lead.strip = static_cast<std::size_t>(std::stoul(strip));
    b.broken_lead.from_s = std::stod(from);
  } catch (const std::exception&) {
    return make_error(Errc::invalid_argument, "--broken-lead '" + text + "': strip and seconds must be numbers");
  }
  return {};
}

struct SimArrayArgs {
  sae::SimArrayOptions options;
  std::vector<std::string> without;
  std::string broken_lead;
  bool no_redonned = false;
  bool ideal = false;
};

int run_sim_array(SimArrayArgs a) {
  auto& o = a.options;
  o.version = PROPRIO_VERSION;
  if (a.ideal) o.board = sas::BoardOptions::ideal();
  switch_off(o.board, a.without);
  switch_off(o.mocap, a.without);
  if (!a.broken_lead.empty()) {
    if (auto st = parse_broken_lead(a.broken_lead, o.board); !st) return report_error(st.error());
  }
  o.redonned_test = !a.no_redonned;
  ProgressBar progress("sim-array", o.total_simulated_minutes(), "simulated minutes");
  sae::SimArrayCallbacks callbacks;
  callbacks.on_progress = [&progress](double minutes) { progress.update(minutes); };
  auto r = sae::write_sim_array_dataset(o, callbacks);
  progress.finish();
  if (!r) return report_error(r.error());
  std::printf("wrote %s: %s\n", o.out.c_str(), r->describe().c_str());
  return 0;
}

struct BenchArrayArgs {
  sae::BenchArrayOptions options;
  sae::DatasetBenchOptions dataset;
  std::vector<std::string> cases = {"uniaxial", "string-pull"};
  std::vector<std::string> without;
  bool json = false;
};

int run_bench_array(BenchArrayArgs a) {
  auto& o = a.options;
  switch_off(o.board, a.without);
  if (auto st = o.validate(); !st) return report_error(st.error());
  auto wants = [&a](const char* c) { return std::find(a.cases.begin(), a.cases.end(), c) != a.cases.end(); };
  sae::BenchArrayReport report;
  if (wants("uniaxial")) {
    auto r = sae::bench_uniaxial(o);
    if (!r) return report_error(r.error().with_context("bench array uniaxial"));
    report.uniaxial = *r;
  }
  if (wants("string-pull")) {
    auto r = sae::bench_string_pull(o);
    if (!r) return report_error(r.error().with_context("bench array string-pull"));
    report.string_pull = *r;
  }
  if (!a.dataset.dataset.empty() || !a.dataset.models.empty()) {
    auto r = sae::bench_dataset(a.dataset, &report.speed);
    if (!r) return report_error(r.error().with_context("bench array on " + a.dataset.dataset));
    report.dataset = std::move(*r);
    report.dataset_name = std::filesystem::path(a.dataset.dataset).filename().string();
  }
  std::printf("%s\n", a.json ? report.json().c_str() : report.describe().c_str());
  return 0;
}

}  // namespace

void add_stretch_array_commands(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SimArrayArgs>();
  auto& o = args->options;
  CLI::App* sim = add_command(app, "sim-array");
  sim->add_option("--motion", o.motion, "balloon, biceps, elbow, wrist or forearm (the thesis's datasets)")
      ->check(CLI::IsMember({"balloon", "biceps", "elbow", "wrist", "forearm"}))
      ->capture_default_str();
  sim->add_option("--layout", o.layout_file,
                  "Array layout TOML (proprio array layout); default prototype_92, biceps_144 for --motion biceps")
      ->check(CLI::ExistingFile);
  sim->add_option("--train-sessions", o.train_sessions, "Training sessions")->check(CLI::Range(0, 100))->capture_default_str();
  sim->add_option("--train-minutes", o.train_minutes, "Minutes per training session")
      ->check(CLI::Range(0.05, 600.0))
      ->capture_default_str();
  sim->add_option("--test-sessions", o.test_sessions, "Test sessions in the training donning")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  sim->add_option("--test-minutes", o.test_minutes, "Minutes per test session")
      ->check(CLI::Range(0.05, 600.0))
      ->capture_default_str();
  sim->add_flag("--no-redonned", args->no_redonned, "Leave out the test session with the sleeve put on again");
  sim->add_option("--rate", o.frame_rate_hz, "Full read-out frames per second (the thesis: 8)")
      ->check(CLI::Range(0.5, 60.0))
      ->capture_default_str();
  sim->add_option("--seed", o.seed, "Random seed; the same seed gives identical files")->capture_default_str();
  std::vector<std::string> sim_effects = kBoardEffects;
  sim_effects.insert(sim_effects.end(), kMocapEffects.begin(), kMocapEffects.end());
  sim->add_option("--without", args->without,
                  "Board and mocap effects to switch off (comma-separated): " + CLI::detail::join(sim_effects))
      ->delimiter(',')
      ->check(CLI::IsMember(sim_effects));
  sim->add_flag("--ideal", args->ideal, "Every board effect off: the board reads M C exactly");
  sim->add_option("--broken-lead", args->broken_lead, "A strip's lead breaks: LAYER:STRIP:SECONDS, e.g. top:3:60");
  sim->add_option("--out", o.out, "Dataset folder to write")->required();
  sim->add_flag("--force", o.force, "Replace a dataset already in --out");
  sim->add_option("--threads", o.threads, "Sessions in parallel (0: one per core)")->check(CLI::Range(0, 256))->capture_default_str();
  sim->callback([args, &exit_code] { exit_code = run_sim_array(*args); });

  auto bargs = std::make_shared<BenchArrayArgs>();
  auto& b = bargs->options;
  CLI::App* bench = add_command(app, "bench array");
  bench->add_option("--cases", bargs->cases,
                    "Which flat cases (comma-separated): uniaxial, string-pull, or none (with --dataset alone)")
      ->delimiter(',')
      ->check(CLI::IsMember({"uniaxial", "string-pull", "none"}))
      ->capture_default_str();
  bench->add_option("--max-stretch", b.uniaxial_max_stretch, "Uniaxial: the stage's largest l/l0")
      ->check(CLI::Range(1.05, 3.0))
      ->capture_default_str();
  bench->add_option("--seconds", b.string_pull_seconds, "String-pull: simulated seconds")
      ->check(CLI::Range(1.0, 3600.0))
      ->capture_default_str();
  bench->add_option("--seed", b.seed, "Random seed")->capture_default_str();
  bench->add_option("--without", bargs->without, "Board effects to switch off: " + CLI::detail::join(kBoardEffects))
      ->delimiter(',')
      ->check(CLI::IsMember(kBoardEffects));
  bench->add_option("--dataset", bargs->dataset.dataset,
                    "A sim-array dataset: its test sessions are reconstructed with --models (marker and dense vertex "
                    "error, and the per-frame time)");
  bench->add_option("--models", bargs->dataset.models, "train array's --out folder (dnn/, lr/, svm/) or an .onnx file");
  bench->add_option("--layout", bargs->dataset.layout_file, "The dataset's layout, when it is not a shipped one")
      ->check(CLI::ExistingFile);
  bench->add_flag("--json", bargs->json, "Print the results as JSON");
  bench->callback([bargs, &exit_code] { exit_code = run_bench_array(*bargs); });
}

}  // namespace proprio::cli
