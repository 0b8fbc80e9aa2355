#include "cli_app.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "option_checks.hpp"
#include "proprio/core/log.hpp"

// Where the family programs are installed, relative to the folder of the
// installed `proprio` (bin/ -> libexec/proprio/), and this build's folder of
// them, the last place looked (a copy of the build's `proprio` run from
// elsewhere, as the hostile suite does).
#ifndef PROPRIO_LIBEXEC_FROM_BIN
#define PROPRIO_LIBEXEC_FROM_BIN "../libexec/proprio"
#endif
#ifndef PROPRIO_BUILD_LIBEXEC_DIR
#define PROPRIO_BUILD_LIBEXEC_DIR ""
#endif

namespace proprio::cli {
namespace {

namespace fs = std::filesystem;

bool is_help(std::string_view a) { return a == "-h" || a == "--help"; }

// The command of another program that argv names, or nullptr when this
// program parses argv itself. Mirrors how CLI11 reads the top level: the
// global options (--log-level VALUE, --log-level=VALUE, -h, --help, --version)
// may come before the command. Anything else first is this program's to
// report.
const CommandInfo* foreign_command(int argc, char** argv) {
  int i = 1;
  while (i < argc) {
    const std::string_view a = argv[i];
    if (a == "--log-level") {
      i += 2;
    } else if (a.starts_with("--log-level=") || is_help(a) || a == "--version") {
      ++i;
    } else {
      break;
    }
  }
  if (i >= argc) return nullptr;
  const CommandInfo* top = find_command(argv[i]);
  if (top == nullptr || top->path.find(' ') != std::string_view::npos) return nullptr;
  if (top->family == Family::split) {
    int j = i + 1;
    while (j < argc && is_help(argv[j])) ++j;
    if (j >= argc) return nullptr;
    const CommandInfo* sub = find_command(std::string(top->path) + " " + argv[j]);
    return sub != nullptr && sub->family != Family::core ? sub : nullptr;
  }
  return top->family == Family::core ? nullptr : top;
}

fs::path own_dir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe.parent_path();
}

// Why `path` cannot be run, or empty when it can.
std::string unusable(const fs::path& path) {
  struct stat st{};
  if (::stat(path.c_str(), &st) != 0) return std::strerror(errno);
  if (S_ISDIR(st.st_mode)) return "a folder, not a program";
  if (S_ISFIFO(st.st_mode)) return "a FIFO (named pipe), not a program";
  if (!S_ISREG(st.st_mode)) return "not a regular file";
  if (::access(path.c_str(), X_OK) != 0) return "not executable";
  return {};
}

// Replaces this process with the program of `command`; returns the exit
// code 1 with a message when there is none to run.
int exec_family(const CommandInfo& command, char** argv) {
  const std::string program(family_program(command.family));
  const char* override_dir = std::getenv("PROPRIO_LIBEXEC_DIR");
  const bool overridden = override_dir != nullptr && *override_dir != '\0';
  std::vector<fs::path> dirs;
  if (overridden) {
    dirs.emplace_back(override_dir);
  } else {
    if (const fs::path dir = own_dir(); !dir.empty()) {
      dirs.push_back(dir);
      dirs.push_back((dir / PROPRIO_LIBEXEC_FROM_BIN).lexically_normal());
    }
    if (std::string_view(PROPRIO_BUILD_LIBEXEC_DIR).size() > 0) dirs.emplace_back(PROPRIO_BUILD_LIBEXEC_DIR);
  }
  std::string looked;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    if (i > 0 && dirs[i] == dirs[i - 1]) continue;
    const fs::path path = dirs[i] / program;
    if (std::string why = unusable(path); !why.empty()) {
      looked += (looked.empty() ? "" : "; ") + path.string() + ": " + why;
      continue;
    }
    ::execv(path.c_str(), argv);
    std::fprintf(stderr, "error: 'proprio %s' runs in %s, which could not be started: %s\n",
                 std::string(command.path).c_str(), path.c_str(), std::strerror(errno));
    return 1;
  }
  std::fprintf(stderr, "error: 'proprio %s' runs in the program %s, which was not found (%s). %s\n",
               std::string(command.path).c_str(), program.c_str(), looked.c_str(),
               overridden ? "PROPRIO_LIBEXEC_DIR is set: point it at the folder holding the program, or unset it."
                          : "Reinstall Proprio, or set PROPRIO_LIBEXEC_DIR to the folder holding the program.");
  return 1;
}

}  // namespace

int run_cli(int argc, char** argv, Family self, AddCommands add_commands) {
  if (self == Family::core) {
    if (const CommandInfo* command = foreign_command(argc, argv)) return exec_family(*command, argv);
  }
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
  // Every command in the table's order; the dispatcher lists the other
  // programs' commands too, as entries that hand argv over when parsed (the
  // argv scan above normally does that before parsing).
  for (const CommandInfo& command : command_table()) {
    if (command.family == self || (command.family == Family::split && self == Family::core)) {
      add_command(app, command.path);
    } else if (self == Family::core) {
      CLI::App* forward = add_command(app, command.path);
      forward->require_subcommand(0, 0);
      forward->prefix_command();
      forward->allow_extras();
      forward->callback([&command, argv, &exit_code] { exit_code = exec_family(command, argv); });
    }
  }
  add_commands(app, exit_code);
  harden_numeric_options(app);
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

}  // namespace proprio::cli
