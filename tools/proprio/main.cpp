// proprio: the command-line entry point to Proprio's runtime.
#include <cstdio>
#include <string>

#include "commands.hpp"
#include "proprio/core/log.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "Proprio: instrumented hands for VR and psychophysics.\n"
      "Simulate, record and replay sensor-glove hand tracking. Run 'proprio <command> --help' for details."};
  app.set_version_flag("--version", std::string("proprio ") + PROPRIO_VERSION);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error or off")->capture_default_str();
  app.require_subcommand(1);

  int exit_code = 0;
  proprio::cli::add_sim_hand_command(app, exit_code);
  proprio::cli::add_replay_command(app, exit_code);
  proprio::cli::add_vist_commands(app, exit_code);
  proprio::cli::add_calibrate_command(app, exit_code);
  proprio::cli::add_stretch_glove_commands(app, exit_code);
  proprio::cli::add_glove_command(app, exit_code);
  proprio::cli::add_sim_glove_command(app, exit_code);
  proprio::cli::add_stretch_board_command(app, exit_code);
  proprio::cli::add_haptics_commands(app, exit_code);
#ifdef PROPRIO_HAVE_STUDY
  proprio::cli::add_study_commands(app, exit_code);
#endif
#ifdef PROPRIO_HAVE_ENGINE
  proprio::cli::add_run_command(app, exit_code);
#endif
#ifdef PROPRIO_HAVE_OPENXR_LAYER
  proprio::cli::add_layer_commands(app, exit_code);
  proprio::cli::add_xr_probe_command(app, exit_code);
#endif
  app.parse_complete_callback([&] {
    if (auto s = proprio::set_log_level(log_level); !s) throw CLI::ValidationError("--log-level", s.error().message);
  });

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return exit_code;
}
