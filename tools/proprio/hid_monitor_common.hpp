#pragma once
// What the USB HID board commands (`proprio glove`, `proprio stretch-board`)
// share: the `list` subcommand and monitor's options for finding the device.
#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "commands.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/hid_transport.hpp"
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

// The device monitor opens: `base` (the board's selector, usage page and all)
// with the IDs, serial and path given. A --path that names no hidraw node is
// refused now rather than retried until --seconds run out.
Result<hid::HidDeviceSelector> monitor_selector(const HidMonitorArgs& args, hid::HidDeviceSelector base = {});

// Adds --vid, --pid, --serial (help: serial_help), --path, --seconds and --interval.
void add_hid_monitor_options(CLI::App& monitor, HidMonitorArgs& args, const std::string& serial_help);

// An emulated board's `--unplug AT:FOR` (seconds): the CLI11 check (empty when
// acceptable, else why not) and the parsed (at, duration) in nanoseconds.
std::string check_board_unplug(const std::string& text);
Result<std::pair<TimeNs, DurationNs>> parse_board_unplug(const std::string& text);

// The link faults and clock every board emulator takes (`emulate` subcommands).
struct BoardEmulatorFaultArgs {
  double clock_ppm = 0.0;
  std::uint32_t start_timestamp_us = 0;
  double drop = 0.0, duplicate = 0.0, corrupt = 0.0, reorder = 0.0;
  std::vector<std::string> unplugs;  // AT:FOR, checked by check_board_unplug
};

// Adds --clock-ppm, --start-timestamp-us, --drop, --duplicate, --corrupt,
// --reorder and --unplug; `device` names what loses power ("the board").
void add_board_emulator_fault_options(CLI::App& emulate, BoardEmulatorFaultArgs& args, const std::string& device);

// Copies them into an emulator's options (clock_error_ppm, boot_timestamp_us, faults).
template <typename EmulatorOptions>
void apply_board_emulator_faults(const BoardEmulatorFaultArgs& a, EmulatorOptions& eo) {
  eo.clock_error_ppm = a.clock_ppm;
  eo.boot_timestamp_us = a.start_timestamp_us;
  eo.faults.drop_probability = a.drop;
  eo.faults.duplicate_probability = a.duplicate;
  eo.faults.corrupt_probability = a.corrupt;
  eo.faults.reorder_probability = a.reorder;
  for (const std::string& u : a.unplugs) {
    if (auto at_for = parse_board_unplug(u)) eo.faults.unplugs.push_back({at_for->first, at_for->second});
  }
}

// Prints a board link's state changes ("[streaming] /dev/hidraw3"); for
// set_state_callback, on the reader thread.
void print_link_state(hid::LinkState state, std::string_view detail);

}  // namespace proprio::cli
