#pragma once
// The functions that register each command file's commands. Which program
// registers which is in main.cpp; names and descriptions of the top-level
// commands are in command_table.cpp.
namespace CLI {
class App;
}

namespace proprio::cli {

// Each registers its subcommand; the callback runs it and sets the exit code.
void add_sim_hand_command(CLI::App& app, int& exit_code);
void add_replay_command(CLI::App& app, int& exit_code);
// `sim-vist`, `track vist` and `bench vist`.
void add_vist_commands(CLI::App& app, int& exit_code);
// `calibrate stereo`.
void add_calibrate_command(CLI::App& app, int& exit_code);
// `glove emulate|monitor|list`: the USB HID IMU glove.
void add_glove_command(CLI::App& app, int& exit_code);
// `sim-glove`: simulated stretch-glove sessions written as a training dataset.
void add_sim_glove_command(CLI::App& app, int& exit_code);
// `bench glove` and `calibrate glove`: the stretch glove's pipeline.
void add_stretch_glove_commands(CLI::App& app, int& exit_code);
// `bench ftm` and `sim-ftm`: the FTM glove's evaluation and simulated sessions.
void add_ftm_commands(CLI::App& app, int& exit_code);
// `stretch-board emulate|monitor|list`: the stretch glove's USB HID read-out board.
void add_stretch_board_command(CLI::App& app, int& exit_code);
// `calibrate ftm`: the FTM glove's guided per-user calibration.
void add_calibrate_ftm_command(CLI::App& app, int& exit_code);
// `ftm-board emulate|monitor|list`: the FTM glove's USB HID read-out board.
void add_ftm_board_command(CLI::App& app, int& exit_code);
// `haptics sim|mjcf|devices|test` and `bench haptics`.
void add_haptics_commands(CLI::App& app, int& exit_code);
void add_haptics_device_commands(CLI::App& haptics, int& exit_code);
// `layer install|uninstall|status|init-config` and `xr-probe`: built when the
// OpenXR layer is part of the build (PROPRIO_HAVE_OPENXR_LAYER).
void add_layer_commands(CLI::App& app, int& exit_code);
// `array layout|check`: stretch sensor array layouts (proprio::stretch_array).
void add_array_commands(CLI::App& app, int& exit_code);
// `sim-array`, `bench array` and `train array`: the stretch arrays' datasets,
// benchmark and regressor training (proprio::stretch_array_eval).
void add_stretch_array_commands(CLI::App& app, int& exit_code);
void add_train_array_command(CLI::App& app, int& exit_code);
// `record array`: a stretch array's session from its read-out board (proprio-devices).
void add_record_array_command(CLI::App& app, int& exit_code);
// `psychometric fit`, `stats ...` and `study ...` (proprio::study).
void add_study_commands(CLI::App& app, int& exit_code);
// `run SCENE`: the engine (proprio::engine).
void add_run_command(CLI::App& app, int& exit_code);
// `run array-demo`: a stretch array reconstructed live (proprio::stretch_array_eval).
void add_run_array_demo_command(CLI::App& app, int& exit_code);
void add_xr_probe_command(CLI::App& app, int& exit_code);
// `rig example|plan|emulate|live` and `bench rig`: the modular rig device (issue 31).
void add_rig_commands(CLI::App& app, int& exit_code);
void add_bench_rig_command(CLI::App& app, int& exit_code);
// `calibrate wrist`: the engine's OpenXR session and the layer's calibration file.
void add_calibrate_wrist_command(CLI::App& app, int& exit_code);

}  // namespace proprio::cli
