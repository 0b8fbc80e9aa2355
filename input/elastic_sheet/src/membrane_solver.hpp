#pragma once
// The quasi-static solve shared by the sheet on a body and the flat rigs.
//
// Unknowns: per vertex its surface coordinates q (2 numbers), so a vertex
// can never leave the surface. Within one solve the surface map is linearised
// per vertex, x = x0 + J (q - q0), around the previous state; the caller
// re-evaluates the exact map afterwards, so the sheet lies on the surface
// exactly and the linearisation error (curvature x step^2, microns for the
// sub-millimetre steps between frames) is not carried from step to step. The
// linearised energy is smooth and cheap, which is what makes < 10 ms per step
// possible: the body's map is evaluated a handful of times per vertex and
// step instead of once per iteration.
//
// Method: L-BFGS whose initial inverse Hessian is the rest-state stiffness
// (2 mu h x cotangent Laplacian + the friction springs), factored once
// (sparse LDLT) -- the "quasi-Newton with a Laplacian" scheme of Liu et al.
// 2017 -- with an Armijo backtracking line search. The Laplacian handles the
// long-wavelength modes plain L-BFGS converges slowly on, so a warm-started
// step converges in a few iterations.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCholesky>

#include "proprio/elastic_sheet/membrane.hpp"

namespace proprio::elastic_sheet::detail {

struct LinearisedSurface {
  std::vector<Vec3> x0;    // exact positions at q0
  std::vector<Mat32> jacobian;
  std::vector<Vec2> q0;
};

struct SolveOutcome {
  int iterations = 0;
  double energy_j = 0.0;
  double remaining_step_m = 0.0;  // the last quasi-Newton step's largest move
  bool converged = false;
  bool line_search_failed = false;
};

class MembraneSolver {
 public:
  // pinned: vertices whose q the solve keeps; spring_stiffness: per-vertex
  // stiffness (N/m) of the springs to `spring_target` in solve().
  Status init(const Membrane& membrane, const std::vector<std::uint8_t>& pinned,
              const std::vector<double>& spring_stiffness_n_per_m);

  // Minimises membrane + springs over q (in/out, warm start). Writes the
  // linearised positions and the membrane's energy gradient at the end.
  SolveOutcome solve(const Membrane& membrane, const LinearisedSurface& surface, const std::vector<Vec3>& spring_target,
                     std::vector<Vec2>& q, int max_iterations, double tolerance_m, double max_step_m,
                     std::vector<Vec3>* membrane_gradient = nullptr);

 private:
  double evaluate(const Membrane& membrane, const LinearisedSurface& surface, const std::vector<Vec3>& spring_target,
                  const Eigen::VectorXd& q, Eigen::VectorXd* g, std::vector<Vec3>* membrane_gradient);
  void precondition(const Eigen::VectorXd& g, Eigen::VectorXd& out) const;

  std::vector<std::uint8_t> pinned_;
  std::vector<double> spring_k_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
  // Scratch, reused between calls.
  std::vector<Vec3> x_, gx_;
  mutable Eigen::MatrixXd rhs_, sol_;  // the preconditioner's right-hand side and solution
};

}  // namespace proprio::elastic_sheet::detail
