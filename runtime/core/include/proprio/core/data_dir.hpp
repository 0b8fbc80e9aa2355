#pragma once
// Where Proprio's shipped data lives: the contents of the source tree's
// config/ folder (glove descriptions, fingertip device models, the stretch
// glove's pose network, study designs), installed to <prefix>/share/proprio.
//
// Looked up in this order:
//   1. $PROPRIO_DATA_DIR, when set and not empty (a user's override);
//   2. <prefix>/share/proprio (the configured CMAKE_INSTALL_DATADIR), for the
//      binary this code is linked into (the CLI, or the OpenXR layer inside an
//      app) installed one to four levels below <prefix> (bin/,
//      libexec/proprio/, lib/proprio/, lib/<multiarch>/proprio/sources/);
//   3. the source tree's config/, for binaries run from their build tree.
// The first that exists wins; a missing override is an error, not a fallback.
#include <filesystem>
#include <string>
#include <string_view>

#include "proprio/core/result.hpp"

namespace proprio {

// The data folder, or an error that names every place looked in.
Result<std::filesystem::path> data_dir();

// data_dir() / relative as a string. When no data folder is found, the reason
// is logged once as an error and the path is built on $PROPRIO_DATA_DIR if set
// (never silently on another folder), else on the build tree's, so that the
// loader's own "no such file" message names it.
std::string data_path(std::string_view relative);

// `relative_to_binary` resolved against the folder of the binary this code is
// linked into, when that names an existing file; empty otherwise. How an
// installed program finds what was installed with it (the CLI its OpenXR
// layer, cmake/install.cmake giving the relative path), while the same
// program run from its build tree gets empty and uses its build's files.
std::filesystem::path installed_file(std::string_view relative_to_binary);

}  // namespace proprio
