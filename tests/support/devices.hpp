#pragma once
// Helpers shared by the USB HID device tests (glove and stretch-glove
// protocols, emulators, transports).
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>
#include <vector>

namespace proprio::testing_support {

// Standard gravity, m/s².
constexpr double kG = 9.80665;

// A report's bytes, from any container of bytes (std::array, std::span, ...).
inline std::vector<std::uint8_t> bytes_of(const auto& array) {
  return std::vector<std::uint8_t>(array.begin(), array.end());
}

inline void write_bytes(const std::filesystem::path& p, const std::vector<std::uint8_t>& b) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

inline std::vector<std::uint8_t> read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Polls `pred` every millisecond until it holds (true) or `timeout` passes (false).
template <typename Pred>
bool wait_until(Pred pred, std::chrono::seconds timeout = std::chrono::seconds(20)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace proprio::testing_support
