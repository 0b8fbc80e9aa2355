// Fuzzes hid::CaptureReader, the capture-file reader behind `proprio glove
// monitor --from-file` and `proprio stretch-board monitor --from-file`, with
// the IMU glove's and the stretch board's framings. Whatever the bytes:
//  - every yielded frame is the file's bytes at its offset (never out of
//    bounds), starts with an ID of the protocol, and is as long as that ID
//    says, or shorter only when it ends the file;
//  - a frame marked intact has a matching CRC, and a frame marked damaged
//    does not (or is cut short);
//  - frames and skipped bytes tile the file: together they are its size;
//  - the window's size changes nothing (a small window slides, re-reads and
//    must yield the same frames as a window holding the whole file);
//  - the frames and skips are exactly those of the whole-buffer reader the
//    two monitors had before (reference_frames below, kept as the spec).
// Input: byte 0 picks the window and whether to make the frames' CRCs right
// first (so that mutations reach the resynchronisation, which random bytes
// seldom do); the rest is the capture. Seeds: corpus/capture_file/.
#include <cstdlib>
#include <vector>

#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/hid/capture_file.hpp"
#include "proprio/hid/crc16.hpp"

using namespace proprio;

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

struct Span {
  std::uint64_t offset;
  std::size_t size;
  bool operator==(const Span&) const = default;
};

struct Outcome {
  std::vector<Span> frames;
  std::uint64_t skipped = 0;
  bool operator==(const Outcome&) const = default;
};

// The reader the monitors carried before hid::CaptureReader, verbatim but for
// names: the whole file in memory.
Outcome reference_frames(std::span<const std::uint8_t> bytes, std::size_t (*size_for)(std::uint8_t) noexcept) {
  const auto valid_frame_at = [&](std::size_t at) {
    const std::size_t size = size_for(bytes[at]);
    if (size == 0 || bytes.size() - at < size) return false;
    const auto frame = bytes.subspan(at, size);
    return hid::crc16_ccitt(frame.first(size - 2)) ==
           static_cast<std::uint16_t>(frame[size - 2] | frame[size - 1] << 8);
  };
  Outcome o;
  std::size_t next_good = 0;
  for (std::size_t at = 0; at < bytes.size();) {
    std::size_t size = size_for(bytes[at]);
    if (size == 0) {
      ++o.skipped;
      ++at;
      continue;
    }
    size = std::min(size, bytes.size() - at);
    if (!valid_frame_at(at) && at + size < bytes.size() && !valid_frame_at(at + size)) {
      if (next_good <= at) {
        next_good = at + 1;
        while (next_good < bytes.size() && !valid_frame_at(next_good)) ++next_good;
      }
      if ((next_good - at) % size != 0) {
        o.skipped += next_good - at;
        at = next_good;
        continue;
      }
    }
    o.frames.push_back({at, size});
    at += size;
  }
  return o;
}

Outcome read_all(std::span<const std::uint8_t> bytes, const hid::CaptureFraming& framing, std::size_t window) {
  hid::CaptureReaderOptions options;
  options.window_bytes = window;
  auto reader = hid::CaptureReader::from_memory(bytes, framing, options);
  require(reader.ok());
  Outcome o;
  std::uint64_t expected_offset = 0, frame_bytes = 0, damaged = 0;
  hid::CaptureFrame f;
  for (;;) {
    auto more = reader->next(f);
    require(more.ok());
    if (!*more) break;
    // Never out of bounds, and truly the file's bytes at that offset.
    require(f.offset >= expected_offset && f.offset < bytes.size() && f.bytes.size() <= bytes.size() - f.offset);
    require(std::equal(f.bytes.begin(), f.bytes.end(), bytes.begin() + static_cast<std::ptrdiff_t>(f.offset)));
    const std::size_t size = framing.report_size_for_id(f.bytes[0]);
    require(size != 0);
    require(f.bytes.size() == size || (f.bytes.size() < size && f.offset + f.bytes.size() == bytes.size()));
    require(f.intact == hid::capture_frame_intact(framing, f.bytes));
    if (!f.intact) ++damaged;
    expected_offset = f.offset + f.bytes.size();
    frame_bytes += f.bytes.size();
    o.frames.push_back({f.offset, f.bytes.size()});
  }
  const hid::CaptureStats& s = reader->stats();
  require(s.bytes_consumed == bytes.size());
  require(s.skipped_bytes + frame_bytes == bytes.size());
  require(s.frames == o.frames.size() && s.damaged_frames == damaged);
  // After the end, the end again.
  auto again = reader->next(f);
  require(again.ok() && !*again);
  o.skipped = s.skipped_bytes;
  return o;
}

// Frames the bytes naively by ID (unknown bytes alone) and writes each
// complete frame's CRC, except where the frame's second byte is odd: a
// stream of intact reports, damaged reports and garbage, from few bytes.
std::vector<std::uint8_t> with_crcs(std::span<const std::uint8_t> bytes,
                                    std::size_t (*size_for)(std::uint8_t) noexcept) {
  std::vector<std::uint8_t> out(bytes.begin(), bytes.end());
  for (std::size_t at = 0; at < out.size();) {
    const std::size_t size = size_for(out[at]);
    if (size == 0 || out.size() - at < size) {
      ++at;
      continue;
    }
    if ((out[at + 1] & 1) == 0) {
      const std::uint16_t crc = hid::crc16_ccitt(std::span(out).subspan(at, size - 2));
      out[at + size - 2] = static_cast<std::uint8_t>(crc);
      out[at + size - 1] = static_cast<std::uint8_t>(crc >> 8);
    }
    at += size;
  }
  return out;
}

void check(std::span<const std::uint8_t> bytes, std::size_t (*size_for)(std::uint8_t) noexcept,
           std::size_t small_window) {
  const hid::CaptureFraming framing{size_for};
  const Outcome spec = reference_frames(bytes, size_for);
  require(read_all(bytes, framing, bytes.size() + 1) == spec);
  require(read_all(bytes, framing, small_window) == spec);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::uint8_t control = data[0];
  const std::span<const std::uint8_t> capture(data + 1, size - 1);
  // 0 asks for the smallest window the reader allows (two largest reports).
  const std::size_t small_window = static_cast<std::size_t>(control & 0x7f) * 3;
  for (auto size_for : {&devices::report_size_for_id, &devices::stretch_report_size_for_id}) {
    if (control & 0x80) {
      const auto fixed = with_crcs(capture, size_for);
      check(fixed, size_for, small_window);
    } else {
      check(capture, size_for, small_window);
    }
  }
  return 0;
}
