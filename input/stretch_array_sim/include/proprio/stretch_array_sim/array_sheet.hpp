#pragma once
// What a deformed array sheet is, electrically, before any board reads it
// (issue 30): the ideal capacitance of every cell (the truth the regressor
// never sees), each cell's largest stretch (for over-stretch damage) and how
// much each strip's resistance grew on the way to each of its cells.
//
// Ideal capacitance. Each triangle i of a cell is a plate capacitor over an
// incompressible dielectric: its thickness is d0 A_i0 / A_i, so
//   C_i = eps A_i / d = eps A_i^2 / (A_i0 d0),   C_cell = sum_i C_i,
// which is eq. 4.8 times the rest capacitance eps A0 / d0 (eq. 4.1), with
// eps and d0 from the layout's SheetMaterial. A_i is the deformed triangle's
// area in 3D, so bending a sheet without stretching it leaves C unchanged.
//
// Strip resistance. A conductive-silicone strip of rest width w0 and
// thickness t0 carries current along itself. Stretched by l1 along and l2
// across, incompressibility gives t = t0 / (l1 l2), so a piece of rest length
// ds has R = rho l1 ds / (l2 w0 t0 / (l1 l2)) = (rho / t0) l1^2 ds / w0: the
// resistance grows with the square of the stretch along the strip whatever the
// sideways stretch does (the R ~ (l/l0)^2). ArraySheet integrates
// l1^2 ds / w0 ("squares": multiply by the sheet resistance in ohm per square)
// along each strip's centre line, from the strip's connector end (the sheet's
// low edge: y = min for top strips, x = min for bottom strips) to each cell's
// centre, l1 = |F d| from each triangle's deformation gradient F.
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/sheet_mesh.hpp"

namespace proprio::stretch_array_sim {

// A deformed sheet, as the board's physics needs it.
struct SheetState {
  std::vector<double> cell_f;            // ideal capacitance per cell (F)
  std::vector<double> cell_max_stretch;  // largest principal stretch over the cell's triangles
  // Per cell: squares (l1^2 ds / w0 summed) along its top strip and along its
  // bottom strip, from the strip's connector end to the cell's centre.
  std::vector<double> top_squares, bottom_squares;
};

// (1 - w) a + w b, field by field: for a caller that has the sheet at two
// instants and wants it between them (rows are measured at their own times).
// The largest stretch is interpolated too, so a damage threshold crossed only
// between the two is missed; sample finely enough. Errors on mismatched sizes.
Result<SheetState> interpolate(const SheetState& a, const SheetState& b, double w);

class ArraySheet {
 public:
  // Errors when the layout is invalid, the mesh does not match it (a cell
  // with no triangles, a strip centre line that leaves the mesh) or a
  // triangle is degenerate.
  static Result<ArraySheet> create(const stretch_array::StripArrayLayout& layout, const stretch_array::SheetMesh& mesh);

  // The state of the sheet with these vertex positions (same order as the
  // mesh's vertices_m; metres, any frame). Errors on a size mismatch or a
  // non-finite position.
  Result<SheetState> evaluate(std::span<const Eigen::Vector3d> vertices_m) const;
  // The flat rest sheet (z = 0) and its state.
  std::vector<Eigen::Vector3d> rest_vertices_m() const;
  const SheetState& rest_state() const noexcept { return rest_; }

  // Ideal per-cell capacitance (F) alone, and eq. 4.8's C/C0 computed through
  // stretch_array::cell_capacitance_ratio (for comparing).
  Result<std::vector<double>> ideal_capacitance_f(std::span<const Eigen::Vector3d> vertices_m) const;
  Result<std::vector<double>> eq48_ratio(std::span<const Eigen::Vector3d> vertices_m) const;

  const stretch_array::StripArrayLayout& layout() const noexcept { return *layout_; }
  const stretch_array::SheetMesh& mesh() const noexcept { return *mesh_; }
  std::size_t cell_count() const noexcept { return layout_->cells.size(); }
  // Rest squares of each strip from its connector end to the far edge of its
  // last cell (top strips first, then bottom): what the end-to-end
  // resistance of a strip is made of.
  const std::vector<double>& strip_rest_squares() const noexcept { return strip_rest_squares_; }

 private:
  friend class BoardSimulator;  // holds one by value
  ArraySheet() = default;
  struct Sample {
    std::uint32_t triangle = 0;
    double ds_over_w = 0.0;  // rest length / strip width of this piece
  };
  struct StripPath {
    Eigen::Vector2d direction;  // unit, along the strip on the rest sheet
    // Pieces from the connector end, and for each of the strip's cells, the
    // number of pieces that lie before the cell centre.
    std::vector<Sample> samples;
    std::vector<std::size_t> cells, samples_before_cell;
  };
  Result<SheetState> evaluate_impl(std::span<const Eigen::Vector3d> vertices_m) const;

  std::shared_ptr<const stretch_array::StripArrayLayout> layout_;
  std::shared_ptr<const stretch_array::SheetMesh> mesh_;
  std::vector<std::vector<std::uint32_t>> cell_triangles_;
  std::vector<double> triangle_rest_m2_;
  std::vector<Eigen::Matrix2d> rest_edges_inverse_;  // per triangle, [p1 - p0, p2 - p0]^-1
  std::vector<StripPath> top_paths_, bottom_paths_;
  std::vector<double> strip_rest_squares_;
  double eps_over_d0_ = 0.0;  // F / m^2
  SheetState rest_;
};

}  // namespace proprio::stretch_array_sim
