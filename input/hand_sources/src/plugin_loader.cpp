#include "proprio/hand_sources/plugin_loader.hpp"

#include <dlfcn.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <system_error>

#include "proprio/core/file_io.hpp"
#include "proprio/core/log.hpp"

// The plugins' folder in this build tree (input/hand_sources/CMakeLists.txt).
#ifndef PROPRIO_PLUGIN_BUILD_DIR
#define PROPRIO_PLUGIN_BUILD_DIR ""
#endif
// GNUInstallDirs' CMAKE_INSTALL_LIBDIR relative to the prefix ("lib" or "lib/<multiarch>").
#ifndef PROPRIO_INSTALL_LIBDIR
#define PROPRIO_INSTALL_LIBDIR "lib"
#endif
// Debian's multiarch triplet (x86_64-linux-gnu), for a CLI in bin/ whatever libdir this build was configured with.
#ifndef PROPRIO_LIBRARY_ARCHITECTURE
#define PROPRIO_LIBRARY_ARCHITECTURE ""
#endif
#ifndef PROPRIO_HAND_SOURCE_BUILD_ID
#error "PROPRIO_HAND_SOURCE_BUILD_ID must be defined (input/hand_sources/CMakeLists.txt)"
#endif

namespace proprio::hand_sources {
namespace {

namespace fs = std::filesystem;

fs::path own_binary_dir() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&own_binary_dir), &info) == 0 || info.dli_fname == nullptr) return {};
  std::error_code ec;
  const auto path = fs::canonical(info.dli_fname, ec);
  return ec ? fs::path() : path.parent_path();
}

std::string quoted(const fs::path& p) { return "'" + printable(p.string(), 300) + "'"; }

std::string list(const std::vector<fs::path>& dirs) {
  std::string s;
  for (const auto& d : dirs) s += (s.empty() ? "" : ", ") + quoted(d);
  return s.empty() ? "(nowhere: no folder to look in)" : s;
}

Result<const HandSourcePluginV1*> check_table(const HandSourcePluginV1* t, const fs::path& file) {
  const std::string where = "hand-source plugin " + quoted(file);
  const std::string fix = "; reinstall Proprio so the plugin and the layer/CLI come from the same build, or point "
                          "PROPRIO_PLUGIN_DIR at the plugins built with this one";
  if (t == nullptr) return make_error(Errc::unsupported, where + " returned no table" + fix);
  // struct_size and abi_version sit first in every version of the table.
  if (t->abi_version != kPluginAbiVersion) {
    return make_error(Errc::unsupported, where + " speaks plugin ABI version " + std::to_string(t->abi_version) +
                                             ", this Proprio version " + std::to_string(kPluginAbiVersion) + fix);
  }
  if (t->struct_size < sizeof(HandSourcePluginV1)) {
    return make_error(Errc::unsupported, where + " has a table of " + std::to_string(t->struct_size) +
                                             " bytes, expected " + std::to_string(sizeof(HandSourcePluginV1)) + fix);
  }
  if (t->build_id == nullptr || std::strcmp(t->build_id, PROPRIO_HAND_SOURCE_BUILD_ID) != 0) {
    return make_error(Errc::unsupported, where + " was built from other sources (build id " +
                                             printable(t->build_id ? t->build_id : "(none)", 80) + ", this one " +
                                             PROPRIO_HAND_SOURCE_BUILD_ID + ")" + fix);
  }
  if (t->start == nullptr || t->logger_address == nullptr) {
    return make_error(Errc::unsupported, where + " has an incomplete table" + fix);
  }
  // proprio::core is linked statically into the host and into the plugin, so
  // each has its own logger(); both find the one "proprio" logger in spdlog's
  // registry, which lives in the shared libspdlog (one per process). If that
  // ever breaks, the plugin's warnings would go elsewhere: say so.
  if (t->logger_address() != static_cast<const void*>(&logger())) {
    logger().warn("Proprio: {} logs through a logger of its own; its messages may not follow this process's log level",
                  where);
  }
  return t;
}

}  // namespace

std::string plugin_file_name(std::string_view family) {
  return "libproprio_source_" + std::string(family) + ".so";
}

std::vector<fs::path> default_plugin_dirs() {
  std::vector<fs::path> dirs;
  auto add = [&](const fs::path& d) {
    const fs::path n = d.lexically_normal();
    for (const auto& e : dirs) {
      if (e == n) return;
    }
    dirs.push_back(n);
  };
  if (const fs::path own = own_binary_dir(); !own.empty()) {
    add(own / "sources");
    if (const fs::path libdir = PROPRIO_INSTALL_LIBDIR; libdir.is_relative()) {
      add(own / ".." / libdir / "proprio" / "sources");
    }
    add(own / ".." / "lib" / "proprio" / "sources");
    if (std::string_view(PROPRIO_LIBRARY_ARCHITECTURE).size() > 0) {
      add(own / ".." / "lib" / PROPRIO_LIBRARY_ARCHITECTURE / "proprio" / "sources");
    }
  }
  if (std::string_view(PROPRIO_PLUGIN_BUILD_DIR).size() > 0) add(PROPRIO_PLUGIN_BUILD_DIR);
  return dirs;
}

Result<const HandSourcePluginV1*> load_plugin_from(const std::string& file_name, const std::vector<fs::path>& dirs) {
  for (const auto& dir : dirs) {
    const fs::path file = dir / file_name;
    if (::access(file.c_str(), F_OK) != 0 && (errno == ENOENT || errno == ENOTDIR)) continue;
    // Regular files only: dlopen would block on a FIFO and read a device
    // forever. open_input_file opens without blocking and says what it is.
    if (auto f = open_input_file(file, "hand-source plugin"); !f) return f.error();
    // RTLD_LOCAL: the plugin's copies of Proprio's static libraries stay its
    // own; RTLD_NOW: a missing symbol fails here, not in the middle of a frame.
    void* handle = ::dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* err = ::dlerror();
      return make_error(Errc::unsupported, "cannot load hand-source plugin " + quoted(file) + ": " +
                                               printable(err ? err : "unknown dlopen error", 500));
    }
    ::dlerror();
    void* sym = ::dlsym(handle, kPluginEntryPoint);
    if (sym == nullptr) {
      const char* err = ::dlerror();
      return make_error(Errc::unsupported, "hand-source plugin " + quoted(file) + " does not export " +
                                               kPluginEntryPoint + " (" + printable(err ? err : "", 300) +
                                               "); it is not a Proprio plugin of this version");
    }
    // Never dlclose'd (plugin_loader.hpp); a refused plugin stays mapped too,
    // since its static constructors already ran and may have started state.
    return check_table(reinterpret_cast<PluginEntryPointV1>(sym)(), file);
  }
  return make_error(Errc::not_found, "hand-source plugin " + file_name + " was not found (looked in " + list(dirs) +
                                         "); reinstall Proprio, or set PROPRIO_PLUGIN_DIR to the folder holding it");
}

Result<const HandSourcePluginV1*> load_plugin(std::string_view family) {
  static std::mutex mutex;
  static std::map<std::string, const HandSourcePluginV1*, std::less<>> loaded;
  // The host's logger exists before any plugin's code runs (check_table).
  (void)logger();
  std::lock_guard lock(mutex);
  if (auto it = loaded.find(family); it != loaded.end()) return it->second;
  const std::string file = plugin_file_name(family);
  Result<const HandSourcePluginV1*> plugin = make_error(Errc::not_found, "");
  if (const char* env = std::getenv("PROPRIO_PLUGIN_DIR"); env != nullptr && *env != '\0') {
    struct stat st {};
    if (::stat(env, &st) != 0 || !S_ISDIR(st.st_mode)) {
      return make_error(Errc::not_found, "PROPRIO_PLUGIN_DIR is set to " + quoted(env) +
                                             ", which is not a folder, so hand-source plugin " + file +
                                             " cannot be loaded; point it at the folder holding Proprio's source "
                                             "plugins or unset it");
    }
    plugin = load_plugin_from(file, {fs::path(env)});
    if (!plugin) return plugin.error().with_context("with PROPRIO_PLUGIN_DIR set");
  } else {
    plugin = load_plugin_from(file, default_plugin_dirs());
    if (!plugin) return plugin.error();
  }
  if (std::strcmp((*plugin)->family ? (*plugin)->family : "", std::string(family).c_str()) != 0) {
    return make_error(Errc::unsupported, "hand-source plugin " + file + " says it serves '" +
                                             printable((*plugin)->family ? (*plugin)->family : "", 80) +
                                             "', not '" + std::string(family) + "'; reinstall Proprio");
  }
  loaded.emplace(std::string(family), *plugin);
  return plugin;
}

}  // namespace proprio::hand_sources
