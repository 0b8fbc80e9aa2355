#pragma once
// A stretch sensor array (Glauser 2019, ch. 4, "Deformation capture via soft
// and stretchable sensor arrays", TOG 2019) as data: two conductive layers of
// electrode strips (n top, k bottom) in a silicone sheet, a sensor cell where
// a top and a bottom strip cross (each pair at most once), and each cell's
// outline on the flat rest sheet. Read by the simulator and the read-out
// alike; the format is in docs/stretch-arrays.md.
//
// Geometry. Strips are straight bands on the flat rest sheet (sheet frame:
// x right, y up, metres): top strips run along y at their x, bottom strips
// along x at their y, each with its width. A cell's outline is the overlap
// rectangle of its two strips, or an explicit polygon (for warped layouts
// whose strips are not straight).
//
// Read-out (eqs. 4.5-4.7). A measurement connects a set of strips as the
// source electrode and grounds the rest; a cell charges when exactly one of
// its two strips is a source, and the cells that charge add up. The plan:
//   M^I:  every (top t, bottom b) pair as the source: n k rows (the thesis's
//         mandatory part);
//   M^II: every single strip as the source: n + k rows. The thesis takes
//         "all remaining combinations"; 2^(n+k) of them is not a plan, and the
//         single strips are what makes the small layouts solvable: M^I alone
//         leaves a full 2 x 3 grid at rank 4 of 6 (the thesis's own Fig. 4.6
//         example), with the single strips it has rank 6.
// A layout is readable when M = [M^I; M^II] has full column rank;
// check_layout() says so with the rank and condition number of both, and
// names the cells that cannot be told apart.
#include <array>
#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"

namespace proprio::stretch_array {

using Point2 = Eigen::Vector2d;

struct Strip {
  std::string name;
  double centre_m = 0.0;  // top strips: x; bottom strips: y
  double width_m = 0.005;
};

struct ArrayCell {
  std::string name;  // "<top>-<bottom>" unless given
  std::size_t top = 0, bottom = 0;  // indices into top_strips / bottom_strips
  // Counter-clockwise polygon on the rest sheet; empty: the strips' overlap rectangle.
  std::vector<Point2> outline_m;
};

// The silicone sheet the strips sit in (thesis Sec. 4.3.3 and Appendix B).
struct SheetMaterial {
  // Between the two conductive layers. The thesis casts it between two
  // layers of 65 um tape with solvent that evaporates; it gives no cured
  // value, only the whole sheet's (~500 um) and each conductive layer's
  // (45 um). 100 um is our estimate; it sets the absolute C0 only.
  double dielectric_thickness_m = 0.1e-3;
  double relative_permittivity = 2.8;      // silicone dielectric
  double youngs_modulus_pa = 0.85e6;       // the thesis's silicones: 0.73-0.98 MPa
  double poisson_ratio = 0.49;             // near-incompressible (the simulator's membrane is incompressible)
  double total_thickness_m = 0.5e-3;       // the whole sheet, five layers (thesis Sec. 4.3.3): the simulator's stiffness
};

struct StripArrayLayout {
  std::string name;
  std::vector<Strip> top_strips, bottom_strips;
  std::vector<ArrayCell> cells;
  SheetMaterial sheet;

  std::size_t cell_count() const noexcept { return cells.size(); }
  // The cell's outline (explicit, or the overlap rectangle), counter-clockwise.
  std::vector<Point2> outline(std::size_t cell) const;
  double rest_area_m2(std::size_t cell) const;
  Point2 centroid(std::size_t cell) const;

  // Rows M^I, then M^II (see the top of this file); each row's source strips.
  struct Measurement {
    std::vector<std::size_t> top_sources, bottom_sources;
    bool mandatory = true;  // M^I
  };
  std::vector<Measurement> measurement_plan(bool with_m2 = true) const;
  // measurement_plan().size() x cell_count(), entries 0 or 1.
  Eigen::MatrixXd measurement_matrix(bool with_m2 = true) const;

  // Unique names, indices in range, each strip pair crossing at most once,
  // positive sizes, outlines that are simple polygons of positive area.
  Status validate() const;

  static Result<StripArrayLayout> parse(std::string_view toml_text, const std::string& source_name);
  static Result<StripArrayLayout> load(const std::filesystem::path& path);
  std::string to_toml() const;

  // A regular grid: n top strips and k bottom strips at `pitch_m`, all n k
  // crossings (band < 0) or only those with |t - b| <= band.
  static StripArrayLayout grid(std::string name, std::size_t n, std::size_t k, double pitch_m, double width_m,
                               int band = -1);
  // The two layouts of the thesis, by their counts. The thesis's figures are
  // not in its text, so these are stand-ins with the same strips and cells:
  //   prototype_92: 12 + 12 strips, 92 cells (Fig. 4.3c, 4.4): a banded grid,
  //     |t - b| <= 4 (88 cells) plus four crossings at |t - b| = 5;
  //   biceps_144: 12 + 12 strips, all 144 crossings (Fig. 4.14's sleeve).
  static StripArrayLayout prototype_92();
  static StripArrayLayout biceps_144();
};

// How readable a layout is: rank and condition number of the measurement
// matrix with M^I alone and with M^I and M^II.
struct LayoutCheck {
  std::size_t cells = 0;
  std::size_t rows_m1 = 0, rows_all = 0;
  long rank_m1 = 0, rank_all = 0;
  double condition_m1 = 0.0, condition_all = 0.0;  // inf when rank-deficient
  std::vector<std::string> indistinguishable;      // cells in the kernel of [M^I; M^II]
  bool readable() const noexcept { return rank_all == static_cast<long>(cells); }
  std::string describe() const;
};
LayoutCheck check_layout(const StripArrayLayout& layout);
// check_layout(), as an Error naming the cells when the layout is not readable.
Status require_readable(const StripArrayLayout& layout);

}  // namespace proprio::stretch_array
