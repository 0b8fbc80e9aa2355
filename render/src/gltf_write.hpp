#pragma once
// The end of every glTF save: one default scene, the asset header, and the
// write as a .gltf with the buffers embedded, shared by the static and the
// skinned mesh savers.
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <filesystem>

#include "proprio/core/result.hpp"

namespace proprio::render::detail {

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
