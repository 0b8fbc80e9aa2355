#pragma once
// The one list of the CLI's top-level commands: name, description and which
// program carries them out. `proprio` itself runs the commands that need no
// OpenCV, Vulkan, MuJoCo or hidapi; each heavier family is a program of its own
// in libexec (the dispatcher execs it with the same argv), so that a command
// loads only the libraries it uses. Both the dispatcher (for --help and to
// find the program) and the family programs (to register the command) read
// this table, so a name or description is written once.
#include <span>
#include <string_view>

namespace CLI {
class App;
}

namespace proprio::cli {

enum class Family {
  core,      // proprio itself: core, sim, study, the layer's config
  trackers,  // proprio-trackers: VIST and stretch glove (OpenCV)
  devices,   // proprio-devices: the USB HID boards (hidapi)
  haptics,   // proprio-haptics: MuJoCo and the fingertip devices
  engine,    // proprio-engine: the engine and OpenXR (Vulkan, everything)
  split,     // a group whose subcommands live in different programs
};

struct CommandInfo {
  std::string_view path;  // "sim-hand", or "bench vist" for a subcommand of a split group
  std::string_view description;
  Family family;
  bool group;  // requires a subcommand
};

// In the order `proprio --help` lists them.
std::span<const CommandInfo> command_table();
const CommandInfo* find_command(std::string_view path);

// The program that runs `family` ("proprio-engine"); "proprio" for core.
std::string_view family_program(Family family);

// The subcommand `path` ("run", "bench vist") of `app`: the one already
// registered, or a new one with the table's description (a group requires a
// subcommand). The parent of a two-word path is added the same way.
CLI::App* add_command(CLI::App& app, std::string_view path);

}  // namespace proprio::cli
