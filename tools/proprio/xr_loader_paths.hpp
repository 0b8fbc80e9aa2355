#pragma once
// Where the OpenXR loader looks for API layer manifests and the active runtime
// on Linux, reproduced from the loader (checked against Debian's 1.0.20 loader
// with strace and XR_LOADER_DEBUG=all; see docs/openxr-layer.md):
//
//   layer manifests, each base + /openxr/1/api_layers/{explicit,implicit}.d:
//     $XDG_CONFIG_DIRS (default /etc/xdg), /etc, $XDG_DATA_DIRS (default
//     /usr/local/share:/usr/share), $XDG_DATA_HOME (default ~/.local/share).
//     XR_API_LAYER_PATH, when set, replaces this whole list for explicit
//     layers (its entries are used as they are); implicit layers ignore it.
//   active runtime: XR_RUNTIME_JSON, else the first openxr/1/active_runtime.json in
//     $XDG_CONFIG_HOME (default ~/.config), $XDG_CONFIG_DIRS (default /etc/xdg), /etc
//
// Note that the loader never reads layer manifests from $XDG_CONFIG_HOME.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace proprio::cli::xr {

inline constexpr const char* kLayerName = "XR_APILAYER_PROPRIO_hand_tracking";
inline constexpr const char* kLayerDisableEnv = "DISABLE_XR_APILAYER_PROPRIO_HAND_TRACKING";
inline constexpr const char* kLayerManifestFile = "XrApiLayer_proprio_hand_tracking.json";

enum class LayerKind { explicit_layer, implicit_layer };
enum class Scope { user, system };

const char* to_string(LayerKind k) noexcept;  // "explicit" / "implicit"

// The variable's value, or "" when it is unset.
std::string env(const char* name);
std::vector<std::string> split_list(std::string_view colon_separated);

struct SearchDir {
  std::filesystem::path dir;  // a directory of manifests (or, from XR_API_LAYER_PATH, possibly one file)
  std::string origin;         // which variable or default it came from
};
// In the loader's order.
std::vector<SearchDir> layer_search_dirs(LayerKind kind);

// Where `proprio layer install` writes: user = $XDG_DATA_HOME (or ~/.local/share),
// system = /etc (always searched, whatever XDG_CONFIG_DIRS says). Empty when
// neither XDG_DATA_HOME nor HOME is set for the user scope.
std::filesystem::path install_dir(Scope scope, LayerKind kind);

struct RuntimeLookup {
  std::optional<std::filesystem::path> file;  // the manifest the loader would use
  std::string origin;                          // "XR_RUNTIME_JSON", "XDG_CONFIG_HOME", ...
  std::vector<std::filesystem::path> tried;    // in order, when not from XR_RUNTIME_JSON
};
RuntimeLookup find_active_runtime();

// A layer manifest as the loader reads it (the fields we report on).
struct LayerManifest {
  std::filesystem::path file;
  std::string origin;  // SearchDir::origin
  LayerKind kind = LayerKind::explicit_layer;
  bool parsed = false;
  std::string parse_error;
  std::string name, library_path, disable_environment, enable_environment;
  std::filesystem::path resolved_library;  // library_path resolved as the loader does; empty for a bare file name
};
std::optional<LayerManifest> read_layer_manifest(const std::filesystem::path& file, LayerKind kind, std::string origin);

// Every manifest named kLayerName (or with Proprio's file name) in the search path of `kind`.
std::vector<LayerManifest> find_proprio_manifests(LayerKind kind);

}  // namespace proprio::cli::xr
