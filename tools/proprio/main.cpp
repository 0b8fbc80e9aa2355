// proprio: the command-line entry point to Proprio's runtime. This one main is
// built into every CLI program: `proprio` (PROPRIO_CLI_FAMILY core, the
// dispatcher) and the family programs in libexec; CMakeLists.txt says which
// command files each links and defines PROPRIO_CLI_FAMILY_<NAME> for it.
#include "cli_app.hpp"
#include "command_list.hpp"

namespace {

void add_commands([[maybe_unused]] CLI::App& app, [[maybe_unused]] int& exit_code) {
  using namespace proprio::cli;
#ifdef PROPRIO_CLI_FAMILY_CORE
  add_sim_hand_command(app, exit_code);
  add_replay_command(app, exit_code);
  add_array_commands(app, exit_code);
#ifdef PROPRIO_HAVE_STUDY
  add_study_commands(app, exit_code);
#endif
#ifdef PROPRIO_HAVE_OPENXR_LAYER
  add_layer_commands(app, exit_code);
#endif
#endif
#ifdef PROPRIO_CLI_FAMILY_TRACKERS
  add_vist_commands(app, exit_code);
  add_calibrate_command(app, exit_code);
  add_stretch_glove_commands(app, exit_code);
  add_sim_glove_command(app, exit_code);
  add_stretch_array_commands(app, exit_code);
  add_train_array_command(app, exit_code);
  add_ftm_commands(app, exit_code);
  add_calibrate_ftm_command(app, exit_code);
#endif
#ifdef PROPRIO_CLI_FAMILY_DEVICES
  add_glove_command(app, exit_code);
  add_stretch_board_command(app, exit_code);
  add_ftm_board_command(app, exit_code);
  add_record_array_command(app, exit_code);
#endif
#ifdef PROPRIO_CLI_FAMILY_HAPTICS
  add_haptics_commands(app, exit_code);
#endif
#ifdef PROPRIO_CLI_FAMILY_ENGINE
#ifdef PROPRIO_HAVE_ENGINE
  add_run_command(app, exit_code);
  add_run_array_demo_command(app, exit_code);
#ifdef PROPRIO_HAVE_RIG
  add_rig_commands(app, exit_code);
  add_bench_rig_command(app, exit_code);
#endif
#endif
#ifdef PROPRIO_HAVE_OPENXR_LAYER
  add_xr_probe_command(app, exit_code);
#endif
#if defined(PROPRIO_HAVE_ENGINE) && defined(PROPRIO_HAVE_OPENXR_LAYER)
  add_calibrate_wrist_command(app, exit_code);
#endif
#endif
}

}  // namespace

int main(int argc, char** argv) {
  return proprio::cli::run_cli(argc, argv, proprio::cli::Family::PROPRIO_CLI_FAMILY, add_commands);
}
