// Fuzzes RecordingReader over arbitrary bytes. Any input must end in an Error
// or a finite run of records, without crash, hang or outsized allocation, and
// the summary must account for every byte. Seeds: corpus/recording_reader/
// (regenerate with PROPRIO_REGEN_CORPUS=1, see tests/unit/test_recording.cpp).
#include <cstdlib>

#include "proprio/core/recording.hpp"

using namespace proprio;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  auto reader = RecordingReader::from_bytes({data, size});
  if (!reader) return 0;
  // Every call consumes a whole record (>= 20 bytes) or ends the file.
  const std::size_t max_calls = size / 20 + 2;
  for (std::size_t calls = 0;; ++calls) {
    if (calls > max_calls) std::abort();
    auto rec = reader->next();
    if (!rec) continue;
    if (!*rec) break;
    const StreamInfo* info = reader->stream((*rec)->stream);
    if (!info || info->kind != (*rec)->kind()) std::abort();
  }
  const RecordingSummary& s = reader->summary();
  if (s.end == RecordingEnd::reading || s.valid_bytes + s.ignored_bytes != size) std::abort();
  auto after = reader->next();
  if (!after || *after) std::abort();  // the end is sticky
  return 0;
}
