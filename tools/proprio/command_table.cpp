#include "command_table.hpp"

#include <CLI/CLI.hpp>
#include <string>

namespace proprio::cli {
namespace {

constexpr CommandInfo kCommands[] = {
    {"sim-hand",
     "Simulate a hand performing a motion protocol and record its ground truth.\n"
     "Writes streams hand/<hand>/ground_truth (26 joint poses with velocities), "
     "hand/<hand>/joint_angles_ground_truth, head/ground_truth and events.",
     Family::core, false},
    {"replay",
     "Read a recording: list its streams, check its integrity, summarise the hand motion and play the hand poses "
     "through the replay HandSource.\nA file cut short by a crash is read up to its last complete record. "
     "Exit status: 0 readable, 1 cannot open, 3 corrupt data found.",
     Family::core, false},
    {"sim-vist",
     "Simulate a subject wearing the VIST glove in front of a head-mounted stereo camera and record the session\n"
     "(IMU samples, stereo marker detections, camera poses, ground truth and the live tracker output).",
     Family::trackers, false},
    {"track", "Run a tracker on recorded sensor data", Family::trackers, true},
    {"bench", "Benchmarks that measure accuracy on simulated data", Family::split, true},
    {"bench vist",
     "Run the VIST evaluation protocol on simulated subjects and print the accuracy:\n"
     "natural motion (continuous, with tremor and flicks) on a simulator as hard as real hands (the glove as built,\n"
     "soft tissue, a real camera's images in image mode; --without, --idealised, --suite realism for the ablation),\n"
     "challenges (half the markers occluded 2 s,\n"
     "hand out of view 3 s, distractor blobs, 10% dropped frames, IMU board unplugged 1 s) and ablations (IMU only,\n"
     "vision only, correspondence search without IMU priors).",
     Family::trackers, false},
    {"bench glove",
     "Run the stretch glove's pipeline (read-out, min-max calibration, ONNX pose model, hand) on held-out\n"
     "simulated subjects and print the joint-angle error with each session's own min-max calibration (the thesis's\n"
     "scenario 4) and, with --global-model, with the training data's min-max (scenario 3).\n"
     "--without and --realism-ablation switch the simulated glove's real-world effects off.\n"
     "Simulated accuracy is not real-world accuracy.",
     Family::trackers, false},
    {"bench ftm",
     "Run the FTM glove's evaluation on held-out simulated subjects, calibration included: the thesis's IMU bench\n"
     "(Euler error), free motion and pinch-grasp (tracked-DOF and fingertip error) and magnetic disturbances\n"
     "(detector hit/false-alarm rates, heading error gated vs plain). Simulated accuracy is not real-world accuracy.",
     Family::trackers, false},
    {"bench haptics",
     "Time the MuJoCo step (hand + peg-in-hole, pressing) and the 1 kHz servo loop on its own thread:\n"
     "tick duration, wake-up jitter and overruns. Timings depend on the machine and its load.",
     Family::haptics, false},
    {"calibrate",
     "Calibrate sensors: 'calibrate stereo' for VIST's camera, 'calibrate glove' for the stretch glove, "
     "'calibrate ftm' for the FTM glove, 'calibrate wrist' for a tracked device's offset to the wrist",
     Family::split, true},
    {"calibrate stereo",
     "Calibrate VIST's stereo camera from checkerboard image pairs (docs/stereo-camera.md).\n"
     "Writes the full calibration (intrinsics, distortion, extrinsics, rectification) to --out and prints the "
     "rectified rig as a glove file [rig] table (also written to --rig-toml).\n"
     "Images: a folder of pairs named left_000.png + right_000.png (names differing only in left/right), or left/ "
     "and right/ subfolders with the same names, or side-by-side images (--side-by-side; left half = left camera).\n"
     "Capturing from a live camera is not built in (there is no --from-camera): grab pairs with any tool, e.g. "
     "'ffmpeg -f v4l2 -video_size 2560x720 -i /dev/video0 -vf fps=1 board_%03d.png' for a ZED Mini, holding the "
     "board still in a new pose each second.",
     Family::trackers, false},
    {"calibrate glove",
     "Per-user min-max calibration of the stretch glove (Glauser 2019, Sec. 5.3.3): explore extreme poses while\n"
     "the per-cell 20-frame medians' min and max are collected; prints which fingers need more movement.",
     Family::trackers, false},
    {"calibrate ftm",
     "Per-user calibration of the FTM glove (docs/ftm.md), guided on stdout: a figure-eight until every compass has\n"
     "seen enough directions, then the three known poses, each taken once the hand moved into it and held still.\n"
     "Solves the compasses' hard/soft iron and the field, the bend sensors' beta0/beta1 and the IMU mountings, prints\n"
     "them with their residuals and writes a per-user TOML file (atomically; nothing on failure). From a board on\n"
     "USB, the board emulator with a simulated wearer (--subject N --emulate) or the simulated wearer alone.",
     Family::trackers, false},
#if defined(PROPRIO_HAVE_ENGINE) && defined(PROPRIO_HAVE_OPENXR_LAYER)
    {"calibrate wrist",
     "Measure where the wearer's wrist is relative to a tracked device, a VIVE-style wrist tracker "
     "(XR_HTCX_vive_tracker_interaction) or the hand's controller (grip pose), so Proprio's OpenXR layer puts a "
     "glove's fingers on the right wrist (layer config: wrist = \"tracker\" | \"controller\", "
     "wrist_calibration). See docs/wrist-calibration.md.\n"
     "Guided on stdout: a countdown, then hold the hand still in the pose it asks for; it starts again when you "
     "move. --reference pose measures the wrist's rotation from that pose and the head's forward direction and "
     "assumes its position (--wrist-below-device-m, --wrist-behind-grip-m); --reference runtime-hand takes the "
     "whole offset from the runtime's own hand tracking (Proprio's layer is disabled in this process).\n"
     "Writes [wrist] position_m, rotation_deg (the wrist in the device's grip frame) to a per-user file and "
     "prints the layer config lines to paste.",
     Family::engine, false},
#endif
    {"record", "Record sessions and training data", Family::split, true},
    {"record glove",
     "Record a stretch-glove training session: the read-out board's frames (USB HID) paired with a ground-truth\n"
     "hand recorded at the same time (a .prec from a hand tracker, CLOCK_MONOTONIC timestamps), written as a\n"
     "dataset for tools/stretch_glove (train.py, finetune.py). The first --exploration-seconds are the session's\n"
     "min-max calibration phase.",
     Family::trackers, false},
    {"record array",
     "Record a stretch sensor array (docs/stretch-arrays.md) from its read-out board (USB HID, protocol 1.1 with\n"
     "single strips) or, with --emulate, the board emulator: the first --rest-seconds calibrate the rows'\n"
     "parasitics and each cell's C0 with the sleeve at rest, then the raw row measurements and the solved cells\n"
     "(F, with C0 in the stream's meta) go to a session recording (.prec) until --seconds or Ctrl-C.\n"
     "Exit status 1 when the board does not match the layout, sends nothing, or is unplugged for longer than\n"
     "--disconnect-timeout (the recording then keeps what came before).",
     Family::devices, false},
    {"glove",
     "The USB HID IMU glove (7 IMUs at 100 Hz; protocol in docs/glove-hid-protocol.md): list devices, monitor a "
     "glove or a capture file, or emulate one.",
     Family::devices, true},
    {"sim-ftm",
     "Simulate a subject wearing the FTM glove (figure-eight, three calibration poses, then the task) and record the\n"
     "session (4 IMUs with raw compass, 3 bend sensors, wrist tracker, ground truth); --magnets brings objects near\n"
     "the hand, --plot tracks it and plots the heading error with and without the disturbance gate.",
     Family::trackers, false},
    {"sim-glove",
     "Simulate stretch-glove sessions and write a training dataset (cells.npy, angles.npy, session.npy, "
     "subject.npy, phase.npy, calib_min.npy, calib_max.npy, meta.json).\n"
     "Each session is a new donning: an exploration phase for the min-max calibration, then free motion.",
     Family::trackers, false},
    {"sim-array",
     "Simulate stretch-array sessions (a sleeve on a balloon, biceps, elbow, wrist or forearm) and write a dataset:\n"
     "the elastic sheet on the moving body, the read-out board with the effects the model ignores, the markers\n"
     "through a simulated optical system and the semi-automatic labelling. docs/stretch-arrays.md.",
     Family::trackers, false},
    {"bench array",
     "The stretch array's accuracy on simulated data: a 15 x 50 mm cell on a linear stage (eq. 4.2) and a\n"
     "string-pulled sheet read through the whole read-out (eq. 4.8). Simulated accuracy is not real-world accuracy.",
     Family::trackers, false},
    {"train", "Train regressors on recorded or simulated data", Family::trackers, true},
    {"train array",
     "Train the stretch array's regressors (the thesis's DNN, linear regression, an RBF kernel model) on a dataset\n"
     "(PyTorch, tools/stretch_array/train.py) into OUT/<kind>/model.onnx, which the live pipeline runs through\n"
     "OpenCV DNN.",
     Family::trackers, false},
    {"stretch-board",
     "The stretch glove's USB HID read-out board (13 x 14 strips, 960 measurements/s; protocol in "
     "docs/stretch-glove-hid-protocol.md): list devices, monitor a board or a capture file, or run an emulated board "
     "as a self-test.",
     Family::devices, true},
    {"ftm-board",
     "The FTM glove's USB HID read-out board (4 IMUs at 200 Hz, 3 bend sensors at 1 kHz; protocol in "
     "docs/ftm-hid-protocol.md): list devices, monitor a board, or run an emulated board worn by a simulated "
     "subject as a self-test.",
     Family::devices, true},
    {"haptics", "Contact simulation and fingertip haptic devices", Family::haptics, true},
#ifdef PROPRIO_HAVE_STUDY
    {"array",
     "Stretch sensor arrays (docs/stretch-arrays.md): 'array layout' writes a shipped layout to start from, "
     "'array check' says whether a layout's cells can be read out",
     Family::core, true},
    {"psychometric", "Psychometric functions (docs/study.md)", Family::core, true},
    {"stats", "Statistics on wide CSVs (one row per subject, one column per condition)", Family::core, true},
    {"study", "Study designs and whole-study analysis (docs/study.md)", Family::core, true},
#endif
#ifdef PROPRIO_HAVE_ENGINE
    {"run",
     "Run a scene with the engine: tracked hands, the haptics servo loop and the renderer. Output goes to an HMD "
     "through OpenXR when a runtime with XR_KHR_vulkan_enable2 is present, else to a window, else headless to PNG "
     "frames (force one with --xr, --window or --headless). Headless runs step simulated time, so they are "
     "reproducible.",
     Family::engine, false},
    {"run array-demo",
     "A stretch sensor array live: a simulated wearer and the read-out board emulated over the fake USB cable, read, "
     "solved and reconstructed (--model: a regressor from 'proprio train array'), drawn beside the simulator's true "
     "sheet with the frame rate, latency and mean vertex error. Headless to PNG frames unless --window or --xr.",
     Family::engine, false},
    {"rig",
     "The modular rig device (docs/rig-device.md): plan a device of Hall-sensor joints and splitters for a glTF "
     "character ('rig plan'), emulate it on its fault-tolerant bus ('rig emulate'), pose the character with it "
     "('rig live'), or write an example character ('rig example')",
     Family::engine, true},
    {"rig example", "Write one of the example characters (humanoid, quadruped, creature) with its sample poses as glTF",
     Family::engine, false},
    {"rig plan",
     "Pick where a kit's joints and splitters go on a skinned glTF character from its sample poses (greedy joints with "
     "the reachability fit, splitters by an ILP with COIN-OR CBC) and write plan.json, assembly instructions "
     "(assembly.txt, assembly.svg) and the error curve (error_curve.svg)",
     Family::engine, false},
    {"rig emulate",
     "Run a plan's device on the emulated bus (message loss and corruption, link power losses, clock skew), read it "
     "through the real driver on the fake USB cable, and print the topology and angles the host sees",
     Family::engine, false},
    {"rig live",
     "Pose a character from the device (emulated with bus faults, or a base on USB): topology bound to the plan, "
     "joints retargeted, the rest by pose-space interpolation; drawn by the engine (headless PNG frames unless "
     "--window or --xr) and recorded with --record",
     Family::engine, false},
    {"bench rig",
     "The rig device's targets on simulated data: joint angles through Hall sensors and calibration, rig reduction "
     "on the example characters, the bus under faults, and the simulated posing task (ours against twist-bend-twist)",
     Family::engine, false},
#endif
#ifdef PROPRIO_HAVE_OPENXR_LAYER
    {"layer",
     "Install, check and configure Proprio's OpenXR API layer (XR_APILAYER_PROPRIO_hand_tracking), which gives any "
     "OpenXR app XR_EXT_hand_tracking joints from Proprio's hand sources. See docs/openxr-layer.md.",
     Family::core, true},
    {"xr-probe",
     "Be a minimal OpenXR app: through the system's OpenXR loader, open a session on the active runtime, create "
     "hand trackers (XR_EXT_hand_tracking) and print once a second what they report: whether each hand is active, "
     "wrist and index-tip positions (mm), palm orientation, the share of joints with all location flags, how often "
     "joints were located and how often the data actually changed.\n"
     "The session is headless (XR_MND_headless) when the runtime offers it. When a headless session cannot run "
     "frames (Monado refuses xrBeginFrame there), or the runtime has no headless mode, the probe uses a Vulkan "
     "graphics binding (XR_KHR_vulkan_enable2) instead, and says which it used.\n"
     "Enabled API layers (Proprio's included, see 'proprio layer status') apply as for any app. Ctrl-C ends it "
     "cleanly.\n"
     "Exit status: 0 a hand was active and no call failed; 1 an error, including any failed OpenXR call (reported "
     "with its XrResult); "
     "2 XR_EXT_hand_tracking not offered, or supportsHandTracking false; 3 the run completed without a failed "
     "call but no hand was ever active.\n"
     "--haptics checks the fingertip devices instead (XR_PROPRIO_fingertip_haptics): it lists both hands' devices, "
     "waits for the session to be FOCUSED (at most 5 s; the layer drives devices only then) and for the gates to "
     "ramp in, presses each present finger with 0.5 N (+Y, fingertip frame) for 0.3 s and reports the peak "
     "commanded and measured force and whether both fell below 0.01 N within 0.2 s of the last submission. Exit: "
     "0 every device pressed and released; 2 the extension is not offered or the layer has no (valid) [haptics] "
     "table; 3 a device failed its press (measured under 0.1 N, commanded under 0.4 N, or not released); 1 any "
     "other error, including a session never FOCUSED or one that lost focus during the presses.",
     Family::engine, false},
#endif
};

}  // namespace

std::span<const CommandInfo> command_table() { return kCommands; }

const CommandInfo* find_command(std::string_view path) {
  for (const CommandInfo& c : kCommands) {
    if (c.path == path) return &c;
  }
  return nullptr;
}

std::string_view family_program(Family family) {
  switch (family) {
    case Family::core:
    case Family::split:
      return "proprio";
    case Family::trackers:
      return "proprio-trackers";
    case Family::devices:
      return "proprio-devices";
    case Family::haptics:
      return "proprio-haptics";
    case Family::engine:
      return "proprio-engine";
  }
  return "proprio";
}

CLI::App* add_command(CLI::App& app, std::string_view path) {
  CLI::App* parent = &app;
  std::string_view name = path;
  if (const auto space = path.find(' '); space != std::string_view::npos) {
    parent = add_command(app, path.substr(0, space));
    name = path.substr(space + 1);
  }
  for (CLI::App* sub : parent->get_subcommands({})) {
    if (sub->get_name() == name) return sub;
  }
  const CommandInfo* info = find_command(path);
  // A path missing from the table is a programming error: register it anyway,
  // so --help shows the gap instead of the command vanishing.
  CLI::App* sub = parent->add_subcommand(std::string(name), info ? std::string(info->description) : std::string());
  if (info != nullptr && info->group) sub->require_subcommand(1);
  return sub;
}

}  // namespace proprio::cli
