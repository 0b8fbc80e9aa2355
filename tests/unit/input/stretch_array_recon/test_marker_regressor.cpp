// The regressor through OpenCV DNN, against the values the exporter printed.
#include "proprio/stretch_array_recon/marker_regressor.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

namespace proprio::stretch_array_recon {
namespace test_marker_regressor {

namespace fs = std::filesystem;

fs::path data_dir() { return fs::path(PROPRIO_TESTS_DIR) / "data" / "stretch_array_recon"; }

class RegressorFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("proprio_regressor_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path write(const std::string& name, const std::string& bytes) {
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
    return dir_ / name;
  }
  static std::string read(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
  }
  fs::path dir_;
};

TEST(MarkerRegressor, MatchesTheExportersOutputs) {
  auto r = MarkerRegressor::load(data_dir() / "tiny_regressor.onnx", 6, 2);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->kind(), "dnn");
  std::ifstream f(data_dir() / "tiny_expected.json");
  const auto j = nlohmann::json::parse(f);
  ASSERT_EQ(j["inputs"].size(), j["outputs"].size());
  ASSERT_GE(j["inputs"].size(), 2u);
  for (std::size_t k = 0; k < j["inputs"].size(); ++k) {
    const auto in = j["inputs"][k].get<std::vector<double>>();
    const auto want = j["outputs"][k].get<std::vector<double>>();
    ASSERT_EQ(want.size(), 6u);
    Eigen::MatrixX3d markers;
    ASSERT_TRUE(r->predict(Eigen::Map<const Eigen::VectorXd>(in.data(), 6), markers));
    ASSERT_EQ(markers.rows(), 2);
    for (int m = 0; m < 2; ++m) {
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(markers(m, c), want[static_cast<std::size_t>(3 * m + c)], 1e-5) << k;
    }
  }
}

TEST(MarkerRegressor, SizesComeFromTheSidecarWhenNotGiven) {
  auto r = MarkerRegressor::load(data_dir() / "tiny_regressor.onnx", 0, 0);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->cell_count(), 6u);
  EXPECT_EQ(r->marker_count(), 2u);
}

TEST(MarkerRegressor, RefusesNanInputsAndWrongSizes) {
  auto r = MarkerRegressor::load(data_dir() / "tiny_regressor.onnx", 6, 2);
  ASSERT_TRUE(r);
  Eigen::VectorXd cells = Eigen::VectorXd::Ones(6);
  cells(3) = std::nan("");
  Eigen::MatrixX3d markers;
  Status s = r->predict(cells, markers);
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("cell 3"), std::string::npos);
  EXPECT_FALSE(r->predict(Eigen::VectorXd::Ones(5), markers));
}

TEST(MarkerRegressor, ASidecarForAnotherSensorIsRefused) {
  auto r = MarkerRegressor::load(data_dir() / "tiny_regressor.onnx", 92, 2);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("6 cells"), std::string::npos) << r.error().message;
  auto r2 = MarkerRegressor::load(data_dir() / "tiny_regressor.onnx", 6, 21);
  ASSERT_FALSE(r2);
  EXPECT_NE(r2.error().message.find("2 markers"), std::string::npos) << r2.error().message;
}

TEST_F(RegressorFiles, MissingEmptyAndCorruptFilesGiveClearErrors) {
  auto missing = MarkerRegressor::load(dir_ / "nothing.onnx", 6, 2);
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);

  auto empty = MarkerRegressor::load(write("empty.onnx", ""), 6, 2);
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.error().message.find("empty"), std::string::npos);

  const std::string model = read(data_dir() / "tiny_regressor.onnx");
  auto truncated = MarkerRegressor::load(write("cut.onnx", model.substr(0, model.size() / 2)), 6, 2);
  ASSERT_FALSE(truncated);
  EXPECT_NE(truncated.error().message.find("cut.onnx"), std::string::npos);

  auto text = MarkerRegressor::load(write("text.onnx", "this is not a model"), 6, 2);
  ASSERT_FALSE(text);
}

TEST_F(RegressorFiles, SidecarProblemsAndShapeMismatches) {
  const std::string model = read(data_dir() / "tiny_regressor.onnx");
  // No sidecar: the caller's sizes are checked by the dry run.
  const fs::path bare = write("bare.onnx", model);
  EXPECT_TRUE(MarkerRegressor::load(bare, 6, 2));
  auto wrong_out = MarkerRegressor::load(bare, 6, 3);
  ASSERT_FALSE(wrong_out);
  EXPECT_NE(wrong_out.error().message.find("output"), std::string::npos) << wrong_out.error().message;
  auto wrong_in = MarkerRegressor::load(bare, 7, 2);
  ASSERT_FALSE(wrong_in);
  EXPECT_NE(wrong_in.error().message.find("[1, 7]"), std::string::npos) << wrong_in.error().message;
  auto unsized = MarkerRegressor::load(bare, 0, 0);
  ASSERT_FALSE(unsized);
  EXPECT_NE(unsized.error().message.find("sidecar"), std::string::npos);
  MarkerRegressorOptions strict;
  strict.require_sidecar = true;
  EXPECT_FALSE(MarkerRegressor::load(bare, 6, 2, strict));

  write("badjson.onnx", model);
  write("badjson.json", "{\"cell_count\": 6,");
  auto bad = MarkerRegressor::load(dir_ / "badjson.onnx", 6, 2);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("badjson.json"), std::string::npos);

  write("kind.onnx", model);
  write("kind.json", R"({"cell_count": 6, "marker_count": 2, "kind": "forest"})");
  auto kind = MarkerRegressor::load(dir_ / "kind.onnx", 6, 2);
  ASSERT_FALSE(kind);
  EXPECT_NE(kind.error().message.find("forest"), std::string::npos);

  write("nocount.onnx", model);
  write("nocount.json", R"({"marker_count": 2})");
  auto nocount = MarkerRegressor::load(dir_ / "nocount.onnx", 6, 2);
  ASSERT_FALSE(nocount);
  EXPECT_NE(nocount.error().message.find("cell_count"), std::string::npos);
}

}  // namespace test_marker_regressor
}  // namespace proprio::stretch_array_recon
