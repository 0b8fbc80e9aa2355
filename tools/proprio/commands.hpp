#pragma once
#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "proprio/core/result.hpp"

namespace proprio::cli {

// A parent command several files add to (`bench vist`, `bench glove`, ...):
// the existing one, or a new one that requires a subcommand.
inline CLI::App* subcommand_group(CLI::App& app, const std::string& name, const std::string& description) {
  for (CLI::App* sub : app.get_subcommands({})) {
    if (sub->get_name() == name) return sub;
  }
  CLI::App* sub = app.add_subcommand(name, description);
  sub->require_subcommand(1);
  return sub;
}

// Prints "error: <message>" to stderr and returns the exit code 1.
inline int report_error(const Error& error) {
  std::fprintf(stderr, "error: %s\n", error.message.c_str());
  return 1;
}

// USB IDs are hexadecimal by convention: "1209", "0x1209".
inline std::uint16_t parse_hex_id(const std::string& text) {
  return static_cast<std::uint16_t>(std::strtoul(text.c_str(), nullptr, 16));
}
inline std::string hex4(std::uint16_t v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "%04x", v);
  return buf;
}

inline std::string check_hex_id(const std::string& text) {
  char* end = nullptr;
  const unsigned long v = std::strtoul(text.c_str(), &end, 16);
  if (text.empty() || *end != '\0' || v > 0xFFFF) return "'" + text + "' is not a 16-bit hexadecimal USB ID";
  return {};
}

// `--from-file` captures are read whole: an hour of a 1 kHz board is ~100 MB.
inline constexpr std::uint64_t kMaxCaptureBytes = 1024ull * 1024ull * 1024ull;

// Long-running commands stop cleanly on Ctrl-C: install on_sigint_stop and
// poll g_sigint_stop; a second Ctrl-C ends the process at once.
inline std::atomic<bool> g_sigint_stop{false};
extern "C" inline void on_sigint_stop(int) {
  g_sigint_stop.store(true);
  std::signal(SIGINT, SIG_DFL);
}

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
// `stretch-board emulate|monitor|list`: the stretch glove's USB HID read-out board.
void add_stretch_board_command(CLI::App& app, int& exit_code);
// `layer install|uninstall|status|init-config` and `xr-probe`: built when the
// OpenXR layer is part of the build (PROPRIO_HAVE_OPENXR_LAYER).
// `haptics sim|mjcf|devices|test` and `bench haptics`.
void add_haptics_commands(CLI::App& app, int& exit_code);
void add_haptics_device_commands(CLI::App& haptics, int& exit_code);
void add_layer_commands(CLI::App& app, int& exit_code);
// `psychometric fit`, `stats ...` and `study ...` (proprio::study).
void add_study_commands(CLI::App& app, int& exit_code);
// `run SCENE`: the engine (proprio::engine).
void add_run_command(CLI::App& app, int& exit_code);
void add_xr_probe_command(CLI::App& app, int& exit_code);

}  // namespace proprio::cli
