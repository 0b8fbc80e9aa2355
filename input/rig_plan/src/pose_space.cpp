#include "proprio/rig_plan/pose_space.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <sstream>
#include <utility>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

namespace proprio::rig_plan {

namespace pose_space_detail {
namespace {

// Samples come from files and plans; the thesis's largest set has 25.
constexpr std::size_t kMaxPoseSpaceSamples = 4096;
constexpr double kUnitTolerance = 1e-6;
// Barycentric slack when deciding a point lies in a triangle: shared edges
// are then found in either neighbour, and both give the same blend there.
constexpr double kInsideSlack = 1e-12;

Quat aligned(const Quat& q, const Quat& reference) {
  return q.dot(reference) < 0.0 ? Quat(-q.w(), -q.x(), -q.y(), -q.z()) : q;
}

// The libqhull_r error text goes to a memory stream so a refusal can say why
// without printing on the user's terminal.
struct MemoryStream {
  char* buffer = nullptr;
  std::size_t size = 0;
  FILE* file = nullptr;
  MemoryStream() { file = open_memstream(&buffer, &size); }
  ~MemoryStream() {
    if (file) std::fclose(file);
    std::free(buffer);
  }
  std::string text() {
    if (file) std::fflush(file);
    return buffer ? std::string(buffer, size) : std::string();
  }
};

// Delaunay triangles of 2-D points (indices into points), or an error text.
Result<std::vector<std::array<int, 3>>> delaunay(const std::vector<Vec2>& points) {
  std::vector<coordT> coordinates;
  coordinates.reserve(points.size() * 2);
  for (const Vec2& p : points) {
    coordinates.push_back(p.x());
    coordinates.push_back(p.y());
  }
  MemoryStream errors;
  qhT qh_storage;
  qhT* qh = &qh_storage;
  qh_zero(qh, errors.file);
  char flags[] = "qhull d Qt Qbb Qc Qz";
  const int exit_code = qh_new_qhull(qh, 2, static_cast<int>(points.size()), coordinates.data(), False, flags,
                                     nullptr, errors.file);
  std::vector<std::array<int, 3>> triangles;
  bool malformed = false;
  if (exit_code == 0) {
    facetT* facet = nullptr;
    FORALLfacets {
      if (facet->upperdelaunay) continue;
      std::array<int, 3> t{-1, -1, -1};
      int k = 0;
      vertexT* vertex = nullptr;
      vertexT** vertexp = nullptr;
      FOREACHvertex_(facet->vertices) {
        if (k < 3) t[static_cast<std::size_t>(k)] = qh_pointid(qh, vertex->point);
        ++k;
      }
      if (k != 3 || t[0] < 0 || t[1] < 0 || t[2] < 0) {
        malformed = true;
        continue;
      }
      triangles.push_back(t);
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int still_long = 0, total_long = 0;
  qh_memfreeshort(qh, &still_long, &total_long);
  if (exit_code != 0)
    return make_error(Errc::invalid_argument, "qhull could not triangulate the projected samples (exit " +
                                                  std::to_string(exit_code) + "): " + errors.text().substr(0, 400));
  if (malformed || triangles.empty())
    return make_error(Errc::invalid_argument, "qhull returned no usable triangle for the projected samples");
  return triangles;
}

double cross2(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

}  // namespace
}  // namespace pose_space_detail

Status PoseSpaceOptions::validate() const {
  if (!std::isfinite(identical_tolerance) || identical_tolerance < 0.0)
    return make_error(Errc::invalid_argument, "pose space: identical_tolerance must be a finite value >= 0");
  if (!std::isfinite(collinear_ratio) || collinear_ratio < 0.0 || collinear_ratio >= 1.0)
    return make_error(Errc::invalid_argument, "pose space: collinear_ratio must lie in [0, 1)");
  return {};
}

std::string PoseSpaceOptions::describe() const {
  std::ostringstream out;
  out << "pose space: 2-D PCA + Delaunay (qhull); samples are one pose below an RMS spread of "
      << identical_tolerance << ", on a line below sigma2/sigma1 = " << collinear_ratio;
  return out.str();
}

Result<PoseSpace> PoseSpace::create(std::span<const std::vector<Quat>> sample_rotations,
                                    std::span<const int> feature_nodes, const PoseSpaceOptions& options) {
  using namespace pose_space_detail;
  if (Status s = options.validate(); !s) return s.error();
  if (sample_rotations.empty())
    return make_error(Errc::invalid_argument, "pose space: no sample pose to interpolate from");
  if (sample_rotations.size() > kMaxPoseSpaceSamples)
    return make_error(Errc::invalid_argument, "pose space: " + std::to_string(sample_rotations.size()) +
                                                  " sample poses; at most " + std::to_string(kMaxPoseSpaceSamples) +
                                                  " are supported");
  const std::size_t nodes = sample_rotations[0].size();
  if (nodes == 0 || nodes > kMaxSkeletonNodes)
    return make_error(Errc::invalid_argument, "pose space: sample poses must have 1.." +
                                                  std::to_string(kMaxSkeletonNodes) + " node rotations");
  PoseSpace space;
  space.node_count_ = nodes;
  space.feature_slot_.assign(nodes, -1);
  for (std::size_t i = 0; i < sample_rotations.size(); ++i) {
    if (sample_rotations[i].size() != nodes)
      return make_error(Errc::invalid_argument, "pose space: sample pose " + std::to_string(i) + " has " +
                                                    std::to_string(sample_rotations[i].size()) +
                                                    " node rotations, sample pose 0 has " + std::to_string(nodes));
    for (std::size_t b = 0; b < nodes; ++b) {
      const Quat& q = sample_rotations[i][b];
      if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0) > kUnitTolerance)
        return make_error(Errc::invalid_argument, "pose space: sample pose " + std::to_string(i) +
                                                      ", node " + std::to_string(b) +
                                                      ": the rotation is not a finite unit quaternion");
    }
  }
  for (std::size_t k = 0; k < feature_nodes.size(); ++k) {
    const int b = feature_nodes[k];
    if (b < 0 || static_cast<std::size_t>(b) >= nodes)
      return make_error(Errc::invalid_argument, "pose space: feature node " + std::to_string(b) +
                                                    " is not a node of the " + std::to_string(nodes) + "-node rig");
    if (space.feature_slot_[static_cast<std::size_t>(b)] >= 0)
      return make_error(Errc::invalid_argument,
                        "pose space: feature node " + std::to_string(b) + " is listed twice");
    space.feature_slot_[static_cast<std::size_t>(b)] = static_cast<int>(k);
  }
  space.feature_nodes_.assign(feature_nodes.begin(), feature_nodes.end());
  space.samples_.reserve(sample_rotations.size());
  for (const auto& s : sample_rotations) {
    std::vector<Quat> normalized(s.size());
    for (std::size_t b = 0; b < s.size(); ++b) normalized[b] = s[b].normalized();
    space.samples_.push_back(std::move(normalized));
  }

  const std::size_t n = space.samples_.size();
  const std::size_t k = space.feature_nodes_.size();
  space.projected_.assign(n, Vec2::Zero());
  space.mean_ = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(4 * k));
  space.basis_ = Eigen::Matrix<double, Eigen::Dynamic, 2>::Zero(static_cast<Eigen::Index>(4 * k), 2);
  space.reference_.resize(k);
  for (std::size_t j = 0; j < k; ++j)
    space.reference_[j] = space.samples_[0][static_cast<std::size_t>(space.feature_nodes_[j])];
  if (n < 2 || k == 0) {
    space.mode_ = Mode::single;
    return space;
  }

  Eigen::MatrixXd F(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(4 * k));
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = 0; j < k; ++j) {
      const Quat q = aligned(space.samples_[i][static_cast<std::size_t>(space.feature_nodes_[j])], space.reference_[j]);
      F.block<1, 4>(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(4 * j)) << q.w(), q.x(), q.y(), q.z();
    }
  space.mean_ = F.colwise().mean().transpose();
  F.rowwise() -= space.mean_.transpose();
  Eigen::BDCSVD<Eigen::MatrixXd> svd(F, Eigen::ComputeThinV);
  const Eigen::VectorXd& sigma = svd.singularValues();
  const double sigma1 = sigma.size() > 0 ? sigma(0) : 0.0;
  const double sigma2 = sigma.size() > 1 ? sigma(1) : 0.0;
  if (sigma1 / std::sqrt(static_cast<double>(n)) <= options.identical_tolerance) {
    space.mode_ = Mode::single;
    return space;
  }
  space.basis_.col(0) = svd.matrixV().col(0);
  const bool collinear = n == 2 || sigma2 <= options.collinear_ratio * sigma1;
  if (!collinear) space.basis_.col(1) = svd.matrixV().col(1);
  for (std::size_t i = 0; i < n; ++i)
    space.projected_[i] = space.basis_.transpose() * F.row(static_cast<Eigen::Index>(i)).transpose();

  if (!collinear) {
    auto triangles = delaunay(space.projected_);
    if (triangles) {
      // Counter-clockwise, and without the slivers Qt may leave (zero area).
      double extent = 0.0;
      for (const Vec2& p : space.projected_) extent = std::max(extent, p.cwiseAbs().maxCoeff());
      const double min_area = 1e-14 * extent * extent;
      for (std::array<int, 3> t : *triangles) {
        const Vec2& a = space.projected_[static_cast<std::size_t>(t[0])];
        const double area = cross2(space.projected_[static_cast<std::size_t>(t[1])] - a,
                                   space.projected_[static_cast<std::size_t>(t[2])] - a);
        if (std::abs(area) <= min_area) continue;
        if (area < 0.0) std::swap(t[1], t[2]);
        space.triangles_.push_back(t);
      }
    }
    if (!space.triangles_.empty()) {
      std::map<std::pair<int, int>, std::pair<int, int>> edge_use;  // (min,max) -> (count, triangle)
      for (std::size_t t = 0; t < space.triangles_.size(); ++t)
        for (int e = 0; e < 3; ++e) {
          const int a = space.triangles_[t][static_cast<std::size_t>(e)];
          const int b = space.triangles_[t][static_cast<std::size_t>((e + 1) % 3)];
          auto& use = edge_use[{std::min(a, b), std::max(a, b)}];
          ++use.first;
          use.second = static_cast<int>(t);
        }
      for (const auto& [edge, use] : edge_use)
        if (use.first == 1) space.hull_.push_back({edge.first, edge.second, use.second});
      space.tri_inverse_.reserve(space.triangles_.size());
      for (const auto& t : space.triangles_) {
        const Vec2& a = space.projected_[static_cast<std::size_t>(t[0])];
        Eigen::Matrix2d T;
        T.col(0) = space.projected_[static_cast<std::size_t>(t[1])] - a;
        T.col(1) = space.projected_[static_cast<std::size_t>(t[2])] - a;
        space.tri_inverse_.push_back(T.inverse());
      }
      space.mode_ = Mode::triangulation;
      return space;
    }
    // qhull refused (or left only slivers): fall back to the first direction.
    space.basis_.col(1).setZero();
    for (Vec2& p : space.projected_) p.y() = 0.0;
  }

  space.mode_ = Mode::segment;
  std::vector<int> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return space.projected_[static_cast<std::size_t>(a)].x() < space.projected_[static_cast<std::size_t>(b)].x();
  });
  const double range = space.projected_[static_cast<std::size_t>(order.back())].x() -
                       space.projected_[static_cast<std::size_t>(order.front())].x();
  for (int i : order) {
    if (!space.segment_order_.empty() &&
        space.projected_[static_cast<std::size_t>(i)].x() -
                space.projected_[static_cast<std::size_t>(space.segment_order_.back())].x() <=
            1e-12 * range)
      continue;  // coincident with the previous one: one sample stands for both
    space.segment_order_.push_back(i);
  }
  if (space.segment_order_.size() < 2) space.mode_ = Mode::single;
  return space;
}

Vec2 PoseSpace::project(std::span<const Quat> q_parent_node, std::span<const std::uint8_t> feature_known) const {
  using namespace pose_space_detail;
  if (mode_ == Mode::single) return Vec2::Zero();
  // Least squares over the known features: A x = B_known^T (f - mean).
  Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
  Vec2 rhs = Vec2::Zero();
  for (std::size_t j = 0; j < feature_nodes_.size(); ++j) {
    if (!feature_known.empty() && !feature_known[j]) continue;
    const Quat q = aligned(q_parent_node[static_cast<std::size_t>(feature_nodes_[j])].normalized(), reference_[j]);
    const Eigen::Vector4d f(q.w(), q.x(), q.y(), q.z());
    const auto B = basis_.block<4, 2>(static_cast<Eigen::Index>(4 * j), 0);
    A.noalias() += B.transpose() * B;
    rhs.noalias() += B.transpose() * (f - mean_.segment<4>(static_cast<Eigen::Index>(4 * j)));
  }
  // Directions the known features do not see stay at the mean (0): a
  // pseudo-inverse through the 2x2 eigen-decomposition.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(A);
  const Eigen::Vector2d lambda = eig.eigenvalues();
  const double largest = std::max(lambda(1), 0.0);
  Vec2 x = Vec2::Zero();
  for (int c = 0; c < 2; ++c)
    if (largest > 0.0 && lambda(c) > 1e-9 * std::max(largest, 1.0) && lambda(c) > 1e-12) {
      const Vec2 v = eig.eigenvectors().col(c);
      x += v * (v.dot(rhs) / lambda(c));
    }
  if (mode_ == Mode::segment) x.y() = 0.0;
  return x;
}

PoseSpaceWeights PoseSpace::segment_weights(double x) const {
  PoseSpaceWeights w;
  const auto at = [&](std::size_t i) { return projected_[static_cast<std::size_t>(segment_order_[i])].x(); };
  const std::size_t m = segment_order_.size();
  if (x <= at(0)) {
    w.sample = {segment_order_[0], segment_order_[0], segment_order_[0]};
    w.clamped = x < at(0);
    return w;
  }
  if (x >= at(m - 1)) {
    w.sample = {segment_order_[m - 1], segment_order_[m - 1], segment_order_[m - 1]};
    w.clamped = x > at(m - 1);
    return w;
  }
  // Few samples: a binary search is not worth its branches, but m may be 4096.
  std::size_t lo = 0, hi = m - 1;
  while (hi - lo > 1) {
    const std::size_t mid = (lo + hi) / 2;
    (at(mid) <= x ? lo : hi) = mid;
  }
  const double t = (x - at(lo)) / (at(hi) - at(lo));
  w.sample = {segment_order_[lo], segment_order_[hi], segment_order_[hi]};
  w.weight = {1.0 - t, t, 0.0};
  w.count = 2;
  return w;
}

PoseSpaceWeights PoseSpace::clamp_to_hull(const Vec2& point) const {
  PoseSpaceWeights w;
  double best = std::numeric_limits<double>::infinity();
  for (const HullEdge& e : hull_) {
    const Vec2& a = projected_[static_cast<std::size_t>(e.a)];
    const Vec2& b = projected_[static_cast<std::size_t>(e.b)];
    const Vec2 ab = b - a;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0.0 ? std::clamp((point - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
    const double d2 = (a + t * ab - point).squaredNorm();
    if (d2 < best) {
      best = d2;
      w.sample = {e.a, e.b, e.b};
      w.weight = {1.0 - t, t, 0.0};
      w.count = 2;
    }
  }
  w.clamped = true;
  return w;
}

PoseSpaceWeights PoseSpace::weights_at(const Vec2& point) const {
  PoseSpaceWeights w;
  switch (mode_) {
    case Mode::single:
      return w;
    case Mode::segment:
      return segment_weights(point.x());
    case Mode::triangulation:
      break;
  }
  for (std::size_t t = 0; t < triangles_.size(); ++t) {
    const auto& tri = triangles_[t];
    const Vec2 l = tri_inverse_[t] * (point - projected_[static_cast<std::size_t>(tri[0])]);
    const double l0 = 1.0 - l.x() - l.y();
    if (l0 >= -pose_space_detail::kInsideSlack && l.x() >= -pose_space_detail::kInsideSlack && l.y() >= -pose_space_detail::kInsideSlack) {
      std::array<double, 3> bary{std::max(l0, 0.0), std::max(l.x(), 0.0), std::max(l.y(), 0.0)};
      const double sum = bary[0] + bary[1] + bary[2];
      w.sample = tri;
      w.weight = {bary[0] / sum, bary[1] / sum, bary[2] / sum};
      w.count = 3;
      return w;
    }
  }
  return clamp_to_hull(point);
}

Quat PoseSpace::blend_node(const PoseSpaceWeights& weights, std::size_t node) const {
  const Quat& q0 = samples_[static_cast<std::size_t>(weights.sample[0])][node];
  if (weights.count <= 1) return q0;
  const Quat& q1 = samples_[static_cast<std::size_t>(weights.sample[1])][node];
  const double w01 = weights.weight[0] + weights.weight[1];
  const double t01 = w01 > 0.0 ? weights.weight[1] / w01 : 1.0;
  if (weights.count == 2) return slerp(q0, q1, t01);
  const Quat& q2 = samples_[static_cast<std::size_t>(weights.sample[2])][node];
  if (w01 <= 1e-15) return q2;
  return slerp(slerp(q0, q1, t01), q2, weights.weight[2]);
}

void PoseSpace::blend(const PoseSpaceWeights& weights, std::span<Quat> q_parent_node,
                      std::span<const std::uint8_t> write_mask) const {
  const std::size_t nodes = std::min(node_count_, q_parent_node.size());
  for (std::size_t b = 0; b < nodes; ++b)
    if (write_mask.empty() || write_mask[b]) q_parent_node[b] = blend_node(weights, b);
}

PoseSpaceWeights PoseSpace::interpolate(std::span<Quat> q_parent_node,
                                        std::span<const std::uint8_t> feature_known) const {
  const PoseSpaceWeights w = weights_at(project(q_parent_node, feature_known));
  const std::size_t nodes = std::min(node_count_, q_parent_node.size());
  for (std::size_t b = 0; b < nodes; ++b) {
    const int slot = feature_slot_[b];
    if (slot >= 0 && (feature_known.empty() || feature_known[static_cast<std::size_t>(slot)])) continue;
    q_parent_node[b] = blend_node(w, b);
  }
  return w;
}

}  // namespace proprio::rig_plan
