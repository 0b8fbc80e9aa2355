#include "proprio/core/file_io.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <mutex>
#include <map>
#include <utility>

namespace proprio {
namespace {

std::string quoted(const std::filesystem::path& p) { return "'" + printable(p.string(), 300) + "'"; }

const char* kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

std::string mib(std::uint64_t bytes) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f MiB", static_cast<double>(bytes) / static_cast<double>(kMiB));
  return buf;
}

// Inputs of this process by (device, inode), with the inode's change time
// when it was opened: a file deleted later may hand its inode number to a new
// file, which must not inherit the protection (its change time differs).
// Never shrinks: a file read once stays protected for the process's life.
struct InputRegistry {
  std::mutex mutex;
  std::map<std::pair<dev_t, ino_t>, std::pair<time_t, long>> files;
};
InputRegistry& registry() {
  static InputRegistry r;
  return r;
}
void remember(const struct stat& st) {
  std::lock_guard lock(registry().mutex);
  registry().files[{st.st_dev, st.st_ino}] = {st.st_ctim.tv_sec, st.st_ctim.tv_nsec};
}
bool is_input(const struct stat& st) {
  std::lock_guard lock(registry().mutex);
  const auto it = registry().files.find({st.st_dev, st.st_ino});
  return it != registry().files.end() && it->second == std::make_pair(st.st_ctim.tv_sec, st.st_ctim.tv_nsec);
}

void close_fd(int& fd) {
  if (fd >= 0) ::close(fd);
  fd = -1;
}

}  // namespace

InputFile::InputFile(InputFile&& other) noexcept : fd_(std::exchange(other.fd_, -1)), size_(other.size_) {}
InputFile& InputFile::operator=(InputFile&& other) noexcept {
  if (this != &other) {
    close_fd(fd_);
    fd_ = std::exchange(other.fd_, -1);
    size_ = other.size_;
  }
  return *this;
}
InputFile::~InputFile() { close_fd(fd_); }
int InputFile::release() noexcept { return std::exchange(fd_, -1); }

Result<InputFile> open_input_file(const std::filesystem::path& path, std::string_view what) {
  const std::string w(what);
  if (path.empty()) return make_error(Errc::invalid_argument, "no " + w + " given (the path is empty)");
  // O_NONBLOCK: opening a FIFO without a writer would otherwise wait forever.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd < 0) {
    const int err = errno;
    if (err == ENOENT) return make_error(Errc::not_found, w + " " + quoted(path) + " does not exist; check the path");
    return make_error(Errc::io_error, "cannot open " + w + " " + quoted(path) + ": " + std::strerror(err));
  }
  InputFile f;
  f.fd_ = fd;
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    return make_error(Errc::io_error, "cannot inspect " + w + " " + quoted(path) + ": " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) {
    return make_error(Errc::invalid_argument,
                      w + " " + quoted(path) + " is " + kind_of(st.st_mode) + "; pass a regular file");
  }
  // Regular files never block; clear O_NONBLOCK so reads behave normally.
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0) ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
  f.size_ = static_cast<std::uint64_t>(st.st_size);
  remember(st);
  return f;
}

Result<std::string> read_input_file(const std::filesystem::path& path, std::string_view what,
                                    std::uint64_t max_bytes) {
  auto f = open_input_file(path, what);
  if (!f) return f.error();
  const std::string w(what);
  auto too_large = [&](std::uint64_t size) {
    return make_error(Errc::invalid_argument, w + " " + quoted(path) + " is too large (" + mib(size) +
                                                  "; the limit for a " + w + " is " + mib(max_bytes) + ")");
  };
  if (f->size() > max_bytes) return too_large(f->size());
  std::string text;
  text.resize(static_cast<std::size_t>(f->size()));
  std::size_t got = 0;
  // Read to EOF rather than to the stat size (the file may change), bounded.
  for (;;) {
    if (got == text.size()) {
      if (text.size() >= max_bytes) {
        // One more byte tells a file that grew past the cap from one that ends here.
        char probe;
        const ssize_t n = ::read(f->fd(), &probe, 1);
        if (n > 0) return too_large(max_bytes + 1);
        break;
      }
      text.resize(std::min<std::uint64_t>(max_bytes, std::max<std::size_t>(4096, text.size() * 2)));
    }
    const ssize_t n = ::read(f->fd(), text.data() + got, text.size() - got);
    if (n < 0) {
      if (errno == EINTR) continue;
      return make_error(Errc::io_error, "cannot read " + w + " " + quoted(path) + ": " + std::strerror(errno));
    }
    if (n == 0) break;
    got += static_cast<std::size_t>(n);
  }
  text.resize(got);
  return text;
}

void forget_input_file(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;
  std::lock_guard lock(registry().mutex);
  registry().files.erase({st.st_dev, st.st_ino});
}

Status check_output_path(const std::filesystem::path& path, std::string_view what) {
  const std::string w(what);
  if (path.empty()) return make_error(Errc::invalid_argument, "no " + w + " path given (the path is empty)");
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return Status::success();  // a new file
  if (is_input(st)) {
    return make_error(Errc::invalid_argument, "refusing to write the " + w + " to " + quoted(path) +
                                                  ": that file is an input of this command; choose another path");
  }
  // Streams may go to /dev/null or a FIFO a reader holds open; a folder or a
  // socket is a mistake.
  if (S_ISDIR(st.st_mode) || S_ISSOCK(st.st_mode)) {
    return make_error(Errc::invalid_argument,
                      "cannot write the " + w + " to " + quoted(path) + ": it is " + kind_of(st.st_mode));
  }
  return Status::success();
}

Status write_file_atomic(const std::filesystem::path& path, std::string_view contents, std::string_view what,
                         bool overwrite) {
  const std::string w(what);
  if (auto s = check_output_path(path, what); !s) return s;
  struct stat st {};
  // The rename would replace the node itself: never a device or a FIFO.
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    return make_error(Errc::invalid_argument,
                      "cannot write the " + w + " to " + quoted(path) + ": it is " + kind_of(st.st_mode));
  }
  if (!overwrite && ::lstat(path.c_str(), &st) == 0) {
    return make_error(Errc::invalid_argument, w + " " + quoted(path) + " already exists; pass --force to replace it");
  }
  std::filesystem::path dir = path.parent_path();
  if (dir.empty()) dir = ".";
  std::filesystem::path tmp = path;
  tmp += ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    return make_error(Errc::io_error, "cannot create the " + w + " " + quoted(path) + ": " + std::strerror(errno));
  }
  auto fail = [&](const char* step) {
    const int err = errno;
    ::close(fd);
    ::unlink(tmp.c_str());
    return make_error(Errc::io_error,
                      "cannot " + std::string(step) + " the " + w + " " + quoted(path) + ": " + std::strerror(err));
  };
  std::size_t done = 0;
  while (done < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + done, contents.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return fail("write");
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0) return fail("flush");
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return make_error(Errc::io_error, "cannot write the " + w + " " + quoted(path) + ": " + std::strerror(err));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return make_error(Errc::io_error, "cannot replace " + quoted(path) + " with the new " + w + ": " +
                                          std::strerror(err));
  }
  // The rename is durable only once the folder's entry is on disk.
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return Status::success();
}

FolderLock::FolderLock(FolderLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
FolderLock& FolderLock::operator=(FolderLock&& other) noexcept {
  if (this != &other) {
    close_fd(fd_);
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}
FolderLock::~FolderLock() { close_fd(fd_); }

Result<FolderLock> FolderLock::acquire(const std::filesystem::path& folder, std::string_view what) {
  const std::filesystem::path file = folder / kFileName;
  const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (fd < 0) {
    return make_error(Errc::io_error, "cannot lock the " + std::string(what) + " " + quoted(folder) + " (" +
                                          quoted(file) + "): " + std::strerror(errno));
  }
  FolderLock lock;
  lock.fd_ = fd;
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    if (err != EWOULDBLOCK) {
      return make_error(Errc::io_error, "cannot lock the " + std::string(what) + " " + quoted(folder) + ": " +
                                            std::strerror(err));
    }
    char buf[32] = {};
    const ssize_t n = ::pread(fd, buf, sizeof buf - 1, 0);
    std::string owner = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string();
    while (!owner.empty() && (owner.back() == '\n' || owner.back() == ' ')) owner.pop_back();
    return make_error(Errc::unavailable,
                      "the " + std::string(what) + " " + quoted(folder) + " is in use by another process" +
                          (owner.empty() ? std::string() : " (pid " + printable(owner, 20) + ")") +
                          "; wait for it to finish, or choose another --out");
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd, 0) == 0) {
    [[maybe_unused]] const ssize_t n = ::pwrite(fd, pid.data(), pid.size(), 0);
  }
  return lock;
}

std::string printable(std::string_view text, std::size_t max_chars) {
  std::string out;
  out.reserve(std::min(text.size(), max_chars) + 3);
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (out.size() >= max_chars) {
      out += "...";
      break;
    }
    const auto c = static_cast<unsigned char>(text[i]);
    out += (c < 0x20 || c == 0x7f) ? '?' : static_cast<char>(c);
  }
  return out;
}

}  // namespace proprio
