// sim-array end to end on a few simulated seconds: the dataset it writes is
// complete and consistent, the rest frames read C/C0 = 1, the labelled
// markers are the true ones within the mocap noise, and the same seed gives
// the same bytes whatever the thread count.
#include "proprio/stretch_array_eval/sim_array.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>

#include "proprio/stretch_array_eval/array_dataset.hpp"

namespace proprio::stretch_array_eval {
namespace {

SimArrayOptions tiny(const char* name, int threads) {
  SimArrayOptions o;
  o.motion = "elbow";
  o.train_sessions = 1;
  o.train_minutes = 0.05;
  o.test_sessions = 0;
  o.redonned_test = true;
  o.test_minutes = 0.05;
  o.threads = threads;
  o.out = (std::filesystem::path(testing::TempDir()) / name).string();
  o.force = true;
  return o;
}

std::string bytes_of(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(SimArray, WritesAConsistentDatasetWhoseLabelsAreTheTrueMarkers) {
  const SimArrayOptions o = tiny("sim_array_a", 2);
  auto report = write_sim_array_dataset(o);
  ASSERT_TRUE(report) << report.error().message;
  ASSERT_EQ(report->sessions.size(), 2u);
  auto d = load_array_dataset(o.out);
  ASSERT_TRUE(d) << d.error().message;
  EXPECT_EQ(d->frames(), report->frames);
  // Two sessions of 1 s at rest + 3 s at 8 Hz, less what the labelling dropped.
  EXPECT_EQ(report->frames + report->frames_dropped, 32u + 32u);
  EXPECT_LT(report->frames_dropped, 20u);
  ASSERT_EQ(d->sessions.size(), 2u);
  EXPECT_EQ(d->sessions[1].donning, 1);
  EXPECT_EQ(d->sessions[1].split, "test");
  EXPECT_EQ(d->shape.layout, "prototype_92");
  const std::size_t C = d->shape.cell_names.size(), M = d->shape.marker_names.size();
  ASSERT_EQ(C, 92u);

  // The first kept frame is at rest: every cell's C/C0 about 1. C0 is the
  // mean of the rest frames, so one frame is off by its noise: 1 fF steps
  // and the 555's jitter on cells of about 3 pF, through a least-squares
  // solve of condition 9.
  double worst_rest = 0.0, mean_rest = 0.0, widest = 0.0;
  for (std::size_t c = 0; c < C; ++c) {
    worst_rest = std::max(worst_rest, std::abs(d->cells.values[c] - 1.0));
    mean_rest += std::abs(d->cells.values[c] - 1.0) / static_cast<double>(C);
  }
  for (double v : d->cells.values) widest = std::max(widest, std::abs(v - 1.0));
  EXPECT_LT(worst_rest, 0.03);
  EXPECT_LT(mean_rest, 0.005);
  EXPECT_GT(widest, 0.05) << "the elbow bends: some cells stretch";

  // Labelled markers against the truth the labelling never saw: within a
  // millimetre (0.2 mm noise per axis) except for wrong matches, which must be rare.
  std::size_t close = 0, total = 0;
  for (std::size_t i = 0; i < d->frames() * M; ++i) {
    const double dx = d->markers.values[3 * i] - d->markers_truth.values[3 * i];
    const double dy = d->markers.values[3 * i + 1] - d->markers_truth.values[3 * i + 1];
    const double dz = d->markers.values[3 * i + 2] - d->markers_truth.values[3 * i + 2];
    close += std::sqrt(dx * dx + dy * dy + dz * dz) < 1e-3;
    ++total;
  }
  EXPECT_GT(static_cast<double>(close) / static_cast<double>(total), 0.97);

  // The same seed with one thread: the same bytes.
  const SimArrayOptions again = tiny("sim_array_b", 1);
  ASSERT_TRUE(write_sim_array_dataset(again));
  for (const char* f : {"cells.npy", "markers.npy", "vertices_truth.npy"}) {
    EXPECT_EQ(bytes_of(std::filesystem::path(o.out) / f), bytes_of(std::filesystem::path(again.out) / f)) << f;
  }
}

TEST(SimArray, BadOptionsAreRefusedBeforeAnythingIsWritten) {
  SimArrayOptions o = tiny("sim_array_bad", 1);
  o.motion = "knee";
  EXPECT_FALSE(write_sim_array_dataset(o));
  o = tiny("sim_array_bad", 1);
  o.train_minutes = std::nan("");
  EXPECT_FALSE(write_sim_array_dataset(o));
  o = tiny("sim_array_bad", 1);
  o.layout_file = "/dev/zero";
  auto r = write_sim_array_dataset(o);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("/dev/zero"), std::string::npos) << r.error().message;
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(o.out) / "meta.json"));
}

}  // namespace
}  // namespace proprio::stretch_array_eval
