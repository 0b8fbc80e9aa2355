#pragma once
// The stretch-sensing capacitive glove (Glauser 2019, ch. 5) as data: the
// electrode strips of its two conductive layers, the sensor cells where a top
// and a bottom strip cross, where each cell sits on the hand and which way it
// is most sensitive to stretch, and the grids the pose network reads and
// writes. Both the simulator (ground truth) and the run-time pipeline read the
// same layout, so a lab with another electrode pattern describes it once, in
// a TOML file (config/stretch_glove.toml is the thesis-like glove; the format
// is documented in docs/stretch-glove-layout.md).
//
// Read-out model (thesis eqs 4.5-4.7). One measurement drives one top strip
// and one bottom strip as the source electrode and grounds every other strip.
// Cells with exactly one plate on a source strip charge in parallel, so the
// measured capacitance is the sum over cells c of [top(c)==t] xor
// [bottom(c)==b] * C_c. One full cycle measures every (t, b) pair: rows
// t * bottom_strips + b of measurement_matrix(). The first, mandatory
// rows of the thesis (M^I) and the extra ones (M^II) are the same kind of
// row, so the layout keeps them in one matrix; the solver uses all of them in
// the least-squares sense (eq 4.6).
//
// Pose DoFs. Proprio's kinematic hand has 20 DOFs (hand_model.hpp); the
// thesis's network predicts the 25 of Tkach et al. 2017. The 5x5 output grid
// keeps the thesis's shape: each cell names a HandDof, or is empty (the DoFs
// Proprio's hand does not have). Empty cells are masked out of the loss and
// ignored at run time.
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

// The direction a cell is most sensitive to, on the hand's surface:
// "along" the bone under it (flexion stretches it) or "across" it (finger
// volume and abduction stretch it). The thesis calls them vertical and
// horizontal in its flat rest layout (Fig. 5.3).
enum class StretchDirection : std::uint8_t { along = 0, across = 1 };
std::string_view to_string(StretchDirection d) noexcept;
std::optional<StretchDirection> parse_stretch_direction(std::string_view s) noexcept;

// The thesis's four sensor categories (Sec. 5.2.1), kept for the 14-to-44
// sensor ablation (Fig. 5.10).
enum class StretchCellCategory : std::uint8_t { joint = 0, abduction = 1, perpendicular = 2, dorsum = 3 };
std::string_view to_string(StretchCellCategory c) noexcept;
std::optional<StretchCellCategory> parse_stretch_cell_category(std::string_view s) noexcept;

// "index_mcp_flexion" -> HandDof::index_mcp_flexion (the names of to_string(HandDof)).
std::optional<HandDof> parse_hand_dof(std::string_view s) noexcept;

struct StretchCell {
  std::string name;      // "index_mcp_along", ...
  int top_strip = 0;     // 0 .. top_strips-1
  int bottom_strip = 0;  // 0 .. bottom_strips-1
  StretchCellCategory category = StretchCellCategory::joint;
  StretchDirection direction = StretchDirection::along;
  // Where the cell sits: on the back of a segment (a glove segment, as in
  // glove_description.hpp), a fraction of the bone length from its joint.
  // Dorsum cells: along_fraction of hand length from the wrist, across_fraction
  // of hand width, + toward the little finger. Abduction cells sit in the web
  // between two fingers: segment is the radial finger's proximal phalanx (for
  // the web between thumb and index, whose skin spans the thumb's metacarpal,
  // thumb_metacarpal or thumb_proximal); the web reaches to the next finger
  // toward the little finger.
  HandJoint segment = HandJoint::wrist;
  double along_fraction = 0.5;
  double across_fraction = 0.0;
  // Cell size in the rest layout (thesis: 5 x 7.5 or 5 x 11.5 mm): length_m
  // is the extent in the cell's stretch direction, width_m across it.
  double length_m = 0.0115;
  double width_m = 0.005;
  double rest_capacitance_pf = 20.0;  // C0 at rest; a nominal value, per glove
  // Where the network input puts this cell: layer 0 = along, 1 = across.
  int grid_layer = 0;
  int grid_row = 0;
  int grid_col = 0;

  bool operator==(const StretchCell&) const = default;
};

inline constexpr int kStretchGridSize = 5;  // 5 x 5 maps, as the thesis's Fig. 5.7-5.8
inline constexpr int kStretchInputLayers = 2;
// Floats in one network input (layers x rows x cols, NCHW with N = 1).
inline constexpr std::size_t kStretchInputSize = kStretchInputLayers * kStretchGridSize * kStretchGridSize;

struct StretchGloveLayout {
  std::string name;
  int top_strips = 13;
  int bottom_strips = 14;
  std::vector<StretchCell> cells;
  // Output grid, row-major: output_grid[row * 5 + col].
  std::array<std::optional<HandDof>, kStretchGridSize * kStretchGridSize> output_grid{};
  double frame_rate_hz = 60.0;  // full frames of recovered cells per second
  std::string origin;           // file it came from

  static Result<StretchGloveLayout> load(const std::filesystem::path& path);
  static Result<StretchGloveLayout> parse(std::string_view toml_text, const std::string& source_name);
  // The thesis-like glove: 44 cells on 27 leads (13 top + 14 bottom).
  static StretchGloveLayout thesis_default();

  std::size_t cell_count() const noexcept { return cells.size(); }
  std::size_t measurement_count() const noexcept {
    return static_cast<std::size_t>(top_strips) * static_cast<std::size_t>(bottom_strips);
  }
  // measurement_count() x cell_count(), entries 0 or 1 (see the top of this file).
  Eigen::MatrixXd measurement_matrix() const;
  // Flat index of each cell in the 2 x 5 x 5 input grid (layer, row, col):
  // layer * 25 + row * 5 + col.
  std::vector<int> input_grid_index() const;
  // Index of the cell with this name.
  std::optional<std::size_t> find_cell(std::string_view cell_name) const;
  // Everything parse() checks (strips in range, each strip pair used once,
  // unique names and grid slots, output grid, a measurement matrix of full
  // column rank), for layouts built in code. Errc::invalid_argument naming
  // the cell and what to change.
  Status validate() const;
  std::string describe() const;
  // The layout in the file format parse() reads (docs/stretch-glove-layout.md);
  // parse(to_toml()) gives this layout back, origin aside.
  std::string to_toml() const;

  bool operator==(const StretchGloveLayout&) const = default;
};

}  // namespace proprio
