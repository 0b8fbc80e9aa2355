#pragma once
// `proprio run`'s arguments and the engine wiring they describe, shared by the
// plain scene runner (cmd_run.cpp) and the study samples it dispatches to
// (`proprio run perception-threshold|peg-in-hole --participant ...`).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/data_dir.hpp"
#include "proprio/core/result.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/haptics/servo_loop.hpp"

namespace CLI {
class App;
}

namespace proprio::cli {

struct RunArgs {
  std::string scene = "half-cylinder";
  bool xr = false, window = false, headless = false;
  std::vector<std::string> hands{"touch"};
  std::string haptics = "sim";
  std::string device = data_path("haptics/band_2dof.toml");
  bool device_given = false;             // --device on the command line (hid: else each device's kind)
  std::vector<std::string> hid_devices;  // --haptics hid: FINGER=SERIAL or FINGER=/dev/hidrawN
  std::vector<std::string> fingers{"index"};
  int frames = -1;
  double fps = 30.0;
  std::string out = "proprio-frames";
  bool out_given = false;
  std::string size = "1280x720";
  bool mono = false;
  std::string camera = "head";
  bool software = false, validation = false, realtime = false, no_hud = false;
  std::string hand = "right";
  std::string hand_look = "joints";  // joints, skinned, or a glTF hand file (skinned with it)
  int sim_subject = 3;
  std::string glove_calibration;
  std::string ftm_calibration;  // --hands ftm device: the FTM glove's calibration (proprio calibrate ftm)
  bool no_recentre = false;       // --hands vist|glove: the source's coordinates as they are  // --hands glove device: the wearer's min-max calibration
  std::uint64_t seed = 1;
  bool seed_given = false;   // --seed on the command line (studies: replaces the design's seed)
  // Study samples.
  std::string participant;   // "sim", or a real participant's id
  int participants = 1;      // --participant sim: how many simulated participants
  std::string design;        // the sample's config file; empty: published defaults
  bool resume = false;       // continue a crashed session in --out
  bool force = false;        // overwrite existing session data
  std::string calibration;   // an HMD calibration (proprio run hmd-calibration) applied to what is drawn
  std::string tracker;       // peg-in-hole, --participant sim: ideal|ftm (empty: the design's, ideal by default)
};

// The output flags of a live view drawn by the engine (`run array-demo`,
// `rig live`): --xr, --window or --headless (the default), --out, --size,
// --fps (headless: frames per second of wall time), --software, --no-hud.
void add_live_view_options(CLI::App* cmd, RunArgs& a);

// The engine options the flags describe (output, size, frames, camera, ...).
Result<engine::AppOptions> app_options_from(const RunArgs& a);

// Hand source and haptic channels for `scene` as the flags describe them.
// `simulated_time`: headless runs stepping a ManualClock (placed in
// inputs.simulated_clock) that the hand source reads.
Result<engine::AppInputs> app_inputs_from(const RunArgs& a, const engine::Scene& scene,
                                          const engine::AppOptions& options);

// --haptics hid: the fingertip devices on USB for the --fingers, bound by
// --hid-device or as hid_channels.hpp describes; prints which is which.
Result<std::vector<haptics::ServoChannel>> open_hid_haptics(const RunArgs& a);

// Runs an App to completion, with Ctrl-C stopping it cleanly.
Result<engine::AppReport> run_app_until_done(engine::App& app);

// Study samples; each returns the process exit code.
int run_perception_threshold(const RunArgs& a);
int run_hmd_calibration(const RunArgs& a);
int run_peg_in_hole(const RunArgs& a);

}  // namespace proprio::cli
