// The layer maps only what its configured sources need (input/hand_sources):
// a layer serving sim or replay hands brings neither OpenCV nor hidapi into
// the app; a glove source loads the stretch-glove plugin, and OpenCV with it;
// an ftm source loads the FTM plugin and hidapi, and no OpenCV.
// Each case runs layer_maps_probe, a bare OpenXR app, in a fresh process
// through Debian's loader on the mock runtime, and reads what it mapped.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "layer_test_util.hpp"

namespace {

using layer_test::TempDir;

struct ProbeRun {
  int status = -1;  // exit status, or -signal, or -1000 on timeout
  std::string out, err;
  std::vector<std::string> mapped;
  bool maps(const std::string& fragment) const {
    for (const auto& m : mapped) {
      if (m.find(fragment) != std::string::npos) return true;
    }
    return false;
  }
  std::string describe() const { return "exit " + std::to_string(status) + "\nstdout:\n" + out + "\nstderr:\n" + err; }
};

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class LayerSourcePlugins : public ::testing::Test {
 protected:
  // The probe with the loader on the mock runtime, our layer enabled and
  // `config` as the layer's config; `extra` adds or overrides variables.
  ProbeRun run(const std::string& config, const std::string& hands = "both",
               std::map<std::string, std::string> extra = {}) {
    std::map<std::string, std::string> env;
    for (char** e = environ; *e; ++e) {
      const std::string kv = *e;
      const auto eq = kv.find('=');
      if (eq != std::string::npos) env[kv.substr(0, eq)] = kv.substr(eq + 1);
    }
    env.erase("PROPRIO_PLUGIN_DIR");
    env.erase("PROPRIO_MOCK_RUNTIME_HAND_TRACKING");
    env["XR_RUNTIME_JSON"] = PROPRIO_MOCK_RUNTIME_JSON;
    env["XR_API_LAYER_PATH"] = PROPRIO_LAYER_MANIFEST_DIR;
    env["XR_ENABLE_API_LAYERS"] = "XR_APILAYER_PROPRIO_hand_tracking";
    env["XDG_CONFIG_HOME"] = (dir_.path() / "config").string();
    env["XDG_DATA_HOME"] = (dir_.path() / "data").string();
    env["PROPRIO_LAYER_CONFIG"] = dir_.write("layer.toml", config).string();
    for (auto& [k, v] : extra) env[k] = v;
    std::vector<std::string> kv;
    for (auto& [k, v] : env) kv.push_back(k + "=" + v);
    std::vector<char*> envp;
    for (auto& s : kv) envp.push_back(s.data());
    envp.push_back(nullptr);
    const auto out_file = dir_.path() / "probe.out";
    const auto err_file = dir_.path() / "probe.err";
    std::string probe = PROPRIO_LAYER_MAPS_PROBE;
    std::vector<char*> argv{probe.data(), const_cast<char*>(hands.c_str()), nullptr};

    ProbeRun r;
    const pid_t pid = ::fork();
    if (pid == 0) {
      const int o = ::open(out_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      const int e = ::open(err_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (o < 0 || e < 0) ::_exit(125);
      ::dup2(o, 1);
      ::dup2(e, 2);
      ::execve(argv[0], argv.data(), envp.data());
      ::_exit(126);
    }
    if (pid < 0) {
      ADD_FAILURE() << "fork failed";
      return r;
    }
    int wstatus = 0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    for (;;) {
      const pid_t w = ::waitpid(pid, &wstatus, WNOHANG);
      if (w == pid) break;
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &wstatus, 0);
        r.status = -1000;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (r.status != -1000) r.status = WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : -WTERMSIG(wstatus);
    r.out = slurp(out_file);
    r.err = slurp(err_file);
    std::istringstream lines(r.out);
    for (std::string line; std::getline(lines, line);) {
      if (line.rfind("mapped ", 0) == 0) r.mapped.push_back(line.substr(7));
    }
    return r;
  }

  // Both hands located as active at least once: the source really started.
  static void expect_both_active(const ProbeRun& r) {
    int left = 0, right = 0;
    const auto at = r.out.find("active ");
    ASSERT_NE(at, std::string::npos) << r.describe();
    ASSERT_EQ(std::sscanf(r.out.c_str() + at, "active %d %d", &left, &right), 2) << r.describe();
    EXPECT_GT(left, 0) << r.describe();
    EXPECT_GT(right, 0) << r.describe();
  }

  static void expect_no_opencv_no_hidapi(const ProbeRun& r) {
    EXPECT_TRUE(r.maps("libXrApiLayer_proprio_hand_tracking.so")) << "the layer was not loaded\n" << r.describe();
    EXPECT_FALSE(r.maps("libopencv_")) << r.describe();
    EXPECT_FALSE(r.maps("libhidapi")) << r.describe();
    EXPECT_FALSE(r.maps("libproprio_source_")) << r.describe();  // ftm, glove, vist and haptics alike
    EXPECT_FALSE(r.maps("libmujoco")) << r.describe();
  }

  TempDir dir_;
};

TEST_F(LayerSourcePlugins, ASimSourceMapsNeitherOpenCvNorHidapi) {
  const auto r = run("[[source]]\ntype = \"sim\"\nspace = \"local\"\n");
  ASSERT_EQ(r.status, 0) << r.describe();
  expect_both_active(r);
  expect_no_opencv_no_hidapi(r);
}

TEST_F(LayerSourcePlugins, AReplaySourceMapsNeitherOpenCvNorHidapi) {
  const auto rec = layer_test::write_still_recording(dir_.path(), 10 * proprio::kNsPerSecond);
  const auto r = run("[[source]]\ntype = \"replay\"\nspace = \"local\"\npath = \"" + rec.string() + "\"\n");
  ASSERT_EQ(r.status, 0) << r.describe();
  expect_both_active(r);
  expect_no_opencv_no_hidapi(r);
}

// The positive control: the same probe does see a plugin and OpenCV when a
// source needs them, so the two tests above can fail.
TEST_F(LayerSourcePlugins, AGloveSourceLoadsTheStretchGlovePluginAndOpenCv) {
  const auto r = run("[layer]\nmax_prediction_ms = 500\n[[source]]\ntype = \"glove\"\ninput = \"sim\"\n"
                     "hands = [\"right\"]\nspace = \"local\"\n",
                     "right");
  ASSERT_EQ(r.status, 0) << r.describe();
  int left = 0, right = 0;
  const auto at = r.out.find("active ");
  ASSERT_NE(at, std::string::npos) << r.describe();
  ASSERT_EQ(std::sscanf(r.out.c_str() + at, "active %d %d", &left, &right), 2) << r.describe();
  EXPECT_GT(right, 0) << r.describe();
  EXPECT_TRUE(r.maps("/libproprio_source_stretch_glove.so")) << r.describe();
  EXPECT_TRUE(r.maps("libopencv_dnn")) << r.describe();
  EXPECT_FALSE(r.maps("libproprio_source_vist.so")) << r.describe();
  EXPECT_FALSE(r.maps("libproprio_source_ftm.so")) << r.describe();
}

// Fingertip devices (issue 29): a [haptics] table brings the haptics plugin
// and MuJoCo into an app's session (its vibrations reach the fingertips even
// though it never heard of Proprio), and still no OpenCV.
TEST_F(LayerSourcePlugins, AHapticsTableLoadsTheHapticsPluginAndMujoco) {
  const auto r = run("[[source]]\ntype = \"sim\"\nspace = \"local\"\n[haptics]\ndevices = \"emulated\"\n"
                     "right = [\"index\"]\n");
  ASSERT_EQ(r.status, 0) << r.describe();
  expect_both_active(r);
  EXPECT_TRUE(r.maps("/libproprio_source_haptics.so")) << r.describe();
  EXPECT_TRUE(r.maps("libmujoco")) << r.describe();
  EXPECT_FALSE(r.maps("libopencv_")) << r.describe();
  EXPECT_FALSE(r.maps("libproprio_source_vist.so")) << r.describe();
}

// The FTM glove's plugin maps only what the glove needs: hidapi for its board,
// never OpenCV nor the other gloves' plugins (a simulated wearer too: the
// plugin is one library).
TEST_F(LayerSourcePlugins, AnFtmSourceLoadsOnlyTheFtmPlugin) {
  const auto r = run("[layer]\nmax_prediction_ms = 500\n[[source]]\ntype = \"ftm\"\ninput = \"sim\"\n"
                     "hands = [\"right\"]\nspace = \"local\"\n",
                     "right");
  ASSERT_EQ(r.status, 0) << r.describe();
  int left = 0, right = 0;
  const auto at = r.out.find("active ");
  ASSERT_NE(at, std::string::npos) << r.describe();
  ASSERT_EQ(std::sscanf(r.out.c_str() + at, "active %d %d", &left, &right), 2) << r.describe();
  EXPECT_GT(right, 0) << "the ftm source served the right hand\n" << r.describe();
  EXPECT_EQ(left, 0) << "one glove, one hand\n" << r.describe();
  EXPECT_TRUE(r.maps("/libproprio_source_ftm.so")) << r.describe();
  EXPECT_TRUE(r.maps("libhidapi")) << r.describe();
  EXPECT_FALSE(r.maps("libopencv_")) << r.describe();
  EXPECT_FALSE(r.maps("libproprio_source_stretch_glove.so")) << r.describe();
  EXPECT_FALSE(r.maps("libproprio_source_vist.so")) << r.describe();
}

// A configured glove source whose plugin is missing: the layer says which
// file it looked for and where, serves no hands from it, and the app runs on.
TEST_F(LayerSourcePlugins, AMissingPluginIsALayerErrorNotACrash) {
  std::filesystem::create_directories(dir_.path() / "no_plugins");
  const auto empty = (dir_.path() / "no_plugins").string();
  const auto r = run("[[source]]\ntype = \"glove\"\ninput = \"sim\"\nhands = [\"right\"]\n", "right",
                     {{"PROPRIO_PLUGIN_DIR", empty}});
  EXPECT_TRUE(r.status == 0 || r.status == 2) << r.describe();
  EXPECT_NE(r.err.find("libproprio_source_stretch_glove.so was not found (looked in '" + empty + "')"),
            std::string::npos)
      << r.describe();
  EXPECT_FALSE(r.maps("libopencv_")) << r.describe();
}

// What the dynamic linker loads with the layer before any source starts.
TEST(LayerLibrary, NeedsNeitherOpenCvNorHidapi) {
  const std::string layer = std::string(PROPRIO_LAYER_MANIFEST_DIR) + "/libXrApiLayer_proprio_hand_tracking.so";
  ASSERT_TRUE(std::filesystem::exists(layer)) << layer;
  FILE* p = ::popen(("readelf -d '" + layer + "'").c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string dynamic;
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) dynamic.append(buf, n);
  ASSERT_EQ(::pclose(p), 0) << "readelf -d failed on " << layer;
  ASSERT_NE(dynamic.find("(NEEDED)"), std::string::npos) << dynamic;
  EXPECT_EQ(dynamic.find("opencv"), std::string::npos) << dynamic;
  EXPECT_EQ(dynamic.find("hidapi"), std::string::npos) << dynamic;
}

}  // namespace
