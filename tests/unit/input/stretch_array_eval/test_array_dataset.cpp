#include "proprio/stretch_array_eval/array_dataset.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>

namespace proprio::stretch_array_eval {
namespace {

ArrayDatasetShape small_shape() {
  ArrayDatasetShape s;
  s.layout = "test";
  s.cell_names = {"a", "b"};
  s.marker_names = {"m0"};
  s.mesh_vertex_count = 2;
  s.frame_rate_hz = 8.0;
  s.pose_name = "angle, degrees";
  s.rest_radius_m = 0.04;
  return s;
}

ArrayDatasetSession session(std::string name, std::size_t frames, float base) {
  ArrayDatasetSession s;
  s.name = std::move(name);
  s.motion = "wrist";
  for (std::size_t f = 0; f < frames; ++f) {
    s.cells.insert(s.cells.end(), {base + f, base + f + 0.5f});
    s.markers.insert(s.markers.end(), {0.01f * f, 0.0f, base});
    s.markers_truth.insert(s.markers_truth.end(), {0.01f * f, 0.001f, base});
    s.vertices_truth.insert(s.vertices_truth.end(), {0, 0, 0, 1, 1, 1});
    s.pose.push_back(10.0f * f);
  }
  return s;
}

std::filesystem::path fresh_dir(const char* name) {
  auto d = std::filesystem::path(testing::TempDir()) / name;
  std::filesystem::remove_all(d);
  return d;
}

TEST(ArrayDataset, WrittenSessionsReadBackInOrder) {
  const auto dir = fresh_dir("array_dataset_rw");
  {
    auto w = ArrayDatasetWriter::create(dir, small_shape(), false);
    ASSERT_TRUE(w) << w.error().message;
    auto a = session("train-0", 3, 1.0f);
    a.frames_dropped = 4;
    ASSERT_TRUE(w->add_session(a));
    auto b = session("test-0", 2, 7.0f);
    b.split = "test";
    b.donning = 1;
    ASSERT_TRUE(w->add_session(b));
    ASSERT_TRUE(w->finish(R"({"tool": "test", "seed": 3})"));
  }
  auto d = load_array_dataset(dir);
  ASSERT_TRUE(d) << d.error().message;
  EXPECT_EQ(d->frames(), 5u);
  ASSERT_EQ(d->sessions.size(), 2u);
  EXPECT_EQ(d->sessions[0].frames_dropped, 4u);
  EXPECT_EQ(d->sessions[1].first_frame, 3u);
  EXPECT_EQ(d->sessions[1].split, "test");
  EXPECT_EQ(d->sessions[1].donning, 1);
  EXPECT_EQ(d->cells.shape, (std::vector<std::size_t>{5, 2}));
  EXPECT_FLOAT_EQ(d->cells.values[3 * 2 + 1], 7.5f);
  EXPECT_EQ(d->markers.shape, (std::vector<std::size_t>{5, 1, 3}));
  EXPECT_EQ(d->session.values[4], 1.0);
  EXPECT_EQ(d->shape.pose_name, "angle, degrees");
  EXPECT_DOUBLE_EQ(d->shape.rest_radius_m, 0.04);
}

TEST(ArrayDataset, ASecondWriterAndAnUnfinishedOrDamagedDatasetAreRefused) {
  const auto dir = fresh_dir("array_dataset_bad");
  auto w = ArrayDatasetWriter::create(dir, small_shape(), false);
  ASSERT_TRUE(w);
  EXPECT_FALSE(ArrayDatasetWriter::create(dir, small_shape(), true)) << "the folder is locked";
  ASSERT_TRUE(w->add_session(session("s", 2, 0.0f)));
  EXPECT_FALSE(load_array_dataset(dir)) << "no meta.json yet";
  auto wrong = session("wrong", 2, 0.0f);
  wrong.cells.pop_back();
  EXPECT_FALSE(w->add_session(wrong));
  ASSERT_TRUE(w->finish("{}"));
  ASSERT_TRUE(load_array_dataset(dir));

  // A truncated array no longer matches meta.json.
  std::filesystem::resize_file(dir / "pose.npy", std::filesystem::file_size(dir / "pose.npy") - 4);
  auto r = load_array_dataset(dir);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("pose.npy"), std::string::npos) << r.error().message;
}

TEST(ArrayDataset, NonFiniteValuesAreRefusedOnLoad) {
  const auto dir = fresh_dir("array_dataset_nan");
  {
    auto w = ArrayDatasetWriter::create(dir, small_shape(), false);
    ASSERT_TRUE(w);
    auto s = session("s", 2, 0.0f);
    s.cells[1] = std::numeric_limits<float>::quiet_NaN();
    ASSERT_TRUE(w->add_session(s));
    ASSERT_TRUE(w->finish("{}"));
  }
  auto r = load_array_dataset(dir);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("NaN"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace proprio::stretch_array_eval
