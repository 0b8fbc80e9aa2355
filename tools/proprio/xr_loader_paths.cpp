#include "xr_loader_paths.hpp"

#include "proprio/core/file_io.hpp"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <system_error>

namespace proprio::cli::xr {

namespace fs = std::filesystem;

namespace {

constexpr const char* kApiLayersRelative = "openxr/1/api_layers";

const char* kind_dir(LayerKind k) { return k == LayerKind::explicit_layer ? "explicit.d" : "implicit.d"; }

void add_list(std::vector<SearchDir>& out, const std::string& list, const char* fallback, const std::string& origin,
              LayerKind kind) {
  const bool use_fallback = list.empty();
  for (const auto& base : split_list(use_fallback ? fallback : list)) {
    out.push_back({fs::path(base) / kApiLayersRelative / kind_dir(kind), use_fallback ? origin + " default" : origin});
  }
}

std::string home_relative(const char* xdg_var, const char* home_suffix) {
  if (auto v = env(xdg_var); !v.empty()) return v;
  if (auto h = env("HOME"); !h.empty()) return (fs::path(h) / home_suffix).string();
  return {};
}

}  // namespace

const char* to_string(LayerKind k) noexcept { return k == LayerKind::explicit_layer ? "explicit" : "implicit"; }

std::string env(const char* name) {
  const char* v = std::getenv(name);
  return v ? v : "";
}

std::vector<std::string> split_list(std::string_view s) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= s.size()) {
    const std::size_t end = std::min(s.find(':', start), s.size());
    if (end > start) out.emplace_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

std::vector<SearchDir> layer_search_dirs(LayerKind kind) {
  std::vector<SearchDir> dirs;
  if (kind == LayerKind::explicit_layer) {
    if (auto over = env("XR_API_LAYER_PATH"); !over.empty()) {
      for (const auto& p : split_list(over)) dirs.push_back({p, "XR_API_LAYER_PATH"});
      return dirs;
    }
  }
  add_list(dirs, env("XDG_CONFIG_DIRS"), "/etc/xdg", "XDG_CONFIG_DIRS", kind);
  dirs.push_back({fs::path("/etc") / kApiLayersRelative / kind_dir(kind), "/etc (loader's SYSCONFDIR)"});
  add_list(dirs, env("XDG_DATA_DIRS"), "/usr/local/share:/usr/share", "XDG_DATA_DIRS", kind);
  if (auto d = env("XDG_DATA_HOME"); !d.empty()) {
    dirs.push_back({fs::path(d) / kApiLayersRelative / kind_dir(kind), "XDG_DATA_HOME"});
  } else if (auto h = env("HOME"); !h.empty()) {
    dirs.push_back({fs::path(h) / ".local/share" / kApiLayersRelative / kind_dir(kind), "HOME/.local/share"});
  }
  return dirs;
}

fs::path install_dir(Scope scope, LayerKind kind) {
  if (scope == Scope::system) return fs::path("/etc") / kApiLayersRelative / kind_dir(kind);
  const std::string base = home_relative("XDG_DATA_HOME", ".local/share");
  if (base.empty()) return {};
  return fs::path(base) / kApiLayersRelative / kind_dir(kind);
}

RuntimeLookup find_active_runtime() {
  RuntimeLookup r;
  if (auto j = env("XR_RUNTIME_JSON"); !j.empty()) {
    r.origin = "XR_RUNTIME_JSON";
    r.file = fs::path(j);
    return r;
  }
  std::vector<std::pair<fs::path, std::string>> candidates;
  if (auto h = home_relative("XDG_CONFIG_HOME", ".config"); !h.empty()) {
    candidates.emplace_back(fs::path(h) / "openxr/1/active_runtime.json", "XDG_CONFIG_HOME");
  }
  const std::string conf_dirs = env("XDG_CONFIG_DIRS");
  for (const auto& d : split_list(conf_dirs.empty() ? "/etc/xdg" : conf_dirs)) {
    candidates.emplace_back(fs::path(d) / "openxr/1/active_runtime.json", "XDG_CONFIG_DIRS");
  }
  candidates.emplace_back("/etc/openxr/1/active_runtime.json", "/etc (loader's SYSCONFDIR)");
  for (const auto& [path, origin] : candidates) {
    r.tried.push_back(path);
    std::error_code ec;
    if (fs::exists(path, ec)) {
      r.file = path;
      r.origin = origin;
      return r;
    }
  }
  return r;
}

std::optional<LayerManifest> read_layer_manifest(const fs::path& file, LayerKind kind, std::string origin) {
  std::error_code ec;
  if (!fs::exists(file, ec)) return std::nullopt;
  LayerManifest m;
  m.file = file;
  m.kind = kind;
  m.origin = std::move(origin);
  // What sits in a manifest folder is not ours: never block on a FIFO there.
  auto text = read_input_file(file, "layer manifest", 1024 * 1024);
  if (!text) {
    m.parse_error = text.error().message;
    return m;
  }
  auto j = nlohmann::json::parse(*text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object() || !j.contains("api_layer") || !j["api_layer"].is_object()) {
    m.parse_error = "not a valid API layer manifest (JSON object with an \"api_layer\" object)";
    return m;
  }
  const auto& layer = j["api_layer"];
  auto str = [&](const char* key) -> std::string {
    return layer.contains(key) && layer[key].is_string() ? layer[key].get<std::string>() : std::string{};
  };
  m.name = str("name");
  m.library_path = str("library_path");
  m.disable_environment = str("disable_environment");
  m.enable_environment = str("enable_environment");
  if (m.name.empty() || m.library_path.empty()) {
    m.parse_error = "\"api_layer\" lacks \"name\" or \"library_path\"";
    return m;
  }
  m.parsed = true;
  // The loader takes an absolute path as is, a path with a '/' relative to the
  // manifest's folder, and a bare file name through the dynamic linker's search.
  const fs::path lib(m.library_path);
  if (lib.is_absolute()) {
    m.resolved_library = lib;
  } else if (m.library_path.find('/') != std::string::npos) {
    m.resolved_library = file.parent_path() / lib;
  }
  return m;
}

std::vector<LayerManifest> find_proprio_manifests(LayerKind kind) {
  std::vector<LayerManifest> found;
  for (const auto& sd : layer_search_dirs(kind)) {
    std::error_code ec;
    std::vector<fs::path> files;
    if (fs::is_directory(sd.dir, ec)) {
      for (const auto& e : fs::directory_iterator(sd.dir, ec)) {
        if (e.path().extension() == ".json") files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());
    } else if (fs::is_regular_file(sd.dir, ec) && sd.dir.extension() == ".json") {
      files.push_back(sd.dir);
    }
    for (const auto& f : files) {
      auto m = read_layer_manifest(f, kind, sd.origin);
      if (!m) continue;
      const bool ours = m->name == kLayerName || (!m->parsed && f.filename() == kLayerManifestFile);
      if (ours) found.push_back(std::move(*m));
    }
  }
  return found;
}

}  // namespace proprio::cli::xr
