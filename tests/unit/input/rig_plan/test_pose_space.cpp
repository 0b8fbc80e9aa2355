#include "proprio/rig_plan/pose_space.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <utility>
#include <vector>

#include "unit/input/rig_plan/runtime_fixtures.hpp"

namespace proprio::rig_plan::pose_space_tests {
namespace {

namespace fx = test_fixtures;

double max_angle(const std::vector<Quat>& a, const std::vector<Quat>& b) {
  double m = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, angle_between(a[i], b[i]));
  return m;
}

std::vector<Quat> blend_at(const PoseSpace& space, const Vec2& p) {
  std::vector<Quat> q(space.node_count(), Quat::Identity());
  space.blend(space.weights_at(p), q);
  return q;
}

// Boundary edges (used by one triangle) of the triangulation.
std::vector<std::pair<int, int>> hull_edges(const PoseSpace& space) {
  std::map<std::pair<int, int>, int> use;
  for (const auto& t : space.triangles())
    for (int e = 0; e < 3; ++e) {
      const int a = t[static_cast<std::size_t>(e)], b = t[static_cast<std::size_t>((e + 1) % 3)];
      ++use[{std::min(a, b), std::max(a, b)}];
    }
  std::vector<std::pair<int, int>> out;
  for (const auto& [e, n] : use)
    if (n == 1) out.push_back(e);
  return out;
}

const std::vector<int> kFeatures = {1, 3, 5};

TEST(PoseSpace, ReproducesEachSampleAtItsOwnProjection) {
  const RigInput input = fx::small_input(10);
  const auto rotations = fx::rotations_of(input);
  auto space = PoseSpace::create(rotations, kFeatures);
  ASSERT_TRUE(space.ok()) << space.error().message;
  ASSERT_EQ(space->mode(), PoseSpace::Mode::triangulation);
  EXPECT_GE(space->triangles().size(), 1u);
  for (std::size_t i = 0; i < rotations.size(); ++i) {
    const Vec2 p = space->project(rotations[i]);
    EXPECT_LT((p - space->projected_samples()[i]).norm(), 1e-12) << "sample " << i;
    std::vector<Quat> q = rotations[i];
    for (int b : std::vector<int>{0, 2, 4, 6, 7, 8}) q[static_cast<std::size_t>(b)] = Quat::Identity();
    const PoseSpaceWeights w = space->interpolate(q);
    EXPECT_FALSE(w.clamped);
    EXPECT_LT(max_angle(q, rotations[i]), 1e-9) << "sample " << i;
  }
}

TEST(PoseSpace, ManySamplesTriangulateAndReproduce) {
  const RigInput input = fx::small_input(300, 77);
  const auto rotations = fx::rotations_of(input);
  const std::vector<int> features = {1, 2, 3, 5, 7, 6};
  auto space = PoseSpace::create(rotations, features);
  ASSERT_TRUE(space.ok()) << space.error().message;
  ASSERT_EQ(space->mode(), PoseSpace::Mode::triangulation);
  // Euler: a triangulation of n points with h on the hull has 2n - h - 2 triangles.
  EXPECT_GT(space->triangles().size(), 300u);
  for (std::size_t i = 0; i < rotations.size(); i += 7) {
    const PoseSpaceWeights w = space->weights_at(space->projected_samples()[i]);
    double sum = 0.0, own = 0.0;
    for (int k = 0; k < w.count; ++k) {
      sum += w.weight[static_cast<std::size_t>(k)];
      if (w.sample[static_cast<std::size_t>(k)] == static_cast<int>(i)) own += w.weight[static_cast<std::size_t>(k)];
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_NEAR(own, 1.0, 1e-9) << "sample " << i;
  }
}

TEST(PoseSpace, IsContinuousAcrossTriangleEdges) {
  const RigInput input = fx::small_input(12, 5);
  auto space = PoseSpace::create(fx::rotations_of(input), kFeatures);
  ASSERT_TRUE(space.ok()) << space.error().message;
  ASSERT_EQ(space->mode(), PoseSpace::Mode::triangulation);
  const auto& P = space->projected_samples();
  int interior_edges = 0;
  std::map<std::pair<int, int>, int> use;
  for (const auto& t : space->triangles())
    for (int e = 0; e < 3; ++e) {
      const int a = t[static_cast<std::size_t>(e)], b = t[static_cast<std::size_t>((e + 1) % 3)];
      ++use[{std::min(a, b), std::max(a, b)}];
    }
  for (const auto& [e, n] : use) {
    const Vec2 a = P[static_cast<std::size_t>(e.first)], b = P[static_cast<std::size_t>(e.second)];
    for (double t : {0.25, 0.5, 0.8}) {
      const Vec2 m = a + t * (b - a);
      const Vec2 normal = Vec2(-(b - a).y(), (b - a).x()).normalized();
      const double eps = 1e-7;
      const auto left = blend_at(*space, m + eps * normal);
      const auto right = blend_at(*space, m - eps * normal);
      const auto on = blend_at(*space, m);
      // Both sides (a different triangle, or outside the hull) agree with the edge.
      EXPECT_LT(max_angle(left, on), 1e-4);
      EXPECT_LT(max_angle(right, on), 1e-4);
      // On an edge the blend is the slerp of its two samples.
      for (std::size_t node = 0; node < on.size(); ++node) {
        const Quat expected = slerp(input.samples[static_cast<std::size_t>(e.first)].q_parent_node[node],
                                    input.samples[static_cast<std::size_t>(e.second)].q_parent_node[node], t);
        EXPECT_LT(angle_between(on[node], expected), 1e-7);
      }
    }
    interior_edges += n == 2 ? 1 : 0;
  }
  EXPECT_GT(interior_edges, 0);
}

TEST(PoseSpace, SmallStepsGiveSmallChanges) {
  const RigInput input = fx::small_input(12, 9);
  auto space = PoseSpace::create(fx::rotations_of(input), kFeatures);
  ASSERT_TRUE(space.ok());
  Vec2 lo = space->projected_samples()[0], hi = lo;
  for (const Vec2& p : space->projected_samples()) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  // A walk across (and beyond) the whole space in small steps never jumps.
  const Vec2 from = lo - 0.3 * (hi - lo), to = hi + 0.3 * (hi - lo);
  const int steps = 4000;
  auto previous = blend_at(*space, from);
  double largest = 0.0;
  for (int k = 1; k <= steps; ++k) {
    const auto q = blend_at(*space, from + (to - from) * (static_cast<double>(k) / steps));
    largest = std::max(largest, max_angle(q, previous));
    previous = q;
  }
  // Sample rotations differ by up to ~1.8 rad; a step is 1/4000 of a
  // path 1.6 times the span: a jump would be far above this.
  EXPECT_LT(largest, 0.05);
}

TEST(PoseSpace, ClampsOutsideTheHullToTheNearestHullPoint) {
  const RigInput input = fx::small_input(10);
  auto space = PoseSpace::create(fx::rotations_of(input), kFeatures);
  ASSERT_TRUE(space.ok());
  const auto edges = hull_edges(*space);
  ASSERT_GE(edges.size(), 3u);
  const auto& P = space->projected_samples();
  Vec2 centroid = Vec2::Zero();
  for (const Vec2& p : P) centroid += p;
  centroid /= static_cast<double>(P.size());
  for (double angle = 0.0; angle < 2 * M_PI; angle += 0.37) {
    const Vec2 far = centroid + 50.0 * Vec2(std::cos(angle), std::sin(angle));
    // Nearest boundary point, found independently.
    double best = 1e300;
    Vec2 nearest = Vec2::Zero();
    for (const auto& [a, b] : edges) {
      const Vec2 A = P[static_cast<std::size_t>(a)], B = P[static_cast<std::size_t>(b)];
      const double t = std::clamp((far - A).dot(B - A) / (B - A).squaredNorm(), 0.0, 1.0);
      const Vec2 c = A + t * (B - A);
      if ((c - far).norm() < best) {
        best = (c - far).norm();
        nearest = c;
      }
    }
    const PoseSpaceWeights w = space->weights_at(far);
    EXPECT_TRUE(w.clamped);
    EXPECT_FALSE(space->weights_at(nearest + 1e-9 * (centroid - nearest)).clamped);
    EXPECT_LT(max_angle(blend_at(*space, far), blend_at(*space, nearest)), 1e-7);
  }
  EXPECT_FALSE(space->weights_at(centroid).clamped);
}

TEST(PoseSpace, UnknownFeaturesAreLeftOutOfTheProjection) {
  const RigInput input = fx::small_input(10);
  const auto rotations = fx::rotations_of(input);
  auto space = PoseSpace::create(rotations, kFeatures);
  ASSERT_TRUE(space.ok());
  // No feature known: the samples' mean (0 in PCA coordinates).
  const std::vector<std::uint8_t> none(3, 0);
  EXPECT_LT(space->project(rotations[2], none).norm(), 1e-12);
  // Garbage in the unknown feature's slot must not matter.
  std::vector<Quat> q = rotations[4];
  const std::vector<std::uint8_t> two_known = {1, 0, 1};
  const Vec2 p = space->project(q, two_known);
  q[3] = so3_exp(Vec3(2.0, -1.0, 0.5));
  EXPECT_LT((space->project(q, two_known) - p).norm(), 1e-12);
  // The unknown feature node itself is filled by the blend.
  const PoseSpaceWeights w = space->interpolate(q, two_known);
  std::vector<Quat> expected(space->node_count(), Quat::Identity());
  space->blend(w, expected);
  EXPECT_LT(angle_between(q[3], expected[3]), 1e-12);
  EXPECT_LT(angle_between(q[1], rotations[4][1]), 1e-15);  // known features untouched
}

TEST(PoseSpace, QuaternionSignsDoNotMoveThePoint) {
  const RigInput input = fx::small_input(10);
  const auto rotations = fx::rotations_of(input);
  auto space = PoseSpace::create(rotations, kFeatures);
  ASSERT_TRUE(space.ok());
  std::vector<Quat> q = rotations[6];
  for (int b : kFeatures) q[static_cast<std::size_t>(b)].coeffs() *= -1.0;
  EXPECT_LT((space->project(q) - space->projected_samples()[6]).norm(), 1e-12);
}

TEST(PoseSpace, OneSampleOrIdenticalSamplesGiveTheFirstSample) {
  const RigInput input = fx::small_input(4);
  auto rotations = fx::rotations_of(input);
  auto one = PoseSpace::create(std::span(rotations).first(1), kFeatures);
  ASSERT_TRUE(one.ok());
  EXPECT_EQ(one->mode(), PoseSpace::Mode::single);
  std::vector<Quat> q(rotations[0].size(), Quat::Identity());
  one->interpolate(q);
  EXPECT_LT(angle_between(q[2], rotations[0][2]), 1e-12);

  // Same features, different other nodes: the features cannot tell them apart.
  for (auto& r : rotations)
    for (int b : kFeatures) r[static_cast<std::size_t>(b)] = rotations[0][static_cast<std::size_t>(b)];
  auto same = PoseSpace::create(rotations, kFeatures);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(same->mode(), PoseSpace::Mode::single);
  std::vector<Quat> r = rotations[3];
  same->interpolate(r);
  EXPECT_LT(angle_between(r[2], rotations[0][2]), 1e-12);

  auto no_features = PoseSpace::create(fx::rotations_of(input), {});
  ASSERT_TRUE(no_features.ok());
  EXPECT_EQ(no_features->mode(), PoseSpace::Mode::single);
}

TEST(PoseSpace, TwoSamplesOrCollinearProjectionsInterpolateAlongALine) {
  const RigInput input = fx::small_input(4);
  auto rotations = fx::rotations_of(input);
  auto two = PoseSpace::create(std::span(rotations).first(2), kFeatures);
  ASSERT_TRUE(two.ok());
  EXPECT_EQ(two->mode(), PoseSpace::Mode::segment);
  // Each end reproduces its sample; the middle of the segment is the slerp.
  for (int i = 0; i < 2; ++i) {
    std::vector<Quat> q = rotations[static_cast<std::size_t>(i)];
    two->interpolate(q);
    EXPECT_LT(max_angle(q, rotations[static_cast<std::size_t>(i)]), 1e-9);
  }
  const Vec2 mid = 0.5 * (two->projected_samples()[0] + two->projected_samples()[1]);
  const auto q_mid = blend_at(*two, mid);
  EXPECT_LT(angle_between(q_mid[8], slerp(rotations[0][8], rotations[1][8], 0.5)), 1e-9);
  // Beyond an end: that end's sample.
  const Vec2 beyond = two->projected_samples()[0] + 5.0 * (two->projected_samples()[0] - mid);
  EXPECT_TRUE(two->weights_at(beyond).clamped);
  EXPECT_LT(max_angle(blend_at(*two, beyond), rotations[0]), 1e-12);

  // Four samples that are two poses twice: the projections are two points.
  std::vector<std::vector<Quat>> doubled = {rotations[0], rotations[1], rotations[0], rotations[1]};
  auto line = PoseSpace::create(doubled, kFeatures);
  ASSERT_TRUE(line.ok());
  EXPECT_EQ(line->mode(), PoseSpace::Mode::segment);
  std::vector<Quat> q = rotations[1];
  line->interpolate(q);
  EXPECT_LT(max_angle(q, rotations[1]), 1e-9);
}

TEST(PoseSpace, ThreeSamplesMakeOneTriangle) {
  const RigInput input = fx::small_input(3, 12);
  const auto rotations = fx::rotations_of(input);
  auto space = PoseSpace::create(rotations, kFeatures);
  ASSERT_TRUE(space.ok()) << space.error().message;
  ASSERT_EQ(space->mode(), PoseSpace::Mode::triangulation);
  ASSERT_EQ(space->triangles().size(), 1u);
  for (std::size_t i = 0; i < 3; ++i) {
    std::vector<Quat> q = rotations[i];
    space->interpolate(q);
    EXPECT_LT(max_angle(q, rotations[i]), 1e-9);
  }
  // The centroid blends all three.
  Vec2 c = Vec2::Zero();
  for (const Vec2& p : space->projected_samples()) c += p / 3.0;
  const PoseSpaceWeights w = space->weights_at(c);
  EXPECT_EQ(w.count, 3);
  for (double x : w.weight) EXPECT_NEAR(x, 1.0 / 3.0, 1e-9);
}

TEST(PoseSpace, RefusesMalformedInput) {
  const RigInput input = fx::small_input(4);
  auto rotations = fx::rotations_of(input);
  EXPECT_FALSE(PoseSpace::create({}, kFeatures).ok());
  const std::vector<int> out_of_range = {1, 9};
  EXPECT_FALSE(PoseSpace::create(rotations, out_of_range).ok());
  const std::vector<int> twice = {1, 1};
  EXPECT_FALSE(PoseSpace::create(rotations, twice).ok());
  auto short_sample = rotations;
  short_sample[2].pop_back();
  EXPECT_FALSE(PoseSpace::create(short_sample, kFeatures).ok());
  auto not_unit = rotations;
  not_unit[1][4].coeffs() *= 2.0;
  auto r = PoseSpace::create(not_unit, kFeatures);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("unit"), std::string::npos);
  PoseSpaceOptions bad;
  bad.collinear_ratio = 2.0;
  EXPECT_FALSE(bad.validate().ok());
  EXPECT_FALSE(PoseSpace::create(rotations, kFeatures, bad).ok());
  EXPECT_FALSE(PoseSpaceOptions{}.describe().empty());
}

}  // namespace
}  // namespace proprio::rig_plan::pose_space_tests
