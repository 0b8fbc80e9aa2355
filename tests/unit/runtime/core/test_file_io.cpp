#include "proprio/core/file_io.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "support/temp_dir.hpp"

namespace proprio {
namespace file_io_test {

namespace fs = std::filesystem;

bool has(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

void write(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary);
  f << text;
}

TEST(InputFile, ReadsARegularFileWhole) {
  testing_support::TempDir dir;
  write(dir.path() / "a.txt", "hello\nworld");
  auto text = read_input_file(dir.path() / "a.txt", "test file");
  ASSERT_TRUE(text) << text.error().message;
  EXPECT_EQ(*text, "hello\nworld");
}

TEST(InputFile, RefusesAFifoWithoutBlocking) {
  testing_support::TempDir dir;
  const fs::path fifo = dir.path() / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // No writer ever opens it: a blocking open would hang this test forever.
  auto text = read_input_file(fifo, "config file");
  ASSERT_FALSE(text);
  EXPECT_EQ(text.error().code, Errc::invalid_argument);
  EXPECT_TRUE(has(text.error().message, "FIFO")) << text.error().message;
  EXPECT_TRUE(has(text.error().message, "config file")) << text.error().message;
}

TEST(InputFile, RefusesDevicesAndDirectoriesAndSaysWhich) {
  testing_support::TempDir dir;
  auto zero = read_input_file("/dev/zero", "recording");
  ASSERT_FALSE(zero);
  EXPECT_TRUE(has(zero.error().message, "character device")) << zero.error().message;
  auto folder = read_input_file(dir.path(), "recording");
  ASSERT_FALSE(folder);
  EXPECT_TRUE(has(folder.error().message, "is a directory")) << folder.error().message;
  auto missing = read_input_file(dir.path() / "nope", "recording");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
  EXPECT_TRUE(has(missing.error().message, "does not exist")) << missing.error().message;
}

TEST(InputFile, RefusesAFileAboveTheCapWithSizeAndLimit) {
  testing_support::TempDir dir;
  write(dir.path() / "big", std::string(5000, 'x'));
  auto text = read_input_file(dir.path() / "big", "design", 4096);
  ASSERT_FALSE(text);
  EXPECT_TRUE(has(text.error().message, "too large")) << text.error().message;
  EXPECT_TRUE(has(text.error().message, "limit")) << text.error().message;
  auto exact = read_input_file(dir.path() / "big", "design", 5000);
  ASSERT_TRUE(exact) << exact.error().message;
  EXPECT_EQ(exact->size(), 5000u);
}

TEST(OutputPath, RefusesAnInputThroughAnyName) {
  testing_support::TempDir dir;
  const fs::path in = dir.path() / "session.prec";
  write(in, "data");
  fs::create_symlink(in, dir.path() / "link.prec");
  fs::create_hard_link(in, dir.path() / "hard.prec");
  EXPECT_TRUE(check_output_path(in, "recording")) << "not read yet, so writable";
  ASSERT_TRUE(open_input_file(in, "recording"));
  for (const fs::path& p : {in, dir.path() / "link.prec", dir.path() / "hard.prec",
                            dir.path() / "." / "session.prec"}) {
    auto s = check_output_path(p, "recording");
    ASSERT_FALSE(s) << p;
    EXPECT_TRUE(has(s.error().message, "input")) << s.error().message;
  }
  auto w = write_file_atomic(dir.path() / "link.prec", "overwritten", "recording");
  EXPECT_FALSE(w);
  std::ifstream f(in);
  std::string still;
  std::getline(f, still);
  EXPECT_EQ(still, "data");
}

TEST(OutputPath, AtomicWriteReplacesAndRefusesNonRegularTargets) {
  testing_support::TempDir dir;
  const fs::path out = dir.path() / "out.toml";
  ASSERT_TRUE(write_file_atomic(out, "a = 1\n", "config"));
  auto again = write_file_atomic(out, "a = 2\n", "config", /*overwrite=*/false);
  ASSERT_FALSE(again);
  EXPECT_TRUE(has(again.error().message, "--force")) << again.error().message;
  ASSERT_TRUE(write_file_atomic(out, "a = 2\n", "config"));
  EXPECT_EQ(*read_input_file(out, "config"), "a = 2\n");
  auto folder = write_file_atomic(dir.path(), "x", "config");
  ASSERT_FALSE(folder);
  EXPECT_TRUE(has(folder.error().message, "directory")) << folder.error().message;
  for (const auto& e : fs::directory_iterator(dir.path())) {
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << "temporary file left: " << e.path();
  }
}

TEST(FolderLock, ASecondHolderIsRefusedUntilTheFirstLetsGo) {
  testing_support::TempDir dir;
  auto first = FolderLock::acquire(dir.path(), "session folder");
  ASSERT_TRUE(first) << first.error().message;
  // flock locks belong to open file descriptions: a second open in this
  // process conflicts just as another process would.
  auto second = FolderLock::acquire(dir.path(), "session folder");
  ASSERT_FALSE(second);
  EXPECT_EQ(second.error().code, Errc::unavailable);
  EXPECT_TRUE(has(second.error().message, "pid " + std::to_string(::getpid()))) << second.error().message;
  first = FolderLock();
  EXPECT_TRUE(FolderLock::acquire(dir.path(), "session folder"));
}

TEST(FolderLock, IsReleasedWhenTheHolderDies) {
  testing_support::TempDir dir;
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto lock = FolderLock::acquire(dir.path(), "session folder");
    ::_exit(lock ? 0 : 1);  // dies holding it, as a crashed study would
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  EXPECT_TRUE(FolderLock::acquire(dir.path(), "session folder"));
}

TEST(Printable, StripsControlCharactersAndCapsLength) {
  EXPECT_EQ(printable("a\x1b[2Jb\n"), "a?[2Jb?");
  EXPECT_EQ(printable(std::string(10, 'x'), 4), "xxxx...");
  EXPECT_EQ(printable("h\xc3\xa9llo"), "h\xc3\xa9llo");  // UTF-8 stays
}

}  // namespace file_io_test
}  // namespace proprio
