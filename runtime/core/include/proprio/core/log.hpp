#pragma once
// One spdlog logger for the whole runtime, named "proprio", on stderr.
#include <spdlog/spdlog.h>

#include <string_view>

#include "proprio/core/result.hpp"

namespace proprio {

spdlog::logger& logger();

// "trace", "debug", "info", "warn", "error", "off".
Status set_log_level(std::string_view level);

}  // namespace proprio
