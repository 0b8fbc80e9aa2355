#pragma once
// Finding and loading hand-source plugins (plugin_abi.hpp).
//
// The rule: the plugin file libproprio_source_<family>.so is taken from the
// first of these folders that holds it.
//   1. $PROPRIO_PLUGIN_DIR, when set and not empty: the only folder looked in
//      (an override that silently fell back would hide a wrong path).
//   2. Relative to the folder of the binary this code is linked into (dladdr,
//      not /proc/self/exe, which in a layer names the app):
//        <dir>/sources                          the layer, installed in <libdir>/proprio/
//        <dir>/../<libdir>/proprio/sources      the CLI, installed in bin/
//        <dir>/../lib/proprio/sources           the same, whatever libdir was configured,
//        <dir>/../lib/<multiarch>/proprio/sources   with and without Debian's multiarch folder
//   3. The build tree's plugin folder, for binaries run where they were built.
// A file that is there but is not a loadable plugin of this build is an
// error, not a reason to look further.
//
// Loaded plugins stay loaded for the life of the process (never dlclose'd):
// a source's code and vtable live in its plugin, and sources may be held by
// objects whose lifetime the loader cannot see (an app's XrInstance, a
// shared_ptr in the CLI). Unloading would save one mapping per family.
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/hand_sources/plugin_abi.hpp"

namespace proprio::hand_sources {

// "libproprio_source_<family>.so"
std::string plugin_file_name(std::string_view family);

// The folders of step 2 and 3 above, in order (not checked for existence).
std::vector<std::filesystem::path> default_plugin_dirs();

// Loads `file_name` from the first of `dirs` holding it (dlopen with
// RTLD_NOW | RTLD_LOCAL) and checks its table. Errors name the file, every
// folder looked in and dlerror().
Result<const HandSourcePluginV1*> load_plugin_from(const std::string& file_name,
                                                   const std::vector<std::filesystem::path>& dirs);

// The plugin for `family` by the rule above; once loaded, later calls return
// the same table.
Result<const HandSourcePluginV1*> load_plugin(std::string_view family);

}  // namespace proprio::hand_sources
