#pragma once
// The start of every glTF load and the end of every save, shared by the static
// and the skinned mesh loaders and savers.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/file_io.hpp"
#include "proprio/core/result.hpp"

namespace proprio::render::detail {

inline constexpr std::uint64_t kMaxGltfBytes = 512 * kMiB;

// tinygltf's file access, routed through core's: external buffers and images
// are read as checked inputs (a .gltf may name a FIFO or /dev/zero as a
// buffer), and files are written atomically, never over an input.
// tinygltf's own FileExists opens the file, which blocks on a FIFO: stat it.
inline bool file_exists_checked(const std::string& path, void*) {
  std::error_code ec;
  return std::filesystem::exists(path, ec);
}
inline bool read_whole_file_checked(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                                    void*) {
  auto bytes = read_input_file(path, "glTF buffer or image", kMaxGltfBytes);
  if (!bytes) {
    if (err) *err += bytes.error().message;
    return false;
  }
  out->assign(bytes->begin(), bytes->end());
  return true;
}
inline bool write_whole_file_atomically(std::string* err, const std::string& path,
                                        const std::vector<unsigned char>& contents, void*) {
  const std::string_view text(reinterpret_cast<const char*>(contents.data()), contents.size());
  if (auto s = write_file_atomic(path, text, "glTF file"); !s) {
    if (err) *err += s.error().message;
    return false;
  }
  return true;
}
inline tinygltf::FsCallbacks checked_fs_callbacks() {
  return tinygltf::FsCallbacks{&file_exists_checked, &tinygltf::ExpandFilePath, &read_whole_file_checked,
                               &write_whole_file_atomically, nullptr};
}

// Reads the file through core's input checks (a regular file, bounded: given a
// FIFO, tinygltf's own reader would block for ever) and parses the bytes;
// external buffers resolve against the file's folder.
inline Status read_gltf_file(tinygltf::Model& model, const std::filesystem::path& file) {
  auto bytes = read_input_file(file, "glTF file", kMaxGltfBytes);
  if (!bytes) return bytes.error();
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks(checked_fs_callbacks());
  std::string err, warn;
  const std::string base = file.parent_path().string();
  const auto size = static_cast<unsigned int>(bytes->size());
  const bool ok =
      file.extension() == ".glb"
          ? loader.LoadBinaryFromMemory(&model, &err, &warn, reinterpret_cast<const unsigned char*>(bytes->data()),
                                        size, base)
          : loader.LoadASCIIFromString(&model, &err, &warn, bytes->data(), size, base);
  if (!ok) {
    return make_error(Errc::parse_error, fmt::format("glTF file '{}' could not be read: {}", printable(file.string()),
                                                     printable(err.empty() ? warn : err, 500)));
  }
  return {};
}

inline Status write_gltf_file(tinygltf::Model& model, const std::filesystem::path& file) {
  model.defaultScene = 0;
  model.asset.version = "2.0";
  model.asset.generator = "proprio";
  if (auto s = check_output_path(file, "glTF file"); !s) return s;
  tinygltf::TinyGLTF writer;
  writer.SetFsCallbacks(checked_fs_callbacks());
  if (!writer.WriteGltfSceneToFile(&model, file.string(), true, true, true, false)) {
    return make_error(Errc::io_error, fmt::format("could not write glTF file '{}'", file.string()));
  }
  return {};
}

}  // namespace proprio::render::detail
