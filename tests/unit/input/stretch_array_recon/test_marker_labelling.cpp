// Semi-automatic marker labelling on synthetic tracks with a known truth.
#include "proprio/stretch_array_recon/marker_labelling.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace proprio::stretch_array_recon {
namespace test_marker_labelling {

using stretch_array::StripArrayLayout;

struct Scene {
  ReconMesh mesh;
  std::vector<std::uint32_t> markers;
  Eigen::MatrixX3d rest;
  std::vector<MocapFrame> frames;
  std::map<std::uint32_t, int> truth;      // label -> marker, -1 for the ghost
  std::vector<std::vector<bool>> visible;  // frame x marker
};

constexpr std::size_t kFrames = 160;
constexpr std::uint32_t kGhost = 9999;

// The sheet bends from a 30 cm to a 12 cm cylinder while it turns and moves.
// Labels: marker m starts as 1000 + m; some markers are lost and come back
// under new labels, one is hidden in the first frames, and a ghost track
// floats 40 mm off a hidden marker.
Scene make_scene() {
  Scene s;
  auto m = build_recon_mesh(StripArrayLayout::prototype_92());
  EXPECT_TRUE(m);
  s.mesh = *m;
  s.markers = *select_marker_vertices(s.mesh);
  s.rest = rest_shape(s.mesh, 0.0);
  const std::size_t M = s.markers.size();
  EXPECT_GE(M, 13u);
  std::mt19937 rng(30);
  std::normal_distribution<double> noise(0.0, 0.0003);
  std::vector<std::uint32_t> label(M);
  for (std::size_t k = 0; k < M; ++k) label[k] = 1000 + static_cast<std::uint32_t>(k);
  struct Gap {
    std::size_t marker, from, to;
    std::uint32_t new_label;
  };
  const std::vector<Gap> gaps = {
      {4, 50, 70, 2000}, {7, 50, 70, 2001}, {10, 120, 130, 2002}, {2, 80, 100, 2003}, {12, 0, 5, 3000}};
  s.visible.assign(kFrames, std::vector<bool>(M, true));
  for (std::size_t t = 0; t < kFrames; ++t) {
    const double u = static_cast<double>(t) / kFrames;
    const Eigen::MatrixX3d bent = rest_shape(s.mesh, 0.30 - 0.18 * u);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.8 * u, Eigen::Vector3d(0.2, 1, 0.3).normalized()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(0.5 + 0.1 * u, 1.0, -0.05 * u);
    MocapFrame f{static_cast<double>(t) / 120.0, {}};
    for (std::size_t k = 0; k < M; ++k) {
      bool hidden = false;
      for (const Gap& g : gaps) {
        if (g.marker != k) continue;
        if (t >= g.from && t < g.to) hidden = true;
        if (t == g.to) label[k] = g.new_label;
      }
      const Eigen::Vector3d p = T * bent.row(s.markers[k]).transpose();
      if (hidden) {
        s.visible[t][k] = false;
        if (k == 4 && t >= 52 && t < 68) {
          f.observations.push_back({kGhost, p + T.linear() * Eigen::Vector3d(0, 0, 0.04)});
        }
        continue;
      }
      s.truth[label[k]] = static_cast<int>(k);
      f.observations.push_back({label[k], p + Eigen::Vector3d(noise(rng), noise(rng), noise(rng))});
    }
    std::shuffle(f.observations.begin(), f.observations.end(), rng);
    s.frames.push_back(std::move(f));
  }
  s.truth[kGhost] = -1;
  return s;
}

TEST(MarkerLabelling, RecoversTheTrueAssignmentAndRejectsTheGhost) {
  const Scene s = make_scene();
  const std::size_t M = s.markers.size();
  const std::vector<InitialMatch> initial = {{1000, 0}, {1005, 5}, {1000 + static_cast<std::uint32_t>(M - 1), M - 1}};
  auto r = label_markers(s.rest, s.mesh.triangles, s.markers, s.frames, initial);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->labels_seen, s.truth.size());
  for (const auto& [label, marker] : s.truth) {
    ASSERT_TRUE(r->marker_of_label.count(label)) << label;
    EXPECT_EQ(r->marker_of_label.at(label), marker) << "label " << label;
  }
  EXPECT_EQ(r->labels_outlier, 1u);
  EXPECT_EQ(r->labels_assigned, s.truth.size() - 1);
  std::size_t complete = 0;
  for (std::size_t t = 0; t < kFrames; ++t) {
    bool all = true;
    for (std::size_t k = 0; k < M; ++k) {
      all = all && s.visible[t][k];
      EXPECT_EQ(std::isnan(r->markers_m[t](static_cast<Eigen::Index>(k), 0)), !s.visible[t][k]) << t << " " << k;
    }
    EXPECT_EQ(r->complete[t], all);
    complete += all;
  }
  EXPECT_EQ(r->frames_complete, complete);
  EXPECT_EQ(r->frames_dropped, kFrames - complete);
  EXPECT_GT(r->proxies_solved, 0u);
}

TEST(MarkerLabelling, AGhostWithinTauOfAFreeMarkerIsTakenOnlyWhenTauAllows) {
  // The same ghost, 40 mm off: with tau = 50 mm it would be taken as marker 4.
  const Scene s = make_scene();
  const std::size_t M = s.markers.size();
  LabellingOptions o;
  o.tau_m = 0.05;
  auto r = label_markers(s.rest, s.mesh.triangles, s.markers, s.frames,
                         {{1000, 0}, {1005, 5}, {1000 + static_cast<std::uint32_t>(M - 1), M - 1}}, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->marker_of_label.at(kGhost), 4);
}

TEST(MarkerLabelling, ShortGapsAreFilledByContinuityAndLongOnesByProxies) {
  // Marker 10 is lost for 10 frames: its new label starts near where it was
  // last seen, so gap filling takes it; markers 4 and 7 are lost for 20,
  // longer than the window, and go through the proxies. Without gap filling
  // every new label goes through the proxies, with the same answers.
  const Scene s = make_scene();
  const std::size_t M = s.markers.size();
  const std::vector<InitialMatch> initial = {{1000, 0}, {1005, 5}, {1000 + static_cast<std::uint32_t>(M - 1), M - 1}};
  for (std::size_t window : {std::size_t{16}, std::size_t{0}}) {
    LabellingOptions o;
    o.continuity_frames = window;
    auto r = label_markers(s.rest, s.mesh.triangles, s.markers, s.frames, initial, o);
    ASSERT_TRUE(r) << r.error().message;
    for (const auto& [label, marker] : s.truth) EXPECT_EQ(r->marker_of_label.at(label), marker) << label;
    EXPECT_EQ(r->labels_by_continuity, window > 0 ? 1u : 0u) << "window " << window;
  }
}

TEST(MarkerLabelling, RefusesBadInitialMatches) {
  const Scene s = make_scene();
  // Marker 12 is hidden in the first frame: its label cannot be matched there.
  auto r = label_markers(s.rest, s.mesh.triangles, s.markers, s.frames, {{1000, 0}, {1005, 5}, {3000, 12}});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("first frame"), std::string::npos);
  EXPECT_FALSE(label_markers(s.rest, s.mesh.triangles, s.markers, s.frames, {{1000, 0}, {1005, 5}}));
  EXPECT_FALSE(label_markers(s.rest, s.mesh.triangles, s.markers, s.frames, {{1000, 0}, {1005, 0}, {1001, 1}}));
}

}  // namespace test_marker_labelling
}  // namespace proprio::stretch_array_recon
