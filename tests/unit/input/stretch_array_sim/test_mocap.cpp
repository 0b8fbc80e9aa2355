// The mocap simulator: noise, occlusion with new labels on reappearance,
// label swaps and ghosts, checked against the truth it keeps apart.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <set>

#include "proprio/stretch_array_sim/mocap.hpp"

namespace proprio::stretch_array_sim {
namespace {

std::vector<Eigen::Vector3d> grid_markers(std::size_t n, double pitch_m) {
  std::vector<Eigen::Vector3d> m;
  for (std::size_t i = 0; i < n; ++i) m.emplace_back(pitch_m * static_cast<double>(i % 4), pitch_m * static_cast<double>(i / 4), 0.1);
  return m;
}

MocapOptions clean() {
  MocapOptions o;
  o.p_lose = 0.0;
  o.p_swap = 0.0;
  o.p_ghost = 0.0;
  return o;
}

TEST(MocapSimulator, NoiseIsTwoTenthsOfAMillimetre) {
  auto sim = MocapSimulator::create(12, clean());
  ASSERT_TRUE(sim);
  const auto markers = grid_markers(12, 0.04);
  double sum2 = 0.0, sum = 0.0;
  std::size_t n = 0;
  for (int k = 0; k < 500; ++k) {
    auto f = sim->step(k / 120.0, markers);
    ASSERT_TRUE(f);
    ASSERT_EQ(f->observations.size(), 12u);
    const auto& who = sim->truth().marker_of_observation.back();
    for (std::size_t i = 0; i < f->observations.size(); ++i) {
      const Eigen::Vector3d e = f->observations[i].position_m - markers[static_cast<std::size_t>(who[i])];
      for (int a = 0; a < 3; ++a) {
        sum += e[a];
        sum2 += e[a] * e[a];
        ++n;
      }
    }
  }
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(sd, 0.2e-3, 0.01e-3);
  EXPECT_NEAR(mean, 0.0, 0.02e-3);
  EXPECT_EQ(sim->truth().labels_issued, 12u);
}

TEST(MocapSimulator, AMarkerThatReappearsGetsANewLabel) {
  MocapOptions o = clean();
  o.visibility = [](std::size_t marker, std::uint64_t frame, const Eigen::Vector3d&) {
    return marker == 3 && frame >= 10 && frame < 20 ? 0.0 : 1.0;
  };
  auto sim = MocapSimulator::create(8, o);
  ASSERT_TRUE(sim);
  const auto markers = grid_markers(8, 0.04);
  std::map<int, std::set<std::uint32_t>> labels_of_marker;
  std::set<std::uint32_t> seen;
  for (int k = 0; k < 30; ++k) {
    auto f = sim->step(k, markers);
    ASSERT_TRUE(f);
    EXPECT_EQ(f->observations.size(), k >= 10 && k < 20 ? 7u : 8u);
    const auto& who = sim->truth().marker_of_observation.back();
    for (std::size_t i = 0; i < who.size(); ++i) {
      if (k == 20 && who[i] == 3) {
        EXPECT_EQ(seen.count(f->observations[i].label), 0u) << "the new label was used before";
      }
      labels_of_marker[who[i]].insert(f->observations[i].label);
    }
    for (const auto& ob : f->observations) seen.insert(ob.label);
  }
  EXPECT_EQ(labels_of_marker[3].size(), 2u);
  for (int m = 0; m < 8; ++m) {
    if (m != 3) {
      EXPECT_EQ(labels_of_marker[m].size(), 1u) << m;
    }
  }
  EXPECT_EQ(sim->truth().reappearances, 1u);
  EXPECT_EQ(sim->truth().labels_issued, 9u);
  EXPECT_EQ(sim->truth().missing, 10u);
}

TEST(MocapSimulator, DefaultOcclusionComesInStretches) {
  MocapOptions o = clean();
  o.p_lose = 0.004;
  o.mean_occluded_frames = 25;
  auto sim = MocapSimulator::create(12, o);
  ASSERT_TRUE(sim);
  const auto markers = grid_markers(12, 0.04);
  std::vector<int> run(12, 0);
  std::vector<int> runs;
  for (int k = 0; k < 6000; ++k) {
    ASSERT_TRUE(sim->step(k, markers));
    std::vector<bool> vis(12, false);
    for (auto m : sim->truth().marker_of_observation.back()) vis[static_cast<std::size_t>(m)] = true;
    for (int m = 0; m < 12; ++m) {
      if (!vis[m]) {
        ++run[m];
      } else if (run[m] > 0) {
        runs.push_back(run[m]);
        run[m] = 0;
      }
    }
  }
  ASSERT_GT(runs.size(), 100u);
  double mean = 0.0;
  for (int r : runs) mean += static_cast<double>(r) / runs.size();
  EXPECT_NEAR(mean, 25.0, 5.0);
  EXPECT_EQ(sim->truth().reappearances, runs.size());
  EXPECT_EQ(sim->truth().labels_issued, 12u + runs.size());
}

TEST(MocapSimulator, SwapsBetweenCloseTracksAreCounted) {
  MocapOptions o = clean();
  o.p_swap = 0.1;
  o.swap_distance_m = 0.01;
  auto sim = MocapSimulator::create(4, o);
  ASSERT_TRUE(sim);
  // Markers 0 and 1 5 mm apart; 2 and 3 far from everything.
  const std::vector<Eigen::Vector3d> markers = {{0, 0, 0}, {0.005, 0, 0}, {0.1, 0, 0}, {0, 0.1, 0}};
  std::uint32_t last = 0;
  std::uint64_t changes = 0;
  std::set<std::uint32_t> labels_of_far;
  for (int k = 0; k < 300; ++k) {
    auto f = sim->step(k, markers);
    ASSERT_TRUE(f);
    const auto& who = sim->truth().marker_of_observation.back();
    for (std::size_t i = 0; i < who.size(); ++i) {
      if (who[i] == 0) {
        if (k > 0 && f->observations[i].label != last) ++changes;
        last = f->observations[i].label;
      }
      if (who[i] >= 2) labels_of_far.insert(f->observations[i].label);
    }
  }
  EXPECT_GT(sim->truth().swaps, 10u);
  EXPECT_EQ(changes, sim->truth().swaps);
  EXPECT_EQ(labels_of_far.size(), 2u) << "far markers never swap";
}

TEST(MocapSimulator, GhostsAreNearMarkersAndMarkedInTheTruth) {
  MocapOptions o = clean();
  o.p_ghost = 0.5;
  auto sim = MocapSimulator::create(6, o);
  ASSERT_TRUE(sim);
  const auto markers = grid_markers(6, 0.1);
  std::uint64_t ghosts = 0;
  for (int k = 0; k < 400; ++k) {
    auto f = sim->step(k, markers);
    ASSERT_TRUE(f);
    const auto& who = sim->truth().marker_of_observation.back();
    ASSERT_EQ(who.size(), f->observations.size());
    for (std::size_t i = 0; i < who.size(); ++i) {
      if (who[i] >= 0) continue;
      ++ghosts;
      double nearest = 1e9;
      for (const auto& m : markers) nearest = std::min(nearest, (m - f->observations[i].position_m).norm());
      EXPECT_LE(nearest, o.ghost_radius_m + 1e-12);
    }
    for (std::size_t i = 1; i < f->observations.size(); ++i) EXPECT_LT(f->observations[i - 1].label, f->observations[i].label);
  }
  EXPECT_EQ(ghosts, sim->truth().ghosts);
  EXPECT_NEAR(static_cast<double>(ghosts), 200.0, 45.0);
}

TEST(MocapSimulator, SeededAndValidated) {
  MocapOptions o;
  o.p_ghost = 0.1;
  o.p_lose = 0.05;
  auto a = MocapSimulator::create(10, o), b = MocapSimulator::create(10, o);
  ASSERT_TRUE(a && b);
  const auto markers = grid_markers(10, 0.01);
  for (int k = 0; k < 50; ++k) {
    auto fa = a->step(k, markers), fb = b->step(k, markers);
    ASSERT_EQ(fa->observations.size(), fb->observations.size());
    for (std::size_t i = 0; i < fa->observations.size(); ++i) {
      EXPECT_EQ(fa->observations[i].label, fb->observations[i].label);
      EXPECT_EQ(fa->observations[i].position_m, fb->observations[i].position_m);
    }
  }
  EXPECT_FALSE(a->step(0, grid_markers(3, 0.01)));
  MocapOptions bad = o;
  bad.p_swap = 2.0;
  EXPECT_FALSE(MocapSimulator::create(3, bad));
  EXPECT_FALSE(MocapSimulator::create(0, o));
  EXPECT_NE(o.describe().find("0.2 mm"), std::string::npos);
}

}  // namespace
}  // namespace proprio::stretch_array_sim
