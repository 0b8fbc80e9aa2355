#pragma once
// Reading a device's optional device-info feature report when the link opens,
// for the input devices that stream without it (the IMU glove, the stretch
// board): a device that lacks it or sends bad bytes still connects, so the
// outcome is only logged.
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "proprio/core/log.hpp"
#include "proprio/core/result.hpp"
#include "proprio/hid/hid_transport.hpp"

namespace proprio::hid {

// Reads feature report report_id (at most Size bytes, report ID first) and
// decodes it. No report: logged at debug (firmware may not have it); one
// that does not decode: a warning. `who` starts each log line ("glove").
template <std::size_t Size, typename Info>
std::optional<Info> query_info_report(HidTransport& transport, std::uint8_t report_id,
                                      Result<Info> (*decode)(std::span<const std::uint8_t>), std::string_view who) {
  std::array<std::uint8_t, Size> buf{};
  auto n = transport.get_feature(report_id, buf);
  if (!n) {
    logger().debug("{}: no device info report: {}", who, n.error().message);
    return std::nullopt;
  }
  auto info = decode(std::span<const std::uint8_t>(buf).first(std::min(*n, buf.size())));
  if (!info) {
    logger().warn("{}: device info report unreadable: {}", who, info.error().message);
    return std::nullopt;
  }
  return *info;
}

}  // namespace proprio::hid
