#pragma once
// What the USB HID board commands (`proprio glove`, `proprio stretch-board`)
// share: the `list` subcommand and monitor's options for finding the device.
#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>

#include "commands.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/link_state.hpp"

namespace proprio::cli {

// Which device a command is about.
struct HidBoardKind {
  const char* name;     // in messages: "glove", "stretch board"
  const char* command;  // the CLI command: "glove", "stretch-board"
  std::uint16_t vendor_id;
  std::uint16_t product_id;
  std::uint16_t usage_page;  // the vendor page its reports use
};

// `list`: the HID devices with the board's USB IDs (or all with --all).
// `help` is the subcommand's description, `all_help` the --all option's.
void add_hid_list_command(CLI::App& parent, const HidBoardKind& kind, const std::string& help,
                          const std::string& all_help, int& exit_code);

// Monitor's options for opening a live board; the defaults are the board's USB IDs.
struct HidMonitorArgs {
  explicit HidMonitorArgs(const HidBoardKind& kind) : vid(hex4(kind.vendor_id)), pid(hex4(kind.product_id)) {}
  std::string vid;
  std::string pid;
  std::string serial;
  std::string path;
  double seconds = 0.0;
  double interval_s = 1.0;
};

// Adds --vid, --pid, --serial (help: serial_help), --path, --seconds and --interval.
void add_hid_monitor_options(CLI::App& monitor, HidMonitorArgs& args, const std::string& serial_help);

// An emulated board's `--unplug AT:FOR` (seconds): the CLI11 check (empty when
// acceptable, else why not) and the parsed (at, duration) in nanoseconds.
std::string check_board_unplug(const std::string& text);
Result<std::pair<TimeNs, DurationNs>> parse_board_unplug(const std::string& text);

// Prints a board link's state changes ("[streaming] /dev/hidraw3"); for
// set_state_callback, on the reader thread.
void print_link_state(hid::LinkState state, std::string_view detail);

}  // namespace proprio::cli
