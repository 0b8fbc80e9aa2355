// proprio train array: the stretch array's regressors (issue 30) trained on a
// dataset from `proprio sim-array` (or a recorded and labelled one). The
// training itself is PyTorch (tools/stretch_array/train.py); this command finds
// the script and Debian's Python, checks the dataset first, and trains each
// requested model into OUT/<kind>/ (model.onnx, model.json), which `bench
// array` and the live pipeline load through OpenCV DNN.
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "proprio/core/data_dir.hpp"
#include "proprio/stretch_array_eval/array_dataset.hpp"

namespace proprio::cli {

namespace {

struct TrainArrayArgs {
  std::string dataset;
  std::string out;
  std::string models = "dnn,lr,svm";
  bool tiny = false;
  int epochs = 0;
  std::string train_sessions;
  std::string test_sessions;
  std::string pose_keep;
  std::string python = "/usr/bin/python3";
  int threads = 0;
};

// tools/stretch_array: $PROPRIO_TOOLS_DIR, the installed data folder's copy,
// then this build's source tree.
Result<std::filesystem::path> find_train_script() {
  std::vector<std::filesystem::path> tried;
  if (const char* env = std::getenv("PROPRIO_TOOLS_DIR")) tried.push_back(std::filesystem::path(env) / "stretch_array");
  if (auto data = data_dir()) tried.push_back(*data / "tools" / "stretch_array");
  tried.push_back(std::filesystem::path(PROPRIO_SOURCE_TOOLS_DIR) / "stretch_array");
  std::string looked;
  for (const auto& dir : tried) {
    if (std::filesystem::is_regular_file(dir / "train.py")) return dir / "train.py";
    looked += "\n  " + (dir / "train.py").string();
  }
  return make_error(Errc::not_found, "the training script is not installed; looked for:" + looked +
                                         "\nset PROPRIO_TOOLS_DIR to the folder holding stretch_array/train.py");
}

int run_child(const std::vector<std::string>& args) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    ::execv(argv[0], argv.data());
    std::fprintf(stderr, "error: cannot run %s\n", argv[0]);
    std::_Exit(127);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

int run_train_array(const TrainArrayArgs& a) {
  // The dataset is checked here first, so a broken one fails in a second with
  // the loader's message instead of after Python and torch have started.
  auto dataset = stretch_array_eval::load_array_dataset(a.dataset);
  if (!dataset) return report_error(dataset.error());
  auto script = find_train_script();
  if (!script) return report_error(script.error());
  if (::access(a.python.c_str(), X_OK) != 0) {
    return report_error(make_error(Errc::not_found, "no Python at " + a.python +
                                                        " (Debian's python3 with python3-torch; ./dev deps installs it)"));
  }
  std::vector<std::string> kinds;
  std::stringstream list(a.models);
  for (std::string k; std::getline(list, k, ',');) {
    if (k != "dnn" && k != "lr" && k != "svm") {
      return report_error(make_error(Errc::invalid_argument, "unknown model '" + k + "' (dnn, lr, svm)"));
    }
    kinds.push_back(k);
  }
  std::printf("training %zu model(s) on %s: %zu frames, %zu cells, %zu markers, %zu sessions\n", kinds.size(),
              a.dataset.c_str(), dataset->frames(), dataset->shape.cell_names.size(),
              dataset->shape.marker_names.size(), dataset->sessions.size());
  for (const auto& kind : kinds) {
    std::vector<std::string> args = {a.python, script->string(), a.dataset, "--model", kind,
                                     "--out", (std::filesystem::path(a.out) / kind).string()};
    if (a.tiny) args.push_back("--tiny");
    if (a.epochs > 0) args.insert(args.end(), {"--epochs", std::to_string(a.epochs)});
    if (!a.train_sessions.empty()) args.insert(args.end(), {"--train-sessions", a.train_sessions});
    if (!a.test_sessions.empty()) args.insert(args.end(), {"--test-sessions", a.test_sessions});
    if (!a.pose_keep.empty()) args.insert(args.end(), {"--pose-keep", a.pose_keep});
    if (a.threads > 0) args.insert(args.end(), {"--threads", std::to_string(a.threads)});
    std::printf("==> %s\n", kind.c_str());
    const int rc = run_child(args);
    if (rc != 0) {
      std::fprintf(stderr, "error: training the %s model failed (exit %d); nothing of it is in %s\n", kind.c_str(), rc,
                   (std::filesystem::path(a.out) / kind).c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace

void add_train_array_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<TrainArrayArgs>();
  CLI::App* cmd = add_command(app, "train array");
  cmd->add_option("dataset", args->dataset, "Array dataset folder (proprio sim-array --out)")->required();
  cmd->add_option("--out", args->out, "Folder for the models: OUT/<kind>/model.onnx and model.json")->required();
  cmd->add_option("--models", args->models, "Comma-separated: dnn (the thesis's network), lr, svm")
      ->capture_default_str();
  cmd->add_flag("--tiny", args->tiny, "A small network and few epochs (seconds; for tests and demos)");
  cmd->add_option("--epochs", args->epochs, "DNN epochs at most (default: the script's, 200)")
      ->check(CLI::Range(1, 100000));
  cmd->add_option("--train-sessions", args->train_sessions, "Training sessions (default split=train)");
  cmd->add_option("--test-sessions", args->test_sessions, "Test sessions (default split=test)");
  cmd->add_option("--pose-keep", args->pose_keep,
                  "Keep only training frames whose pose satisfies this, e.g. \"pose < 20 or pose > 40\"");
  cmd->add_option("--python", args->python, "The Python with torch")->capture_default_str();
  cmd->add_option("--threads", args->threads, "Torch CPU threads (default: the script's)")->check(CLI::Range(1, 256));
  cmd->callback([args, &exit_code] { exit_code = run_train_array(*args); });
}

}  // namespace proprio::cli
