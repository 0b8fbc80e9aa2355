#pragma once
// Flat scenarios without a body (issue 30's two accuracy targets):
//   uniaxial:      a 15 x 50 mm cell clamped at its short ends and pulled
//                  along its length by a linear stage; the long sides are
//                  free, so the width contracts (to 1/sqrt(lambda) away from
//                  the clamps for the incompressible membrane);
//   string-pulled: a flat sheet held at its frame (its outline) with a few
//                  clipped points pulled in-plane by strings over time, giving
//                  spatially varying stretch (the thesis's Fig. 4.19).
// Positions are in the sheet plane (z = 0), same order as the mesh's vertices.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/elastic_sheet/body_proxy.hpp"
#include "proprio/elastic_sheet/membrane.hpp"

namespace proprio::elastic_sheet {

namespace detail {
class MembraneSolver;
}

struct FlatSheetOptions {
  MembraneMaterial material;
  int max_iterations = 3000;    // per solve; the flat rigs are offline ground truth
  double tolerance_m = 1.0e-8;  // the largest remaining quasi-Newton move
  double max_step_m = 0.005;
  Status validate() const;
};

struct FlatSolveReport {
  int iterations = 0;
  bool converged = false;
  double energy_j = 0.0;
};

// A flat sheet with some vertices held at prescribed in-plane positions.
class FlatSheet {
 public:
  static Result<FlatSheet> create(SheetMesh mesh, std::vector<std::uint32_t> held_vertices,
                                  const FlatSheetOptions& options);
  FlatSheet(FlatSheet&&) noexcept;
  FlatSheet& operator=(FlatSheet&&) noexcept;
  ~FlatSheet();

  // Puts the held vertices at these positions (same order as held_vertices)
  // and solves the equilibrium from the current state.
  Result<FlatSolveReport> solve(const std::vector<Eigen::Vector2d>& held_positions_m);
  // Warm start: moves the free vertices too (e.g. an affine guess) before a solve.
  void set_positions(const std::vector<Eigen::Vector2d>& positions_m);

  const SheetMesh& mesh() const noexcept { return mesh_; }
  const std::vector<std::uint32_t>& held_vertices() const noexcept { return held_; }
  const std::vector<Vec3>& vertices_m() const noexcept { return x_; }

 private:
  FlatSheet() = default;
  SheetMesh mesh_;
  std::vector<std::uint32_t> held_;
  FlatSheetOptions options_;
  std::unique_ptr<Membrane> membrane_;
  std::unique_ptr<detail::MembraneSolver> solver_;
  std::vector<Eigen::Vector2d> q_;
  std::vector<Vec3> x_;
};

// A regular grid of the rectangle [0, width] x [0, length], diagonals
// alternating; spacing at most spacing_m. cell_of_triangle is 0 throughout
// (the whole rectangle is the one cell).
Result<SheetMesh> rectangle_mesh(double width_m, double length_m, double spacing_m);

struct UniaxialOptions {
  double width_m = 0.015;
  double length_m = 0.050;
  double spacing_m = 0.001;
  FlatSheetOptions sheet;
  Status validate() const;
  std::string describe() const;
};

class UniaxialStretchRig {
 public:
  static Result<UniaxialStretchRig> create(const UniaxialOptions& options);
  // Moves the stage so the clamps are lambda * length apart (lambda >= 1
  // pulls; steps of up to ~0.3 at a time converge from the affine guess).
  Result<FlatSolveReport> set_stretch(double lambda);
  double stretch() const noexcept { return lambda_; }
  // The deformed cell's width across its middle (the vertex row nearest
  // y = length / 2 on the rest sheet).
  double mid_width_m() const;
  const SheetMesh& mesh() const noexcept { return sheet_.mesh(); }
  const std::vector<Vec3>& vertices_m() const noexcept { return sheet_.vertices_m(); }

 private:
  UniaxialStretchRig(FlatSheet sheet, UniaxialOptions options) : sheet_(std::move(sheet)), options_(options) {}
  FlatSheet sheet_;
  UniaxialOptions options_;
  double lambda_ = 1.0;
};

struct StringPullOptions {
  std::uint64_t seed = 1;
  int strings = 3;
  double max_pull_m = 0.012;     // how far a string drags its clip
  double clip_radius_m = 0.004;  // the clip: vertices within this of the attachment move with it
  double inner_fraction = 0.6;   // attachments lie in this central part of the sheet
  FlatSheetOptions sheet;
  Status validate() const;
  std::string describe() const;
};

struct PullString {
  Eigen::Vector2d attachment_m;  // on the rest sheet
  Eigen::Vector2d direction;     // unit, in the sheet plane
  std::vector<std::uint32_t> clip_vertices;
};

class StringPullRig {
 public:
  // The sheet is held along its outline (the frame); the strings are seeded.
  static Result<StringPullRig> create(SheetMesh mesh, const StringPullOptions& options);
  // Pulls every string by its current amount (a seeded smooth signal in
  // [0, max_pull]) and solves.
  Result<FlatSolveReport> step(double t_s);
  double pull_m(std::size_t string, double t_s) const;
  const std::vector<PullString>& strings() const noexcept { return strings_; }
  const SheetMesh& mesh() const noexcept { return sheet_.mesh(); }
  const std::vector<Vec3>& vertices_m() const noexcept { return sheet_.vertices_m(); }

 private:
  StringPullRig(FlatSheet sheet, StringPullOptions options) : sheet_(std::move(sheet)), options_(options) {}
  FlatSheet sheet_;
  StringPullOptions options_;
  std::vector<PullString> strings_;
  std::vector<MotionSignal> signals_;
  std::vector<std::int32_t> string_of_held_;  // per held vertex: its string, or -1 for the frame
};

}  // namespace proprio::elastic_sheet
