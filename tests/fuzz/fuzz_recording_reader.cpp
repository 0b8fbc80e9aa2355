// Fuzzes RecordingReader over arbitrary bytes. Any input must end in an Error
// or a finite run of records, without crash, hang or outsized allocation, and
// the summary must account for every byte. Each input is also read with its
// CRCs repaired, and once more with its middle damaged, so the payload decoders
// and the resynchronisation after damage both see every input. Seeds: corpus/recording_reader/
// (regenerate with PROPRIO_REGEN_CORPUS=1, see tests/unit/runtime/core/test_recording.cpp).
#include <algorithm>
#include <cstdlib>
#include <vector>

#include "proprio/core/recording.hpp"

using namespace proprio;

namespace {

std::uint32_t le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0] | p[1] << 8 | p[2] << 16) | static_cast<std::uint32_t>(p[3]) << 24;
}
void put32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// Rewrites the header and record CRCs so that mutated payloads get past the
// CRC check and reach the payload decoders.
std::vector<std::uint8_t> with_valid_crcs(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> b(data, data + size);
  if (b.size() < 20) return b;
  const std::size_t header = le32(&b[12]);
  if (header < 20 || header > b.size()) return b;
  put32(&b[header - 4], crc32_ieee(std::span(b).first(header - 4)));
  for (std::size_t pos = header; pos + 20 <= b.size();) {
    const std::size_t len = le32(&b[pos]);
    if (len > b.size() - pos - 20) break;
    put32(&b[pos + 16 + len], crc32_ieee(std::span(b).subspan(pos, 16 + len)));
    pos += 20 + len;
  }
  return b;
}

void check(std::span<const std::uint8_t> bytes) {
  auto reader = RecordingReader::from_bytes(bytes);
  if (!reader) return;
  // Every call consumes a whole record (>= 20 bytes) or ends the file.
  const std::size_t max_calls = bytes.size() / 20 + 2;
  for (std::size_t calls = 0;; ++calls) {
    if (calls > max_calls) std::abort();
    auto rec = reader->next();
    if (!rec) continue;
    if (!*rec) break;
    const StreamInfo* info = reader->stream((*rec)->stream);
    if (!info || info->kind != (*rec)->kind()) std::abort();
  }
  const RecordingSummary& s = reader->summary();
  if (s.end == RecordingEnd::reading || s.valid_bytes + s.ignored_bytes != bytes.size()) std::abort();
  if (s.skipped_bytes > s.ignored_bytes || (s.corrupt_regions > 0) != (s.skipped_bytes > 0)) std::abort();
  if (s.corrupt_regions > 0 && s.end != RecordingEnd::corrupt) std::abort();
  // Resynchronisation work stays within its budget, and giving up is corruption.
  if (s.resync_checked_bytes > kRecordingResyncBudgetFileSizes * bytes.size() + kRecordingResyncBudgetExtraBytes) {
    std::abort();
  }
  if (s.resync_gave_up && s.end != RecordingEnd::corrupt) std::abort();
  auto after = reader->next();
  if (!after || *after) std::abort();  // the end is sticky
}

// Damages the middle of an otherwise intact file (its first byte picks where
// and how), so that the reader's resynchronisation runs on every input.
std::vector<std::uint8_t> damaged_mid_file(std::vector<std::uint8_t> b) {
  if (b.size() < 64) return b;
  const std::size_t at = 20 + (b[0] * (b.size() - 40)) / 256;
  const std::size_t n = 1 + b[1] % 48;
  for (std::size_t i = at; i < std::min(b.size(), at + n); ++i) b[i] = static_cast<std::uint8_t>(b[i] ^ (0x5A + i));
  return b;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  check({data, size});
  const auto intact = with_valid_crcs(data, size);
  check(intact);
  check(damaged_mid_file(intact));
  return 0;
}
