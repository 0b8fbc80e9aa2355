#pragma once
// The reconstruction mesh S^0 of a stretch sensor array (Glauser 2019,
// Sec. 4.4: "we represent each sensor cell S_j with a fan of triangles and
// mesh the overall layout using Delaunay triangulation"), its marker
// vertices and its rest shape.
//
// Vertices: every cell's centroid, its outline corners (outline edges
// subdivided to at most max_edge_m), a rectangle around the sheet (the strips'
// extent plus margin_m, like SheetMesh, its sides subdivided to
// boundary_edge_m) and fill points on a grid in the plain silicone far from
// every cell, so the empty corners of banded layouts get no long slivers.
//
// Fans. The whole point set is triangulated by cv::Subdiv2D (Delaunay). Each
// cell's outline segments are then required to be edges of that
// triangulation; when one is not (a point of the gap, the fill or a
// neighbouring cell lies in its diametral circle) the outlines are subdivided
// further and the triangulation redone. With every outline segment an edge, a
// cell's polygon is exactly a union of Delaunay triangles, and those are
// replaced by the fan centroid -> outline segment. The fan needs the cell to
// be star-shaped from its centroid; cells that are not are refused.
//
// Every vertex carries its flat rest-sheet coordinates (x, y): the material
// point the simulator puts markers and ground truth on.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/array_layout.hpp"

namespace proprio::stretch_array_recon {

using Point2 = stretch_array::Point2;
using Triangle = std::array<std::uint32_t, 3>;

struct ReconMeshOptions {
  double max_edge_m = 0.008;       // cell outline segments at most this long (first try)
  double margin_m = 0.004;         // plain sheet beyond the outermost strip edges
  double boundary_edge_m = 0.008;  // the margin rectangle's segments at most this long
  // Fill points on this grid where the nearest cell outline is at least
  // fill_clearance_m away; 0 disables the fill.
  double fill_spacing_m = 0.012;
  double fill_clearance_m = 0.005;
  int max_refinements = 4;  // outline halvings tried before giving up on the fans
  Status validate() const;
  std::string describe() const;
};

enum class VertexKind : std::uint8_t { cell_centroid, cell_outline, boundary, fill };

struct ReconMesh {
  std::vector<Point2> sheet_xy_m;                            // per vertex: flat rest-sheet coordinates
  std::vector<VertexKind> kind;                              // per vertex
  std::vector<std::int32_t> cell_of_vertex;                  // centroid/outline vertices: their cell; else -1
  std::vector<Triangle> triangles;                           // counter-clockwise on the sheet
  std::vector<std::int32_t> cell_of_triangle;                // the fan's cell, or -1 outside cells
  std::vector<std::uint32_t> centroid_vertex;                // per cell
  std::vector<std::vector<std::uint32_t>> outline_vertices;  // per cell, counter-clockwise
  double outline_edge_m = 0.0;                               // the outline subdivision the fans needed

  std::size_t vertex_count() const noexcept { return sheet_xy_m.size(); }
  double area_m2() const;  // of all triangles
};

Result<ReconMesh> build_recon_mesh(const stretch_array::StripArrayLayout& layout, const ReconMeshOptions& options = {});

// Marker vertices: cell centroids chosen on a regular grid over the sheet
// with spacing at most max_spacing_m, the cell centroid nearest each grid
// node, no cell twice; nodes over bare sheet get none. The thesis put 21
// markers on its 92-cell sensor, at most 5 cm apart; 35 mm gives
// prototype_92 (a stand-in layout) 19, its banded cells leaving more of the
// grid's corners bare.
struct MarkerSelectionOptions {
  double max_spacing_m = 0.035;
  Status validate() const;
  std::string describe() const;
};
Result<std::vector<std::uint32_t>> select_marker_vertices(const ReconMesh& mesh,
                                                          const MarkerSelectionOptions& options = {});

// The rest shape V^0: the flat sheet (radius 0, z = 0), or wrapped on a
// cylinder of radius_m whose axis is parallel to the sheet's y axis: sheet x
// becomes arc length about the sheet's middle xc (of the vertices' x range),
// (x, y) -> (xc + R sin a, y, R cos a - R) with a = (x - xc) / R, so the
// line x = xc stays in place with normal +z and the axis is (xc, y, -R).
// The thesis wraps a sleeve sensor on a cylinder of its intrinsic size
// (R = sheet width / 2 pi). The labelling and the reconstructor align the
// rest shape to the data by Procrustes, so the placement is a convention.
Eigen::MatrixX3d rest_shape(const ReconMesh& mesh, double cylinder_radius_m = 0.0);

}  // namespace proprio::stretch_array_recon
