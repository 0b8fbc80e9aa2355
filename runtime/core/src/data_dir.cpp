#include "proprio/core/data_dir.hpp"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <system_error>
#include <vector>

#include "proprio/core/log.hpp"

#ifndef PROPRIO_BUILD_DATA_DIR
#define PROPRIO_BUILD_DATA_DIR ""
#endif
// GNUInstallDirs' CMAKE_INSTALL_DATADIR, relative to the prefix (cmake/install.cmake).
#ifndef PROPRIO_INSTALL_DATADIR
#define PROPRIO_INSTALL_DATADIR "share"
#endif

namespace proprio {
namespace {

// The folder of the binary this code was linked into: the CLI, the OpenXR
// layer inside someone else's app, or a plugin. Not /proc/self/exe, which in a
// layer names the app.
std::filesystem::path own_binary_dir() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&own_binary_dir), &info) == 0 || info.dli_fname == nullptr) return {};
  std::error_code ec;
  const auto path = std::filesystem::canonical(info.dli_fname, ec);
  return ec ? std::filesystem::path() : path.parent_path();
}

bool is_dir(const std::filesystem::path& p) {
  std::error_code ec;
  return !p.empty() && std::filesystem::is_directory(p, ec);
}

}  // namespace

Result<std::filesystem::path> data_dir() {
  if (const char* env = std::getenv("PROPRIO_DATA_DIR"); env != nullptr && *env != '\0') {
    if (is_dir(env)) return std::filesystem::path(env);
    return make_error(Errc::not_found, std::string("PROPRIO_DATA_DIR is set to '") + env +
                                           "', which is not a folder; point it at a folder holding Proprio's data "
                                           "(the source tree's config/) or unset it");
  }
  std::vector<std::filesystem::path> candidates;
  // bin/, libexec/proprio/, lib/proprio/ and lib/<multiarch>/proprio/sources/
  // sit one to four levels below the prefix.
  for (auto dir = own_binary_dir(); candidates.size() < 4 && dir.has_parent_path() && dir != dir.parent_path();) {
    dir = dir.parent_path();
    candidates.push_back(dir / PROPRIO_INSTALL_DATADIR / "proprio");
  }
  if (std::string_view(PROPRIO_BUILD_DATA_DIR).size() > 0) candidates.emplace_back(PROPRIO_BUILD_DATA_DIR);
  std::string looked;
  for (const auto& c : candidates) {
    if (is_dir(c)) return c;
    looked += (looked.empty() ? "" : ", ") + c.string();
  }
  return make_error(Errc::not_found, "Proprio's data folder was not found (looked in " + looked +
                                         "); reinstall Proprio or set PROPRIO_DATA_DIR to its share/proprio folder");
}

std::string data_path(std::string_view relative) {
  auto dir = data_dir();
  if (dir) return (*dir / relative).string();
  // Say once why the file will be missing; then build the path on the user's
  // override if there is one (never silently on another folder), so the
  // loader's own message names where it looked.
  static std::once_flag said;
  std::call_once(said, [&] { logger().error("{}", dir.error().message); });
  const char* env = std::getenv("PROPRIO_DATA_DIR");
  const std::filesystem::path base =
      env != nullptr && *env != '\0' ? std::filesystem::path(env) : std::filesystem::path(PROPRIO_BUILD_DATA_DIR);
  return (base / relative).string();
}

std::filesystem::path installed_file(std::string_view relative_to_binary) {
  const auto dir = own_binary_dir();
  if (dir.empty() || relative_to_binary.empty()) return {};
  const auto path = (dir / relative_to_binary).lexically_normal();
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec) ? path : std::filesystem::path();
}

}  // namespace proprio
