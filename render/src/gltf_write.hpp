#pragma once
// The start of every glTF load and the end of every save, shared by the static
// and the skinned mesh loaders and savers.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <cstdint>
#include <filesystem>
#include <string>

#include "proprio/core/file_io.hpp"
#include "proprio/core/result.hpp"

namespace proprio::render::detail {

inline constexpr std::uint64_t kMaxGltfBytes = 512 * kMiB;

// Reads the file through core's input checks (a regular file, bounded: given a
// FIFO, tinygltf's own reader would block for ever) and parses the bytes;
// external buffers resolve against the file's folder.
inline Status read_gltf_file(tinygltf::Model& model, const std::filesystem::path& file) {
  auto bytes = read_input_file(file, "glTF file", kMaxGltfBytes);
  if (!bytes) return bytes.error();
  tinygltf::TinyGLTF loader;
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
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToFile(&model, file.string(), true, true, true, false)) {
    return make_error(Errc::io_error, fmt::format("could not write glTF file '{}'", file.string()));
  }
  return {};
}

}  // namespace proprio::render::detail
