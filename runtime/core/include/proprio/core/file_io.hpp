#pragma once
// The one way Proprio opens an input file and creates an output file.
//
// Inputs: only regular files are read. A FIFO, a character device (/dev/zero)
// or a directory is refused with a message before a byte is read, and without
// blocking (the open is non-blocking, so a FIFO with no writer cannot hang an
// app that loads our OpenXR layer). Whole-file reads are capped.
//
// Outputs: nothing this process has opened as an input may be written over,
// whatever path names it (a symlink, "./x", a hard link): every input opened
// here is remembered by device and inode, and every output is checked against
// them. Whole files are written atomically (temporary file, fsync, rename).
//
// Study folders: FolderLock keeps a second process off a folder being written.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "proprio/core/result.hpp"

namespace proprio {

inline constexpr std::uint64_t kMiB = 1024ull * 1024ull;
// Default cap of a whole-file read: configs, designs, CSVs and models are far
// smaller; a larger file is a mistake or an attack, not data.
inline constexpr std::uint64_t kDefaultMaxInputBytes = 64 * kMiB;

// An open, read-only, regular input file (blocking reads; O_CLOEXEC).
class InputFile {
 public:
  InputFile() = default;
  InputFile(InputFile&& other) noexcept;
  InputFile& operator=(InputFile&& other) noexcept;
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;
  ~InputFile();

  int fd() const noexcept { return fd_; }
  // Size when opened (a recording being written may grow after that).
  std::uint64_t size() const noexcept { return size_; }
  // Hands the descriptor over (to fdopen, say); the caller closes it.
  int release() noexcept;

 private:
  friend Result<InputFile> open_input_file(const std::filesystem::path&, std::string_view);
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

// Opens `path` for reading if it is an existing regular file; `what` names it
// in messages ("config file", "recording"). Errors: not_found, invalid_argument
// (a directory, FIFO, device or socket), io_error (permissions, ...).
Result<InputFile> open_input_file(const std::filesystem::path& path, std::string_view what);

// The whole file, refused above `max_bytes` (with the size and the limit).
Result<std::string> read_input_file(const std::filesystem::path& path, std::string_view what,
                                    std::uint64_t max_bytes = kDefaultMaxInputBytes);

// For a file this process owns and updates in place (a study session's
// sidecar, read on resume and rewritten after each trial): it stops counting
// as an input, so write_file_atomic may replace it.
void forget_input_file(const std::filesystem::path& path);

// Refuses an output path that names a file this process reads, a directory or
// a socket. Streams may go to a device (/dev/null) or a FIFO.
Status check_output_path(const std::filesystem::path& path, std::string_view what);

// Writes `contents` to `path` atomically: a temporary file in the same folder,
// fsync, rename over `path`, fsync of the folder. Refuses what
// check_output_path refuses and any existing target that is not a regular
// file; with overwrite = false, also an existing file.
Status write_file_atomic(const std::filesystem::path& path, std::string_view contents, std::string_view what,
                         bool overwrite = true);

// An exclusive, advisory lock on a folder (flock on `<folder>/.lock`, which
// holds the owner's pid), released when the object dies, including when the
// process crashes. A second holder gets a message naming the first one's pid.
class FolderLock {
 public:
  static Result<FolderLock> acquire(const std::filesystem::path& folder, std::string_view what);

  FolderLock() = default;
  FolderLock(FolderLock&& other) noexcept;
  FolderLock& operator=(FolderLock&& other) noexcept;
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;
  ~FolderLock();

  bool held() const noexcept { return fd_ >= 0; }
  static constexpr const char* kFileName = ".lock";

 private:
  int fd_ = -1;
};

// Text safe to print on a terminal: control characters (ANSI escapes from a
// hostile file) become '?', and anything past max_chars is cut with "...".
std::string printable(std::string_view text, std::size_t max_chars = 200);

}  // namespace proprio
