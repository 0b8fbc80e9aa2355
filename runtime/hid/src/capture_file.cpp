#include "proprio/hid/capture_file.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <utility>

#include "proprio/hid/crc16.hpp"

namespace proprio::hid {

namespace {

std::string mib(std::uint64_t bytes) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f MiB", static_cast<double>(bytes) / static_cast<double>(kMiB));
  return buf;
}

}  // namespace

bool capture_frame_intact(const CaptureFraming& framing, std::span<const std::uint8_t> frame) noexcept {
  if (frame.empty() || framing.report_size_for_id == nullptr) return false;
  const std::size_t size = framing.report_size_for_id(frame[0]);
  if (size < 3 || frame.size() != size) return false;
  return crc16_ccitt(frame.first(size - 2)) == static_cast<std::uint16_t>(frame[size - 2] | frame[size - 1] << 8);
}

CaptureReader::CaptureReader(const CaptureFraming& framing, CaptureReaderOptions options)
    : framing_(framing), options_(std::move(options)) {}

Result<CaptureReader> CaptureReader::open(const std::filesystem::path& path, const CaptureFraming& framing,
                                          CaptureReaderOptions options) {
  auto file = open_input_file(path, options.what);
  if (!file) return file.error();
  const std::uint64_t size = file->size();
  std::string name = options.what + " '" + printable(path.string(), 300) + "'";
  return create(std::move(*file), {}, size, std::move(name), framing, std::move(options));
}

Result<CaptureReader> CaptureReader::from_memory(std::span<const std::uint8_t> bytes, const CaptureFraming& framing,
                                                 CaptureReaderOptions options) {
  std::string name = options.what + " in memory";
  return create(InputFile{}, bytes, bytes.size(), std::move(name), framing, std::move(options));
}

Result<CaptureReader> CaptureReader::create(InputFile file, std::span<const std::uint8_t> memory, std::uint64_t size,
                                            std::string name, const CaptureFraming& framing,
                                            CaptureReaderOptions options) {
  CaptureReader r(framing, std::move(options));
  r.file_ = std::move(file);
  r.memory_ = memory;
  r.name_ = std::move(name);
  if (framing.report_size_for_id == nullptr) {
    return make_error(Errc::invalid_argument, "reading " + r.name_ + ": the protocol's framing gives no report sizes");
  }
  for (unsigned id = 0; id < 256; ++id) {
    const std::size_t s = framing.report_size_for_id(static_cast<std::uint8_t>(id));
    if (s == 1 || s == 2) {
      return make_error(Errc::invalid_argument, "reading " + r.name_ + ": the protocol's framing gives report ID " +
                                                    std::to_string(id) + " " + std::to_string(s) +
                                                    " byte(s), too few for the ID and a 2-byte CRC");
    }
    r.max_report_bytes_ = std::max(r.max_report_bytes_, s);
  }
  if (r.max_report_bytes_ == 0) {
    return make_error(Errc::invalid_argument, "reading " + r.name_ + ": the protocol's framing defines no report ID");
  }
  if (r.options_.max_bytes != 0 && size > r.options_.max_bytes) return r.too_large(size);
  r.buffer_.resize(std::max(r.options_.window_bytes, 2 * r.max_report_bytes_));
  return r;
}

Error CaptureReader::too_large(std::uint64_t size) const {
  return make_error(Errc::invalid_argument, name_ + " is too large (" + mib(size) + "; the limit for a " +
                                                options_.what + " is " + mib(options_.max_bytes) + ")");
}

std::size_t CaptureReader::resident(std::uint64_t pos) const noexcept {
  return pos >= base_ && pos <= base_ + length_ ? static_cast<std::size_t>(base_ + length_ - pos) : 0;
}

std::span<const std::uint8_t> CaptureReader::window(std::uint64_t pos, std::size_t n) const noexcept {
  return std::span<const std::uint8_t>(buffer_).subspan(static_cast<std::size_t>(pos - base_), n);
}

// Only for a resident byte.
std::size_t CaptureReader::size_at(std::uint64_t pos) const noexcept {
  return framing_.report_size_for_id(buffer_[static_cast<std::size_t>(pos - base_)]);
}

// Whether an intact report starts at `pos`; its bytes must be resident as far
// as the file has them (fill(pos, max_report_bytes_) first).
bool CaptureReader::intact_at(std::uint64_t pos) const noexcept {
  const std::size_t have = resident(pos);
  if (have == 0) return false;
  const std::size_t size = size_at(pos);
  return size != 0 && size <= have && capture_frame_intact(framing_, window(pos, size));
}

// Makes file bytes [pos, pos + n) resident, or as many of them as the file
// holds (n never exceeds the window).
Status CaptureReader::fill(std::uint64_t pos, std::size_t n) {
  if (pos < base_ || pos > base_ + length_) {
    base_ = pos;
    length_ = 0;
  }
  const std::uint64_t want = pos + n;
  if (want <= base_ + length_) return {};
  if (want - base_ > buffer_.size()) {
    // Slide. Keep the current report when it fits: the resynchronising search
    // comes back to it when the damaged stretch is whole reports.
    const std::uint64_t keep = at_ >= base_ && at_ <= pos && want - at_ <= buffer_.size() ? at_ : pos;
    const auto drop = static_cast<std::size_t>(keep - base_);
    std::memmove(buffer_.data(), buffer_.data() + drop, length_ - drop);
    length_ -= drop;
    base_ = keep;
  }
  while (base_ + length_ < want) {
    const std::uint64_t from = base_ + length_;
    if (at_end_ && from >= end_) break;
    std::size_t room = buffer_.size() - length_;
    if (at_end_) room = static_cast<std::size_t>(std::min<std::uint64_t>(room, end_ - from));
    // One byte past the limit tells a file that grew past it from one that ends there.
    if (options_.max_bytes != 0) {
      room = static_cast<std::size_t>(std::min<std::uint64_t>(room, options_.max_bytes + 1 - from));
    }
    std::size_t got = 0;
    if (file_.fd() >= 0) {
      const ssize_t r = ::pread(file_.fd(), buffer_.data() + length_, room, static_cast<off_t>(from));
      if (r < 0) {
        if (errno == EINTR) continue;
        return make_error(Errc::io_error,
                          "cannot read " + name_ + " at byte " + std::to_string(from) + ": " + std::strerror(errno));
      }
      got = static_cast<std::size_t>(r);
    } else if (from < memory_.size()) {
      got = std::min<std::size_t>(room, memory_.size() - static_cast<std::size_t>(from));
      std::memcpy(buffer_.data() + length_, memory_.data() + from, got);
    }
    if (got == 0) {
      // The end, once and for all: bytes appended later are not read.
      at_end_ = true;
      end_ = from;
      break;
    }
    if (from < read_high_) stats_.reread_bytes += std::min<std::uint64_t>(got, read_high_ - from);
    length_ += got;
    read_high_ = std::max(read_high_, base_ + length_);
    if (options_.max_bytes != 0 && base_ + length_ > options_.max_bytes) return too_large(options_.max_bytes + 1);
  }
  return {};
}

Result<bool> CaptureReader::next(CaptureFrame& frame) {
  if (failed_) {
    return make_error(Errc::io_error, "reading " + name_ + ": the reader stopped at byte " + std::to_string(at_) +
                                          " after an error; open the file again");
  }
  const auto fail = [this](const Error& e) -> Result<bool> {
    failed_ = true;
    return e;
  };
  for (;;) {
    // This report and the next one.
    if (auto s = fill(at_, 2 * max_report_bytes_); !s) return fail(s.error());
    const std::size_t have = resident(at_);
    if (have == 0) return false;
    std::size_t size = size_at(at_);
    if (size == 0) {
      // A run of bytes that are no ID, skipped at once (the common garbage).
      std::size_t run = 1;
      while (run < have && size_at(at_ + run) == 0) ++run;
      stats_.skipped_bytes += run;
      stats_.bytes_consumed = at_ += run;
      continue;
    }
    size = std::min(size, have);  // less only at the end of the file
    const bool intact = intact_at(at_);
    if (!intact && have > size && !intact_at(at_ + size)) {
      // Neither this report nor the next is intact: framing may be lost. Find
      // where the next intact report starts (once per damaged stretch).
      if (next_intact_ <= at_) {
        std::uint64_t p = at_ + 1;
        for (;; ++p) {
          if (auto s = fill(p, max_report_bytes_); !s) return fail(s.error());
          if (resident(p) == 0 || intact_at(p)) break;
        }
        next_intact_ = p;
      }
      if ((next_intact_ - at_) % size != 0) {
        stats_.skipped_bytes += next_intact_ - at_;  // torn or shifted: not whole reports
        stats_.bytes_consumed = at_ = next_intact_;
        continue;
      }
      // Whole reports, just damaged: yield them, so that they count as undecodable.
      if (auto s = fill(at_, size); !s) return fail(s.error());
    }
    frame.bytes = window(at_, size);
    frame.offset = at_;
    frame.intact = intact;
    ++stats_.frames;
    if (!intact) ++stats_.damaged_frames;
    stats_.bytes_consumed = at_ += size;
    return true;
  }
}

Result<CaptureStats> read_capture_file(const std::filesystem::path& path, const CaptureFraming& framing,
                                       const CaptureReaderOptions& options,
                                       const std::function<void(const CaptureFrame&)>& on_frame) {
  auto reader = CaptureReader::open(path, framing, options);
  if (!reader) return reader.error();
  CaptureFrame frame;
  for (;;) {
    auto more = reader->next(frame);
    if (!more) return more.error();
    if (!*more) return reader->stats();
    on_frame(frame);
  }
}

}  // namespace proprio::hid
