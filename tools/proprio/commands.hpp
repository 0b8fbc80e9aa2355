#pragma once
#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "command_list.hpp"
#include "command_table.hpp"
#include "proprio/core/result.hpp"

namespace proprio::cli {

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

}  // namespace proprio::cli
