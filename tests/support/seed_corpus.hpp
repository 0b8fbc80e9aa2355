#pragma once
// The fuzz seed corpora of the board protocols (tests/fuzz/corpus/<target>):
// where they live, when to rewrite them, and the check every board runs over
// its seeds. Naming: info_report* and command* files hold one report each;
// every other file is a stream of data reports, "faults" in its name when the
// emulator corrupted some of them.
#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "support/devices.hpp"

namespace proprio::testing_support {

inline std::filesystem::path fuzz_corpus_dir(std::string_view target) {
  return std::filesystem::path(PROPRIO_TESTS_DIR) / "fuzz" / "corpus" / target;
}

// PROPRIO_REGEN_CORPUS=1 asks the Regenerate tests to rewrite the seeds.
inline bool regenerate_corpus_requested() {
  const char* regen = std::getenv("PROPRIO_REGEN_CORPUS");
  return regen && std::string(regen) == "1";
}

// Emulated reports (anything with a .bytes container) back to back, as a stream seed.
template <typename Reports>
std::vector<std::uint8_t> concat_reports(const Reports& reports) {
  std::vector<std::uint8_t> out;
  for (const auto& r : reports) out.insert(out.end(), r.bytes.begin(), r.bytes.end());
  return out;
}

// How many of a stream seed's fixed-size reports decode (a Result) refuses.
template <typename Decode>
std::size_t count_refused(const std::vector<std::uint8_t>& stream, std::size_t report_size, Decode decode) {
  std::size_t bad = 0;
  for (std::size_t at = 0; at + report_size <= stream.size(); at += report_size) {
    bad += !decode(std::span(stream).subspan(at, report_size)).ok();
  }
  return bad;
}

// Runs the board's checks over every seed in dir (each under its name's
// trace): decode_info / decode_command (a Result) must accept their single
// reports; check_stream(bytes, faulty) judges every stream. Returns how many
// seeds it saw, for the caller to hold against the corpus it expects.
template <typename DecodeInfo, typename DecodeCommand, typename CheckStream>
std::size_t check_seed_corpus(const std::filesystem::path& dir, DecodeInfo decode_info, DecodeCommand decode_command,
                              CheckStream check_stream) {
  std::size_t seeds = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    SCOPED_TRACE(name);
    const std::vector<std::uint8_t> b = read_bytes(e.path());
    ++seeds;
    if (name.rfind("info_report", 0) == 0) {
      EXPECT_TRUE(decode_info(b).ok());
    } else if (name.rfind("command", 0) == 0) {
      EXPECT_TRUE(decode_command(b).ok());
    } else {
      check_stream(b, name.find("faults") != std::string::npos);
    }
  }
  return seeds;
}

}  // namespace proprio::testing_support
