// proprio: the command-line entry point to Proprio's runtime.
#include <cstdio>
#include <string>

#include "commands.hpp"
#include "option_checks.hpp"
#include "proprio/core/log.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "Proprio: instrumented hands for VR and psychophysics.\n"
      "Simulate, record and replay sensor-glove hand tracking. Run 'proprio <command> --help' for details."};
  app.set_version_flag("--version", std::string("proprio ") + PROPRIO_VERSION);
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error or off")->capture_default_str();
  app.require_subcommand(1);
  app.footer(
      "Exit status: 0 success; 1 an error (a bad option or value, unreadable input, a failed run), with a message "
      "on stderr. Some commands add codes of their own, listed in their --help.");

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
  proprio::cli::harden_numeric_options(app);
  app.parse_complete_callback([&] {
    if (auto s = proprio::set_log_level(log_level); !s) throw CLI::ValidationError("--log-level", s.error().message);
  });

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11's own codes (105 for an invalid value, 106 for a missing one, ...)
    // are not ours to document: every usage error is the general error, 1.
    const int code = app.exit(e);
    return code == 0 ? 0 : 1;
  }
  return exit_code;
}
