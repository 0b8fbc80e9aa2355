// proprio/core/data_dir.hpp: the data folder's lookup order and its errors.
// The installed lookup (<prefix>/share/proprio) is covered by
// tests/install/smoke_test.sh on a real installed tree.
#include "proprio/core/data_dir.hpp"

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <filesystem>
#include <optional>
#include <string>

namespace {

namespace fs = std::filesystem;

// Sets an environment variable for one test and restores it afterwards.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value) {
      setenv(name, value, 1);
    } else {
      unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (old_) {
      setenv(name_, old_->c_str(), 1);
    } else {
      unsetenv(name_);
    }
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
  std::optional<std::string> old_;
};

TEST(DataDir, TheOverrideWinsWhenItIsAFolder) {
  const fs::path dir = fs::temp_directory_path() / ("proprio_data_dir_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  {
    ScopedEnv env("PROPRIO_DATA_DIR", dir.c_str());
    auto found = proprio::data_dir();
    ASSERT_TRUE(found) << found.error().message;
    EXPECT_EQ(*found, dir);
    EXPECT_EQ(proprio::data_path("haptics/band_2dof.toml"), (dir / "haptics/band_2dof.toml").string());
  }
  fs::remove_all(dir);
}

TEST(DataDir, AnOverrideThatIsNoFolderIsAnErrorNotAFallback) {
  ScopedEnv env("PROPRIO_DATA_DIR", "/nonexistent/proprio-data");
  auto found = proprio::data_dir();
  ASSERT_FALSE(found);
  EXPECT_NE(found.error().message.find("PROPRIO_DATA_DIR"), std::string::npos) << found.error().message;
  EXPECT_NE(found.error().message.find("/nonexistent/proprio-data"), std::string::npos) << found.error().message;
}

TEST(DataDir, AnEmptyOverrideIsIgnored) {
  ScopedEnv env("PROPRIO_DATA_DIR", "");
  auto found = proprio::data_dir();
  ASSERT_TRUE(found) << found.error().message;
  // Run from the build tree: the source tree's config/, with the shipped data in it.
  EXPECT_TRUE(fs::is_regular_file(*found / "vist_glove.toml")) << *found;
  EXPECT_TRUE(fs::is_regular_file(proprio::data_path("haptics/platform_3dof.toml")));
}

TEST(DataDir, InstalledFileIsEmptyForWhatIsNotThere) {
  EXPECT_TRUE(proprio::installed_file("").empty());
  EXPECT_TRUE(proprio::installed_file("../lib/proprio/no_such_library.so").empty());
  // A folder is not a file.
  EXPECT_TRUE(proprio::installed_file(".").empty());
}

}  // namespace
