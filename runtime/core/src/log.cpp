#include "proprio/core/log.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>

#include <string>

namespace proprio {

spdlog::logger& logger() {
  // Created on first use; stderr keeps stdout free for machine-readable output.
  static std::shared_ptr<spdlog::logger> instance = [] {
    auto l = spdlog::get("proprio");
    if (!l) l = spdlog::stderr_color_mt("proprio");
    l->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
    return l;
  }();
  return *instance;
}

Status set_log_level(std::string_view level) {
  const auto parsed = spdlog::level::from_str(std::string(level));
  // from_str maps anything unknown to "off"; only accept "off" when asked for.
  if (parsed == spdlog::level::off && level != "off") {
    return make_error(Errc::invalid_argument, "unknown log level '" + std::string(level) +
                                                  "' (use trace, debug, info, warn, error or off)");
  }
  logger().set_level(parsed);
  return {};
}

}  // namespace proprio
