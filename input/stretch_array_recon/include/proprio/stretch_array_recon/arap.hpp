#pragma once
// As-rigid-as-possible surface deformation (Sorkine & Alexa 2007) with
// positional constraints, and the Procrustes (Kabsch) fit.
//
// The thesis deforms S^0 with Wang et al. 2015 (a nonlinear elastic
// deformation driven by sparse positional constraints). ARAP is the accepted
// stand-in here: the same input (rest mesh + constrained vertices), the same
// bias (locally rigid, smooth in between), and a solver that is a prefactored
// sparse system plus per-vertex 3x3 SVDs, fast enough for every frame.
//
// Energy: sum_i sum_{j in N(i)} w_ij |(p_i - p_j) - R_i (p0_i - p0_j)|^2 with
// cotangent weights w_ij = (cot a + cot b) / 2 (clamped to a small positive
// value, so obtuse boundary triangles cannot make the system indefinite).
// Local step: R_i from the SVD of the covariance of its edges. Global step:
// L_ff x_f = b_f - L_fc x_c, L_ff prefactored (SimplicialLDLT) and cached per
// constraint set (a small LRU: the labelling alternates between sets).
//
// Threads: one ArapDeformer per thread (solve() mutates its caches).
#include <array>
#include <cstdint>
#include <list>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "proprio/core/result.hpp"

namespace proprio::stretch_array_recon {

// Rigid transform (R, t) minimising sum |R a_i + t - b_i|^2 (Kabsch; no
// scale, det R = +1). Needs >= 3 pairs not on one line.
Result<Eigen::Isometry3d> fit_rigid(const Eigen::MatrixX3d& from, const Eigen::MatrixX3d& to);

struct ArapOptions {
  int max_iterations = 10;
  // Stop when no vertex moved more than this in an iteration (metres).
  double tolerance_m = 1e-5;
  std::size_t factor_cache_size = 16;  // constraint sets kept prefactored
  Status validate() const;
  std::string describe() const;
};

struct ArapStats {
  int iterations = 0;
  double last_step_m = 0.0;  // largest vertex move in the last iteration
  bool refactored = false;   // the constraint set was not cached
};

class ArapDeformer {
 public:
  // rest_m: n x 3 rest vertices; triangles index them.
  static Result<ArapDeformer> create(const Eigen::MatrixX3d& rest_m,
                                     const std::vector<std::array<std::uint32_t, 3>>& triangles,
                                     const ArapOptions& options = {});
  ArapDeformer(ArapDeformer&&) noexcept;
  ArapDeformer& operator=(ArapDeformer&&) noexcept;
  ~ArapDeformer();

  // Deforms the rest shape so vertex constrained[k] sits at targets_m.row(k).
  // `vertices_m` is the initial guess on entry (warm start: last frame's
  // result; rows must be n) and the result on return. With an empty or wrong
  // sized guess it starts from the rest shape moved rigidly onto the
  // constraints (>= 3 of them) or translated (1-2).
  Status solve(const std::vector<std::uint32_t>& constrained, const Eigen::MatrixX3d& targets_m,
               Eigen::MatrixX3d& vertices_m, ArapStats* stats = nullptr);

  // The ARAP energy of `vertices_m` (with the best rotations), for tests.
  double energy(const Eigen::MatrixX3d& vertices_m) const;

  const Eigen::MatrixX3d& rest() const noexcept;
  std::size_t vertex_count() const noexcept;
  std::size_t cached_factorisations() const noexcept;

 private:
  struct Impl;
  explicit ArapDeformer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace proprio::stretch_array_recon
