#include "hid_monitor_common.hpp"

#include <cstdio>
#include <cstdlib>
#include <memory>

#include "proprio/core/log.hpp"
#include "proprio/hid/hid_transport.hpp"

namespace proprio::cli {

namespace {

struct HidListArgs {
  bool all = false;
  std::string vid;
  std::string pid;
};

int run_hid_list(const HidListArgs& a, const HidBoardKind& kind) {
  const std::uint16_t vid = a.all ? 0 : parse_hex_id(a.vid);
  const std::uint16_t pid = a.all ? 0 : parse_hex_id(a.pid);
  auto devices = hid::enumerate_hid_devices(vid, pid);
  if (!devices) return logger().error("{}", devices.error().message), 1;
  if (devices->empty()) {
    if (a.all) {
      std::printf("no HID devices found (hidapi %s)\n", hid::hidapi_version().c_str());
    } else {
      std::printf("no %s found with VID:PID %s:%s; 'proprio %s list --all' lists every HID device\n", kind.name,
                  hex4(vid).c_str(), hex4(pid).c_str(), kind.command);
    }
    return 0;
  }
  std::printf("%-20s %-9s %-8s %-4s %-16s %s\n", "path", "vid:pid", "usage", "intf", "serial", "manufacturer / product");
  const std::string tag = std::string("  [") + kind.name + "]";
  for (const hid::HidDeviceInfo& d : *devices) {
    const bool match = d.vendor_id == kind.vendor_id && d.product_id == kind.product_id &&
                       (d.usage_page == 0 || d.usage_page == kind.usage_page);
    std::printf("%-20s %s:%s %04x:%02x %-4d %-16s %s / %s%s\n", d.path.c_str(), hex4(d.vendor_id).c_str(),
                hex4(d.product_id).c_str(), d.usage_page, d.usage, d.interface_number,
                d.serial.empty() ? "-" : d.serial.c_str(), d.manufacturer.c_str(), d.product.c_str(),
                match ? tag.c_str() : "");
  }
  return 0;
}

std::string check_hex(const std::string& s) { return check_hex_id(s); }

}  // namespace

void add_hid_list_command(CLI::App& parent, const HidBoardKind& kind, const std::string& help,
                          const std::string& all_help, int& exit_code) {
  auto list = std::make_shared<HidListArgs>();
  list->vid = hex4(kind.vendor_id);
  list->pid = hex4(kind.product_id);
  CLI::App* list_cmd = parent.add_subcommand("list", help);
  list_cmd->add_flag("--all", list->all, all_help);
  list_cmd->add_option("--vid", list->vid, "USB vendor ID, hexadecimal")->check(check_hex)->capture_default_str();
  list_cmd->add_option("--pid", list->pid, "USB product ID, hexadecimal")->check(check_hex)->capture_default_str();
  list_cmd->callback([list, kind, &exit_code] { exit_code = run_hid_list(*list, kind); });
}

std::string check_board_unplug(const std::string& text) {
  const auto colon = text.find(':');
  char* end = nullptr;
  if (colon == std::string::npos) return "'" + text + "': use AT:FOR, seconds, e.g. 2.5:1";
  const double at = std::strtod(text.substr(0, colon).c_str(), &end);
  if (*end != '\0' || !(at >= 0) || !(at < 1e6)) return "'" + text + "': AT must be seconds >= 0";
  const double dur = std::strtod(text.substr(colon + 1).c_str(), &end);
  if (*end != '\0' || !(dur > 0) || !(dur < 1e6)) return "'" + text + "': FOR must be seconds > 0";
  return {};
}

Result<std::pair<TimeNs, DurationNs>> parse_board_unplug(const std::string& text) {
  if (std::string why = check_board_unplug(text); !why.empty()) return make_error(Errc::invalid_argument, "--unplug " + why);
  const auto colon = text.find(':');
  return std::pair<TimeNs, DurationNs>{seconds_to_ns(std::strtod(text.substr(0, colon).c_str(), nullptr)),
                                       seconds_to_ns(std::strtod(text.substr(colon + 1).c_str(), nullptr))};
}

void add_board_emulator_fault_options(CLI::App& emulate, BoardEmulatorFaultArgs& args, const std::string& device) {
  emulate.add_option("--clock-ppm", args.clock_ppm, "Device crystal error, ppm (a real one is within ±100)")
      ->check(CLI::Range(-1000.0, 1000.0))
      ->capture_default_str();
  emulate.add_option("--start-timestamp-us", args.start_timestamp_us,
                     "Device µs counter at power-up; real firmware starts at 0, 4294000000 makes it wrap about 1 s in")
      ->capture_default_str();
  emulate.add_option("--drop", args.drop, "Probability that a report is lost")->check(CLI::Range(0.0, 1.0));
  emulate.add_option("--duplicate", args.duplicate, "Probability that a report is sent twice")
      ->check(CLI::Range(0.0, 1.0));
  emulate.add_option("--corrupt", args.corrupt, "Probability that a report has one bit flipped")
      ->check(CLI::Range(0.0, 1.0));
  emulate.add_option("--reorder", args.reorder, "Probability that a report is sent after the next one")
      ->check(CLI::Range(0.0, 1.0));
  emulate.add_option("--unplug", args.unplugs,
                     "AT:FOR in seconds: " + device + " loses power at AT for FOR, then boots again (repeatable)")
      ->check([](const std::string& s) { return check_board_unplug(s); });
}

void print_link_state(hid::LinkState state, std::string_view detail) {
  // On the reader thread; one printf and a flush per change.
  std::printf("[%s] %.*s\n", hid::to_string(state), static_cast<int>(detail.size()), detail.data());
  std::fflush(stdout);
}

Result<hid::HidDeviceSelector> monitor_selector(const HidMonitorArgs& args, hid::HidDeviceSelector base) {
  base.vendor_id = parse_hex_id(args.vid);
  base.product_id = parse_hex_id(args.pid);
  base.serial = args.serial;
  base.path = args.path;
  if (!args.path.empty()) {
    if (auto s = hid::check_hidraw_node(args.path); !s) return s.error();
  }
  return base;
}

void add_hid_monitor_options(CLI::App& monitor, HidMonitorArgs& args, const std::string& serial_help) {
  monitor.add_option("--vid", args.vid, "USB vendor ID, hexadecimal")->check(check_hex)->capture_default_str();
  monitor.add_option("--pid", args.pid, "USB product ID, hexadecimal")->check(check_hex)->capture_default_str();
  monitor.add_option("--serial", args.serial, serial_help);
  monitor.add_option("--path", args.path, "Open this HID device node (e.g. /dev/hidraw3) instead of searching");
  monitor.add_option("--seconds", args.seconds, "Stop after this long, s (0: until Ctrl-C)")
      ->check(CLI::Range(0.0, 7.0 * 24 * 3600))
      ->capture_default_str();
  monitor.add_option("--interval", args.interval_s, "Seconds between status lines")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
}

}  // namespace proprio::cli
