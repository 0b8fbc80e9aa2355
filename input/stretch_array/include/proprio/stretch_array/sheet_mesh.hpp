#pragma once
// The array's rest sheet as a triangle mesh (issue 30): what the simulator
// deforms and what eq. 4.8 sums a cell's capacitance over. Each triangle lies
// inside exactly one cell or in the plain silicone around and between them,
// so a cell's triangles cover its area exactly.
//
// The mesh is a grid whose lines include every strip edge, subdivided to at
// most max_edge_m, each grid rectangle split into two triangles (diagonals
// alternating, so the mesh has no preferred shear direction). Cells with
// explicit outlines (strips that are not straight) are refused for now.
#include <array>
#include <cstdint>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/array_layout.hpp"

namespace proprio::stretch_array {

struct SheetMeshOptions {
  double margin_m = 0.004;    // plain sheet beyond the outermost strip edges
  double max_edge_m = 0.003;  // grid spacing at most this (triangle legs)
  Status validate() const;
};

struct SheetMesh {
  std::vector<Point2> vertices_m;                    // on the flat rest sheet
  std::vector<std::array<std::uint32_t, 3>> triangles;  // counter-clockwise
  std::vector<std::int32_t> cell_of_triangle;        // the cell index, or -1 between cells

  double triangle_area_m2(std::size_t t) const;
  // Per cell, its triangles.
  std::vector<std::vector<std::uint32_t>> triangles_of_cells(std::size_t cell_count) const;
};

Result<SheetMesh> build_sheet_mesh(const StripArrayLayout& layout, const SheetMeshOptions& options = {});

}  // namespace proprio::stretch_array
