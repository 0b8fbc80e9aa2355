// Loading hand-source plugins (input/hand_sources/plugin_loader.hpp): the
// real ones load and share the host's logger; a missing folder, a file that
// is not a shared object, a FIFO, a plugin of another ABI version or build,
// and a library without the entry point are clear errors, never a crash.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "proprio/core/log.hpp"
#include "proprio/hand_sources/hand_sources.hpp"
#include "proprio/hand_sources/plugin_loader.hpp"
#include "support/temp_dir.hpp"

using namespace proprio;
using namespace proprio::hand_sources;
using proprio::testing_support::TempDir;
namespace fs = std::filesystem;

namespace {

const std::string kFile = "libproprio_source_fake.so";

std::string message_of(const Result<const HandSourcePluginV1*>& r) {
  return r ? std::string("(loaded)") : r.error().message;
}

// A fake plugin built by tests/CMakeLists.txt, copied in under kFile.
fs::path install_fake(const TempDir& dir, const char* built) {
  fs::copy_file(built, dir / kFile, fs::copy_options::overwrite_existing);
  return dir.path();
}

TEST(HandSourcePlugins, TheRealPluginsLoadFromTheBuildTreeAndShareTheHostsLogger) {
  for (const char* family : {"vist", "stretch_glove"}) {
    auto p = load_plugin_from(plugin_file_name(family), default_plugin_dirs());
    ASSERT_TRUE(p) << message_of(p);
    EXPECT_STREQ((*p)->family, family);
    EXPECT_EQ((*p)->abi_version, kPluginAbiVersion);
    // One logger per process: a plugin's warnings follow the host's level.
    EXPECT_EQ((*p)->logger_address(), static_cast<const void*>(&logger())) << family;
  }
}

TEST(HandSourcePlugins, AMissingPluginNamesTheFileAndEveryFolderLookedIn) {
  TempDir dir;
  const auto a = dir.path() / "a", b = dir.path() / "b";
  auto p = load_plugin_from(kFile, {a, b});
  ASSERT_FALSE(p);
  EXPECT_EQ(p.error().code, Errc::not_found);
  EXPECT_NE(message_of(p).find(kFile + " was not found (looked in '" + a.string() + "', '" + b.string() + "')"),
            std::string::npos)
      << message_of(p);
  EXPECT_NE(message_of(p).find("PROPRIO_PLUGIN_DIR"), std::string::npos) << message_of(p);
}

TEST(HandSourcePlugins, AFileThatIsNotASharedObjectIsRefusedWithDlerror) {
  TempDir dir;
  dir.write(kFile, "this is not an ELF file\n");
  auto p = load_plugin_from(kFile, {dir.path()});
  ASSERT_FALSE(p);
  EXPECT_NE(message_of(p).find("cannot load hand-source plugin '" + (dir / kFile).string() + "': "), std::string::npos)
      << message_of(p);
  // dlerror()'s reason follows ("<file>: file too short" or "invalid ELF header").
  const std::string m = message_of(p);
  const auto first = m.find((dir / kFile).string());
  EXPECT_NE(m.find((dir / kFile).string(), first + 1), std::string::npos) << m;
}

TEST(HandSourcePlugins, AFifoOrAFolderInThePluginsPlaceIsRefusedWithoutBlocking) {
  TempDir dir;
  ASSERT_EQ(::mkfifo((dir / kFile).c_str(), 0600), 0);
  auto p = load_plugin_from(kFile, {dir.path()});
  ASSERT_FALSE(p);
  EXPECT_NE(message_of(p).find("is a FIFO (named pipe)"), std::string::npos) << message_of(p);
  fs::remove(dir / kFile);
  fs::create_directory(dir / kFile);
  p = load_plugin_from(kFile, {dir.path()});
  ASSERT_FALSE(p);
  EXPECT_NE(message_of(p).find("is a directory"), std::string::npos) << message_of(p);
}

TEST(HandSourcePlugins, APluginOfAnotherAbiVersionIsRefused) {
  TempDir dir;
  auto p = load_plugin_from(kFile, {install_fake(dir, PROPRIO_FAKE_PLUGIN_WRONG_ABI)});
  ASSERT_FALSE(p);
  EXPECT_EQ(p.error().code, Errc::unsupported);
  EXPECT_NE(message_of(p).find("speaks plugin ABI version 999, this Proprio version " + std::to_string(proprio::hand_sources::kPluginAbiVersion)), std::string::npos)
      << message_of(p);
}

TEST(HandSourcePlugins, APluginFromAnotherBuildIsRefused) {
  TempDir dir;
  auto p = load_plugin_from(kFile, {install_fake(dir, PROPRIO_FAKE_PLUGIN_WRONG_BUILD)});
  ASSERT_FALSE(p);
  EXPECT_NE(message_of(p).find("was built from other sources (build id not-this-build"), std::string::npos)
      << message_of(p);
}

TEST(HandSourcePlugins, ALibraryWithoutTheEntryPointIsRefused) {
  TempDir dir;
  auto p = load_plugin_from(kFile, {install_fake(dir, PROPRIO_FAKE_PLUGIN_NO_ENTRY)});
  ASSERT_FALSE(p);
  EXPECT_NE(message_of(p).find("does not export proprio_hand_source_plugin_v1"), std::string::npos) << message_of(p);
}

// PROPRIO_PLUGIN_DIR replaces the search; what it names must be a folder.
// (Families no test loads successfully, so nothing is cached.)
TEST(HandSourcePlugins, PluginDirOverrideIsTheOnlyPlaceAndMustBeAFolder) {
  TempDir dir;
  ::setenv("PROPRIO_PLUGIN_DIR", "/dev/zero", 1);
  auto p = load_plugin("fake");
  EXPECT_FALSE(p);
  EXPECT_NE(message_of(p).find("PROPRIO_PLUGIN_DIR is set to '/dev/zero', which is not a folder"), std::string::npos)
      << message_of(p);
  ::setenv("PROPRIO_PLUGIN_DIR", dir.path().c_str(), 1);
  p = load_plugin("fake");
  EXPECT_FALSE(p);
  EXPECT_NE(message_of(p).find("(looked in '" + dir.path().string() + "')"), std::string::npos) << message_of(p);
  // Through the factory: the source type is named first.
  openxr_layer::SourceConfig sc;
  sc.type = openxr_layer::SourceType::vist;
  sc.path = (dir / "session.prec").string();
  auto s = start_hand_source(sc, 0);
  ::unsetenv("PROPRIO_PLUGIN_DIR");
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("vist source: with PROPRIO_PLUGIN_DIR set: hand-source plugin "
                                   "libproprio_source_vist.so was not found"),
            std::string::npos)
      << s.error().message;
}

TEST(HandSourcePlugins, TheDefaultGloveModelIsTheShippedOne) {
  EXPECT_TRUE(fs::is_regular_file(default_glove_model_path())) << default_glove_model_path();
  EXPECT_EQ(fs::path(default_glove_model_path()).filename(), "stretch_glove_generic.onnx");
}

}  // namespace
