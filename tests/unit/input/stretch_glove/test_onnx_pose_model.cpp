// OnnxPoseModel: load errors a user can act on, the sidecar check against the
// glove layout, and agreement with PyTorch on fixed inputs.
//
// The models and PyTorch's outputs come from an actual PyTorch run:
// tests/data/stretch_model/ is written by
//   /usr/bin/python3 tools/stretch_glove/tests/export_reference.py --out tests/data/stretch_model
// and CTest also runs that script into the build tree and points
// PROPRIO_STRETCH_MODEL_DIR there, so a changed exporter is checked too.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "proprio/stretch_glove/onnx_pose_model.hpp"
#include "support/temp_dir.hpp"
#include "support/text.hpp"

namespace proprio::stretch_glove {
namespace {

namespace fs = std::filesystem;
using proprio::testing_support::TempDir;

fs::path model_dir() {
  if (const char* env = std::getenv("PROPRIO_STRETCH_MODEL_DIR"); env && *env) return fs::path(env);
  return fs::path(PROPRIO_SOURCE_DIR) / "tests" / "data" / "stretch_model";
}

std::vector<std::uint8_t> read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_file(const fs::path& p, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(p, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

void write_text(const fs::path& p, const std::string& text) {
  std::ofstream out(p);
  out << text;
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// A float32, C-order .npy (what numpy.save writes for the fixtures).
struct Npy {
  std::vector<std::size_t> shape;
  std::vector<float> data;
};

Npy read_npy(const fs::path& p) {
  const auto bytes = read_file(p);
  Npy npy;
  if (bytes.size() < 10 || std::memcmp(bytes.data(), "\x93NUMPY", 6) != 0) {
    ADD_FAILURE() << p << ": not an .npy file";
    return npy;
  }
  const int major = bytes[6];
  const std::size_t header_len = major == 1 ? (bytes[8] | (bytes[9] << 8))
                                            : (bytes[8] | (bytes[9] << 8) | (bytes[10] << 16) | (bytes[11] << 24));
  const std::size_t header_start = major == 1 ? 10 : 12;
  const std::string header(bytes.begin() + static_cast<long>(header_start),
                           bytes.begin() + static_cast<long>(header_start + header_len));
  EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos) << p << ": " << header;
  EXPECT_NE(header.find("'fortran_order': False"), std::string::npos) << p << ": " << header;
  std::size_t count = 1;
  const std::size_t open = header.find("'shape': (");
  EXPECT_NE(open, std::string::npos) << p << ": " << header;
  if (open != std::string::npos) {
    std::size_t pos = open + std::strlen("'shape': (");
    while (pos < header.size() && header[pos] != ')') {
      if (std::isdigit(static_cast<unsigned char>(header[pos]))) {
        std::size_t used = 0;
        npy.shape.push_back(std::stoul(header.substr(pos), &used));
        count *= npy.shape.back();
        pos += used;
      } else {
        ++pos;
      }
    }
  }
  const std::size_t data_start = header_start + header_len;
  EXPECT_EQ(bytes.size() - data_start, count * sizeof(float)) << p;
  npy.data.resize(count);
  std::memcpy(npy.data.data(), bytes.data() + data_start, std::min(count * sizeof(float), bytes.size() - data_start));
  return npy;
}

// A layout whose grids are exactly the ones a sidecar names, so the check
// passes; tests then change one thing at a time.
StretchGloveLayout layout_matching(const fs::path& sidecar_path) {
  const auto j = nlohmann::json::parse(read_text(sidecar_path));
  StretchGloveLayout layout;
  layout.name = j.at("layout").get<std::string>();
  const auto index = j.at("input_grid_index").get<std::vector<int>>();
  for (std::size_t i = 0; i < index.size(); ++i) {
    StretchCell c;
    c.name = "cell_" + std::to_string(i);
    c.grid_layer = index[i] / 25;
    c.grid_row = (index[i] % 25) / 5;
    c.grid_col = index[i] % 5;
    layout.cells.push_back(c);
  }
  const auto& grid = j.at("output_grid");
  for (std::size_t k = 0; k < 25; ++k) {
    if (grid[k].is_null()) continue;
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      if (to_string(static_cast<HandDof>(d)) == grid[k].get<std::string>()) layout.output_grid[k] = static_cast<HandDof>(d);
    }
  }
  return layout;
}

using proprio::testing_support::contains;

TEST(OnnxPoseModel, MissingFileIsNotFoundAndSaysWhatToDo) {
  TempDir dir;
  const auto r = OnnxPoseModel::load(dir.path() / "nope.onnx");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::not_found);
  EXPECT_TRUE(contains(r.error().message, "nope.onnx")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "train.py")) << r.error().message;
}

TEST(OnnxPoseModel, EmptyFileIsAParseError) {
  TempDir dir;
  write_file(dir.path() / "empty.onnx", {});
  const auto r = OnnxPoseModel::load(dir.path() / "empty.onnx");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::parse_error);
  EXPECT_TRUE(contains(r.error().message, "empty")) << r.error().message;
}

TEST(OnnxPoseModel, GarbageBytesGiveAClearError) {
  TempDir dir;
  std::vector<std::uint8_t> garbage(4096);
  std::uint32_t x = 12345;
  for (auto& b : garbage) {
    x = x * 1664525u + 1013904223u;
    b = static_cast<std::uint8_t>(x >> 24);
  }
  write_file(dir.path() / "garbage.onnx", garbage);
  const auto r = OnnxPoseModel::load(dir.path() / "garbage.onnx");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::parse_error);
  EXPECT_TRUE(contains(r.error().message, "garbage.onnx")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "corrupt")) << r.error().message;
}

TEST(OnnxPoseModel, TruncatedFileGivesAClearError) {
  TempDir dir;
  const auto full = read_file(model_dir() / "unet.onnx");
  ASSERT_GT(full.size(), 1000u);
  // Without the sidecar, so OpenCV's parser (not the checksum) must notice.
  for (const double fraction : {0.01, 0.3, 0.5, 0.9, 0.999}) {
    const auto cut = static_cast<std::size_t>(fraction * static_cast<double>(full.size()));
    write_file(dir.path() / "cut.onnx", std::vector<std::uint8_t>(full.begin(), full.begin() + static_cast<long>(cut)));
    const auto r = OnnxPoseModel::load(dir.path() / "cut.onnx");
    ASSERT_FALSE(r.ok()) << "cut at " << cut << " of " << full.size() << " bytes";
    EXPECT_EQ(r.error().code, Errc::parse_error) << r.error().message;
    EXPECT_TRUE(contains(r.error().message, "truncated")) << r.error().message;
  }
}

TEST(OnnxPoseModel, DamagedWeightsAreCaughtByTheSidecarChecksum) {
  TempDir dir;
  auto bytes = read_file(model_dir() / "unet.onnx");
  // The weights are the bulk of the file; flipped bits there still parse.
  for (std::size_t i = bytes.size() / 2; i < bytes.size() / 2 + 8; ++i) bytes[i] ^= 0x55;
  write_file(dir.path() / "unet.onnx", bytes);
  fs::copy_file(model_dir() / "unet.json", dir.path() / "unet.json");
  const auto r = OnnxPoseModel::load(dir.path() / "unet.onnx");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::parse_error);
  EXPECT_TRUE(contains(r.error().message, "CRC-32")) << r.error().message;
}

TEST(OnnxPoseModel, WrongOutputShapeIsRefusedByTheDryRun) {
  const auto r = OnnxPoseModel::load(model_dir() / "wrong_shape.onnx");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::unsupported);
  EXPECT_TRUE(contains(r.error().message, "[1, 3, 5, 5]")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "[1, 1, 5, 5]")) << r.error().message;
}

TEST(OnnxPoseModel, WrongTensorNameIsRefusedByTheDryRun) {
  TempDir dir;
  fs::copy_file(model_dir() / "unet.onnx", dir.path() / "unet.onnx");  // no sidecar: names from the options
  OnnxPoseModel::Options options;
  options.input_name = "capacitance";
  const auto r = OnnxPoseModel::load(dir.path() / "unet.onnx", options);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::unsupported);
  EXPECT_TRUE(contains(r.error().message, "capacitance")) << r.error().message;
}

TEST(OnnxPoseModel, RequireSidecar) {
  TempDir dir;
  fs::copy_file(model_dir() / "fcn.onnx", dir.path() / "fcn.onnx");
  EXPECT_TRUE(OnnxPoseModel::load(dir.path() / "fcn.onnx").ok());
  OnnxPoseModel::Options options;
  options.require_sidecar = true;
  const auto r = OnnxPoseModel::load(dir.path() / "fcn.onnx", options);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::not_found);
  EXPECT_TRUE(contains(r.error().message, "fcn.json")) << r.error().message;
}

TEST(OnnxPoseModel, BrokenSidecarNamesTheLine) {
  TempDir dir;
  fs::copy_file(model_dir() / "unet.onnx", dir.path() / "unet.onnx");
  write_text(dir.path() / "unet.json", "{\n  \"cell_count\": 44,\n  \"input_grid_index\": [1, 2,,\n}\n");
  const auto r = OnnxPoseModel::load(dir.path() / "unet.onnx");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::parse_error);
  EXPECT_TRUE(contains(r.error().message, "unet.json:3:")) << r.error().message;
}

TEST(PoseModelSidecar, ParseErrorsNameTheKey) {
  auto sidecar = nlohmann::json::parse(read_text(model_dir() / "unet.json"));
  ASSERT_TRUE(PoseModelSidecar::parse(sidecar.dump(), "ok.json").ok());

  auto bad_name = sidecar;
  bad_name["output_grid"][1] = "index_knuckle_flexion";
  auto r = PoseModelSidecar::parse(bad_name.dump(), "m.json");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "output_grid[1]")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "index_knuckle_flexion")) << r.error().message;

  auto short_index = sidecar;
  short_index["input_grid_index"].erase(0);
  r = PoseModelSidecar::parse(short_index.dump(), "m.json");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "input_grid_index")) << r.error().message;

  auto out_of_grid = sidecar;
  out_of_grid["input_grid_index"][3] = 50;
  r = PoseModelSidecar::parse(out_of_grid.dump(), "m.json");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "input_grid_index[3] = 50")) << r.error().message;

  auto bad_calibration = sidecar;
  bad_calibration["normalisation"]["calibration"] = "global";  // without the min/max it needs
  r = PoseModelSidecar::parse(bad_calibration.dump(), "m.json");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "global_min_pf")) << r.error().message;
}

TEST(OnnxPoseModel, SidecarMustMatchTheLayout) {
  const fs::path onnx = model_dir() / "unet.onnx";
  const StretchGloveLayout matching = layout_matching(model_dir() / "unet.json");
  ASSERT_EQ(matching.cell_count(), 44u);
  const auto ok = OnnxPoseModel::load(onnx, matching);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  ASSERT_TRUE(ok->sidecar().has_value());
  EXPECT_EQ(ok->sidecar()->model_kind, "unet");
  EXPECT_FALSE(ok->describe().empty());

  StretchGloveLayout moved = matching;
  std::swap(moved.cells[2].grid_row, moved.cells[3].grid_row);
  std::swap(moved.cells[2].grid_col, moved.cells[3].grid_col);
  std::swap(moved.cells[2].grid_layer, moved.cells[3].grid_layer);
  auto r = OnnxPoseModel::load(onnx, moved);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, Errc::invalid_argument);
  EXPECT_TRUE(contains(r.error().message, "input_grid_index[2]")) << r.error().message;
  EXPECT_TRUE(contains(r.error().message, "cell_2")) << r.error().message;

  StretchGloveLayout other_outputs = matching;
  std::swap(other_outputs.output_grid[5], other_outputs.output_grid[6]);
  r = OnnxPoseModel::load(onnx, other_outputs);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "output_grid[5] (row 1, col 0)")) << r.error().message;

  StretchGloveLayout fewer = matching;
  fewer.cells.pop_back();
  r = OnnxPoseModel::load(onnx, fewer);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.error().message, "44 cells")) << r.error().message;
}

TEST(PoseModelSidecar, CheckAgreesWithTheThesisLayout) {
  // A sidecar written from the layout's own grids (what `proprio sim-glove` puts in meta.json and train.py copies)
  // must pass; the synthetic fixture's grids are another layout's and must not.
  const StretchGloveLayout layout = StretchGloveLayout::thesis_default();
  PoseModelSidecar sidecar;
  sidecar.layout_name = layout.name;
  sidecar.cell_count = static_cast<int>(layout.cell_count());
  sidecar.input_grid_index = layout.input_grid_index();
  sidecar.output_grid = layout.output_grid;
  const Status st = sidecar.check_against(layout, "thesis.json");
  EXPECT_TRUE(st.ok()) << st.error().message;

  const auto fixture = OnnxPoseModel::load(model_dir() / "unet.onnx", layout);
  ASSERT_FALSE(fixture.ok());
  EXPECT_EQ(fixture.error().code, Errc::invalid_argument);
  EXPECT_TRUE(contains(fixture.error().message, "trained on layout 'synthetic-44'")) << fixture.error().message;
}

// The agreement test: OpenCV's forward pass against PyTorch's on the same
// inputs (see the top of this file for where both come from).
void expect_matches_pytorch(const std::string& kind) {
  const fs::path dir = model_dir();
  const Npy inputs = read_npy(dir / "inputs.npy");
  const Npy reference = read_npy(dir / (kind + "_output.npy"));
  ASSERT_EQ(inputs.shape.size(), 4u);
  ASSERT_EQ(inputs.shape[1] * inputs.shape[2] * inputs.shape[3], kPoseInputSize);
  ASSERT_EQ(reference.data.size(), inputs.shape[0] * kPoseOutputSize);
  ASSERT_GE(inputs.shape[0], 10u);

  auto model = OnnxPoseModel::load(dir / (kind + ".onnx"));
  ASSERT_TRUE(model.ok()) << model.error().message;

  double max_abs_diff = 0.0;
  double max_abs_value = 0.0;
  std::array<float, kPoseOutputSize> out{};
  for (std::size_t i = 0; i < inputs.shape[0]; ++i) {
    ASSERT_TRUE(model->infer(inputs.data.data() + i * kPoseInputSize, out.data()));
    for (std::size_t k = 0; k < kPoseOutputSize; ++k) {
      const double want = reference.data[i * kPoseOutputSize + k];
      max_abs_diff = std::max(max_abs_diff, std::abs(static_cast<double>(out[k]) - want));
      max_abs_value = std::max(max_abs_value, std::abs(want));
    }
  }
  // Outputs are radians of order 1; a wrong rewrite or BatchNorm fold is off by far more.
  EXPECT_LE(max_abs_diff, 1e-4) << kind;
  EXPECT_GT(max_abs_value, 0.1) << kind << ": reference outputs are all near zero, the comparison would prove little";
  ::testing::Test::RecordProperty(kind + "_max_abs_diff_rad", std::to_string(max_abs_diff));
  std::printf("%s: max |OpenCV - PyTorch| = %.3g rad over %zu frames\n", kind.c_str(), max_abs_diff,
              inputs.shape[0]);
}

TEST(OnnxPoseModelAgreement, UNetMatchesPyTorch) { expect_matches_pytorch("unet"); }
TEST(OnnxPoseModelAgreement, FcnMatchesPyTorch) { expect_matches_pytorch("fcn"); }

TEST(OnnxPoseModelAgreement, RepeatedInferenceIsStable) {
  auto model = OnnxPoseModel::load(model_dir() / "unet.onnx");
  ASSERT_TRUE(model.ok()) << model.error().message;
  const Npy inputs = read_npy(model_dir() / "inputs.npy");
  std::array<float, kPoseOutputSize> first{};
  std::array<float, kPoseOutputSize> other{};
  std::array<float, kPoseOutputSize> again{};
  ASSERT_TRUE(model->infer(inputs.data.data(), first.data()));
  ASSERT_TRUE(model->infer(inputs.data.data() + kPoseInputSize, other.data()));
  ASSERT_TRUE(model->infer(inputs.data.data(), again.data()));
  EXPECT_EQ(first, again);  // no state carried between frames
  EXPECT_NE(first, other);
}

}  // namespace
}  // namespace proprio::stretch_glove
