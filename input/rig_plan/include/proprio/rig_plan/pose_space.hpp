#pragma once
// Real-time pose-space interpolation (thesis §3.2.2, after Buck et al. 2000):
// the rig nodes the device does not drive take rotations blended from the
// sample poses, chosen by where the driven nodes put the pose in a 2-D space.
//
// Setup (once):
//  - the feature of a pose is its feature nodes' (the driven nodes') local
//    rotations stacked as 4-vectors (w, x, y, z); each quaternion's sign is
//    flipped to the hemisphere of a per-node reference (sample 0's rotation),
//    so q and -q give one feature. A pose whose rotation turns more than 180
//    deg away from the reference flips sign there: the only discontinuity.
//  - PCA of the samples' features; the two largest principal directions span
//    the pose space; each sample projects to a point there.
//  - a Delaunay triangulation of the projected samples (qhull, libqhull_r,
//    options "d Qt Qbb Qc Qz"); samples whose projections coincide (to qhull's
//    tolerance) keep one of them as the vertex.
// Per frame (no allocation, const: thread-safe):
//  - project: least squares on the known features only (a missing joint's
//    feature is left out; with every feature known this is the orthogonal
//    PCA projection; with none known the point is the samples' mean);
//  - locate the triangle, barycentric weights; a point outside the hull is
//    moved to the nearest point of the hull's boundary first (clamped);
//  - blend: q = slerp(slerp(q_a, q_b, w_b / (w_a + w_b)), q_c, w_c). This is
//    exactly slerp on an edge (one weight 0) and q_a at a vertex, so the
//    interpolant is continuous across edges and reproduces the samples.
//
// Degenerate sample sets fall back (mode()):
//  - single: fewer than 2 samples, no feature node, or every sample's feature
//    within `identical_tolerance` of the mean: the blend is sample 0.
//  - segment: 2 samples, or the second principal spread below
//    `collinear_ratio` times the first (collinear projections), or qhull
//    refused the points: 1-D interpolation along the first principal
//    direction between neighbouring samples, clamped at the ends.
//  - triangulation: the general case above.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/skeleton.hpp"

namespace proprio::rig_plan {

struct PoseSpaceOptions {
  // Below this RMS feature spread (quaternion units) the samples are one pose.
  double identical_tolerance = 1e-9;
  // sigma_2 / sigma_1 below this: the projections lie on a line.
  double collinear_ratio = 1e-6;
  Status validate() const;
  std::string describe() const;
};

using Vec2 = Eigen::Vector2d;

// Which samples blend, with which weights (count of them used, 1..3).
struct PoseSpaceWeights {
  std::array<int, 3> sample{0, 0, 0};
  std::array<double, 3> weight{1.0, 0.0, 0.0};
  int count = 1;
  bool clamped = false;  // the point lay outside the hull (or beyond a segment's end)
};

class PoseSpace {
 public:
  enum class Mode { single, segment, triangulation };

  // sample_rotations[i][b]: local rotation of node b in sample i (unit).
  // feature_nodes: distinct node indices whose rotations place a pose.
  static Result<PoseSpace> create(std::span<const std::vector<Quat>> sample_rotations,
                                  std::span<const int> feature_nodes, const PoseSpaceOptions& options = {});

  Mode mode() const { return mode_; }
  std::size_t sample_count() const { return samples_.size(); }
  std::size_t node_count() const { return node_count_; }
  const std::vector<int>& feature_nodes() const { return feature_nodes_; }
  // Sample i's point in the pose space (the segment mode uses x only).
  const std::vector<Vec2>& projected_samples() const { return projected_; }
  // Triangles as sample indices (triangulation mode), counter-clockwise.
  const std::vector<std::array<int, 3>>& triangles() const { return triangles_; }

  // q_parent_node: one rotation per node (only the feature nodes are read).
  // feature_known: empty (all known) or one flag per feature node.
  Vec2 project(std::span<const Quat> q_parent_node, std::span<const std::uint8_t> feature_known = {}) const;
  PoseSpaceWeights weights_at(const Vec2& point) const;
  // Writes the blend of the weighted samples into q_parent_node for every
  // node whose write_mask entry is non-zero (empty mask: every node).
  void blend(const PoseSpaceWeights& weights, std::span<Quat> q_parent_node,
             std::span<const std::uint8_t> write_mask = {}) const;
  // project + weights_at + blend of the nodes that are not known features.
  PoseSpaceWeights interpolate(std::span<Quat> q_parent_node, std::span<const std::uint8_t> feature_known = {}) const;

 private:
  struct HullEdge {
    int a = 0, b = 0;   // sample indices
    int triangle = 0;   // the triangle it bounds
  };
  PoseSpaceWeights clamp_to_hull(const Vec2& point) const;
  PoseSpaceWeights segment_weights(double x) const;
  Quat blend_node(const PoseSpaceWeights& weights, std::size_t node) const;

  Mode mode_ = Mode::single;
  std::size_t node_count_ = 0;
  std::vector<int> feature_nodes_;
  std::vector<Quat> reference_;              // per feature node
  Eigen::VectorXd mean_;                     // 4 * features
  Eigen::Matrix<double, Eigen::Dynamic, 2> basis_;  // orthonormal columns
  std::vector<std::vector<Quat>> samples_;
  std::vector<Vec2> projected_;
  std::vector<std::array<int, 3>> triangles_;
  std::vector<HullEdge> hull_;
  std::vector<int> segment_order_;           // samples along the segment, by x, coincident ones dropped
  std::vector<Eigen::Matrix2d> tri_inverse_;  // per triangle: (b - a, c - a)^-1
  std::vector<int> feature_slot_;            // per node: index into feature_nodes_, -1
};

}  // namespace proprio::rig_plan
