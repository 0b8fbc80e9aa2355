// Runs a libFuzzer target without libFuzzer: every file of the corpus folders
// given on the command line, then deterministic mutations of each (bit flips,
// truncations, byte runs), so GCC builds and sanitizer builds exercise the
// parser too. The clang preset runs the real coverage-guided fuzzer.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

std::vector<std::uint8_t> read_all(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void run(const std::vector<std::uint8_t>& bytes) { LLVMFuzzerTestOneInput(bytes.data(), bytes.size()); }

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::vector<std::uint8_t>> corpus;
  for (int i = 1; i < argc; ++i) {
    const std::filesystem::path dir(argv[i]);
    if (!std::filesystem::is_directory(dir)) {
      std::fprintf(stderr, "replay_driver: %s is not a directory\n", argv[i]);
      return 2;
    }
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      if (entry.is_regular_file()) corpus.push_back(read_all(entry.path()));
    }
  }
  if (corpus.empty()) {
    std::fprintf(stderr, "replay_driver: no corpus files found\n");
    return 2;
  }
  run({});
  std::mt19937_64 rng(0x5eed);  // fixed: the mutations are the same every run
  std::size_t executions = 0;
  for (const auto& seed : corpus) {
    run(seed);
    ++executions;
    for (std::size_t cut = 0; cut <= seed.size(); cut += 1 + seed.size() / 64) {
      run(std::vector<std::uint8_t>(seed.begin(), seed.begin() + static_cast<std::ptrdiff_t>(cut)));
      ++executions;
    }
    for (int m = 0; m < 2000 && !seed.empty(); ++m) {
      auto bytes = seed;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits; ++e) {
        const std::size_t pos = rng() % bytes.size();
        switch (rng() % 3) {
          case 0: bytes[pos] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
          case 1: bytes[pos] = static_cast<std::uint8_t>(rng()); break;
          default: bytes[pos] = (rng() % 2) ? 0xFF : 0x00; break;
        }
      }
      run(bytes);
      ++executions;
    }
  }
  std::printf("replay_driver: %zu corpus files, %zu executions, no crash\n", corpus.size(), executions);
  return 0;
}
