#pragma once
// Reads a capture file: HID input reports back to back, as hid_read returned
// them (`proprio glove emulate --out`, `cat /dev/hidrawN`). Each report's
// first byte, its ID, gives its size; each ends in crc16_ccitt of the bytes
// before it, little-endian. One reader serves every device: a protocol only
// says how long its reports are.
//
// Damage is survived the way the monitors have always survived it (the
// resynchronisation rule below is theirs, unchanged, so their counts stay
// comparable across versions):
//  - a byte that is no report ID is skipped;
//  - a report that is intact, or damaged but followed by an intact report, is
//    yielded whole (a corrupted payload costs that report, and the decoder
//    counts it as undecodable);
//  - when neither a report nor the one after it is intact, framing may be
//    lost: the reader finds the next offset where an intact report starts. If
//    the gap is a whole number of reports of the current size it yields them
//    (damaged, framing kept); otherwise (a torn write, a corrupted ID byte) it
//    skips the gap;
//  - the last report, cut short by the end of the file, is yielded short.
// Every byte of the file is either in a yielded frame or skipped.
//
// Memory is bounded by the window (default 1 MiB), whatever the file's size.
// The one look-ahead the rule needs, the search for the next intact report,
// may run past the window; a gap of whole damaged reports longer than the
// window is then read a second time (stats().reread_bytes).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/file_io.hpp"
#include "proprio/core/result.hpp"

namespace proprio::hid {

// A protocol's framing.
struct CaptureFraming {
  // Size in bytes (ID byte and CRC included) of the report an ID byte starts;
  // 0 for a byte that is no report ID of the protocol. Sizes 1 and 2 cannot
  // hold a CRC and are refused.
  std::size_t (*report_size_for_id)(std::uint8_t report_id) = nullptr;
};

// Whether `frame` is one complete report of the protocol: as long as its ID
// says, ending in the CRC of the bytes before it.
bool capture_frame_intact(const CaptureFraming& framing, std::span<const std::uint8_t> frame) noexcept;

struct CaptureReaderOptions {
  std::string what = "capture file";  // names the file in messages
  // Refuse a larger file (0: no limit), with read_input_file's message. With
  // bounded memory this bounds the time a monitor takes, nothing more.
  std::uint64_t max_bytes = 0;
  // Bytes held in memory; raised to twice the protocol's largest report (a
  // report and the one after it).
  std::size_t window_bytes = 1u << 20;
};

struct CaptureFrame {
  std::span<const std::uint8_t> bytes;  // valid until the next call to next()
  std::uint64_t offset = 0;             // of its first byte in the file
  bool intact = false;                  // complete, and its CRC matches
};

struct CaptureStats {
  std::uint64_t bytes_consumed = 0;  // frames + skipped so far: the file's size once next() has said "end"
  std::uint64_t frames = 0;          // yielded
  std::uint64_t damaged_frames = 0;  // yielded but not intact (CRC mismatch, or cut short by the end)
  std::uint64_t skipped_bytes = 0;   // in no frame: dropped to resynchronise
  std::uint64_t reread_bytes = 0;    // read a second time (a damaged stretch longer than the window)
};

// Reads a whole capture file, handing every frame to `on_frame` in file
// order; the stats at the end, or the first error.
Result<CaptureStats> read_capture_file(const std::filesystem::path& path, const CaptureFraming& framing,
                                       const CaptureReaderOptions& options,
                                       const std::function<void(const CaptureFrame&)>& on_frame);

class CaptureReader {
 public:
  // Opens a regular file (open_input_file refuses FIFOs, devices and
  // directories, with its messages). Errors also for a framing without sizes.
  static Result<CaptureReader> open(const std::filesystem::path& path, const CaptureFraming& framing,
                                    CaptureReaderOptions options = {});
  // Reads bytes already in memory (which must outlive the reader) through the
  // same window, for tests and fuzzing.
  static Result<CaptureReader> from_memory(std::span<const std::uint8_t> bytes, const CaptureFraming& framing,
                                           CaptureReaderOptions options = {});

  // The next frame: true with `frame` set, false at the end of the file. An
  // error (a failed read, a file grown past max_bytes) names the file and the
  // byte offset; the reader is then spent.
  Result<bool> next(CaptureFrame& frame);

  const CaptureStats& stats() const noexcept { return stats_; }

 private:
  CaptureReader(const CaptureFraming& framing, CaptureReaderOptions options);
  static Result<CaptureReader> create(InputFile file, std::span<const std::uint8_t> memory, std::uint64_t size,
                                      std::string name, const CaptureFraming& framing,
                                      CaptureReaderOptions options);
  Status fill(std::uint64_t pos, std::size_t n);
  std::size_t resident(std::uint64_t pos) const noexcept;
  std::size_t size_at(std::uint64_t pos) const noexcept;
  bool intact_at(std::uint64_t pos) const noexcept;
  std::span<const std::uint8_t> window(std::uint64_t pos, std::size_t n) const noexcept;
  Error too_large(std::uint64_t size) const;

  CaptureFraming framing_;
  CaptureReaderOptions options_;
  std::size_t max_report_bytes_ = 0;
  InputFile file_;                          // the source: a file ...
  std::span<const std::uint8_t> memory_;    // ... or bytes in memory
  std::string name_;                        // "capture file 'x.bin'"
  std::vector<std::uint8_t> buffer_;        // holds file bytes [base_, base_ + length_)
  std::uint64_t base_ = 0;
  std::size_t length_ = 0;
  bool at_end_ = false;                     // end_ is known
  std::uint64_t end_ = 0;                   // the file's size, read to its end
  std::uint64_t read_high_ = 0;             // every byte below this has been read once
  std::uint64_t at_ = 0;                    // where the next report may start
  std::uint64_t next_intact_ = 0;           // the next offset where an intact report starts, once searched for
  bool failed_ = false;
  CaptureStats stats_;
};

}  // namespace proprio::hid
