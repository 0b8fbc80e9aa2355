#include "proprio/glove_descriptions/stretch_glove_layout.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio {

namespace {

constexpr std::array<std::string_view, 2> kDirectionNames = {"along", "across"};
constexpr std::array<std::string_view, 4> kCategoryNames = {"joint", "abduction", "perpendicular", "dorsum"};
constexpr int kGridCells = kStretchGridSize * kStretchGridSize;

std::string segment_text(HandJoint j) { return j == HandJoint::wrist ? "dorsum" : std::string(to_string(j)); }

std::optional<Finger> finger_of(HandJoint j) {
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(f));
    for (std::size_t k = 0; k < fj.count; ++k) {
      if (fj.joints[k] == j) return static_cast<Finger>(f);
    }
  }
  return std::nullopt;
}

// Shortest decimal text that reads back as exactly this double, so to_toml()
// round-trips bit for bit without printing 17 digits for 0.1.
template <typename Exact>
std::optional<std::string> shortest_text(double candidate, Exact exact) {
  for (int precision = 1; precision <= 17; ++precision) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*g", precision, candidate);
    const bool exponent = std::string_view(buf).find('e') != std::string_view::npos;
    if (exponent && std::abs(candidate) >= 1e-4 && std::abs(candidate) < 1e15) continue;
    if (exact(std::strtod(buf, nullptr))) {
      std::string s = buf;
      // "12" would be a TOML integer; a continuous quantity reads better as 12.0.
      if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
      return s;
    }
  }
  return std::nullopt;
}

std::string num(double v) {
  if (auto s = shortest_text(v, [v](double x) { return x == v; })) return *s;
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string mm_text(double metres) {
  return shortest_text(metres * 1000.0, [metres](double mm) { return mm / 1000.0 == metres; })
      .value_or(num(metres * 1000.0));
}

std::string toml_string(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    if (static_cast<unsigned char>(ch) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(ch));
      out += buf;
      continue;
    }
    if (ch == '"' || ch == '\\') out += '\\';
    out += ch;
  }
  return out + "\"";
}

std::string join(const std::vector<std::string_view>& items) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? ", " : "") + std::string(items[i]);
  return out;
}

// Where a problem with cell i (or with a top-level key when i is npos) is:
// "file:line:col: 'cell[3].top_strip'" from a file, "cell 3 (index_mcp_along)"
// for a layout built in code.
using Locator = std::function<std::string(std::size_t cell, std::string_view key)>;
constexpr std::size_t kNoCell = static_cast<std::size_t>(-1);

Status check_layout(const StretchGloveLayout& L, const Locator& at) {
  auto fail = [&](std::size_t cell, std::string_view key, const std::string& what) -> Status {
    return make_error(Errc::invalid_argument, at(cell, key) + " " + what);
  };
  if (L.top_strips < 1 || L.top_strips > 1024) {
    return fail(kNoCell, "top_strips", "must be 1-1024 electrode strips, but it is " + std::to_string(L.top_strips));
  }
  if (L.bottom_strips < 1 || L.bottom_strips > 1024) {
    return fail(kNoCell, "bottom_strips",
                "must be 1-1024 electrode strips, but it is " + std::to_string(L.bottom_strips));
  }
  if (!(L.frame_rate_hz > 0.0 && L.frame_rate_hz <= 10000.0)) {
    return fail(kNoCell, "frame_rate_hz", "must be a rate in hertz above 0 and at most 10000");
  }
  if (L.cells.empty()) return fail(kNoCell, "cell", "is empty: the glove has no cells; add at least one");
  if (L.cells.size() > L.measurement_count()) {
    return fail(kNoCell, "cell",
                "lists " + std::to_string(L.cells.size()) + " cells, but " + std::to_string(L.measurement_count()) +
                    " strip combinations cannot recover more than " + std::to_string(L.measurement_count()) +
                    "; add strips or remove cells");
  }

  std::vector<std::size_t> pair_owner(L.measurement_count(), kNoCell);
  std::vector<std::size_t> slot_owner(kStretchInputSize, kNoCell);
  for (std::size_t i = 0; i < L.cells.size(); ++i) {
    const StretchCell& c = L.cells[i];
    if (c.name.empty()) return fail(i, "name", "must not be empty");
    for (std::size_t j = 0; j < i; ++j) {
      if (L.cells[j].name == c.name) {
        return fail(i, "name", "= \"" + c.name + "\" is already the name of cell " + std::to_string(j) +
                                   "; cell names identify sensor channels, so give each a distinct name");
      }
    }
    if (c.top_strip < 0 || c.top_strip >= L.top_strips) {
      return fail(i, "top_strip", "= " + std::to_string(c.top_strip) + " is not a top strip; use 0-" +
                                      std::to_string(L.top_strips - 1) + " (top_strips = " +
                                      std::to_string(L.top_strips) + ")");
    }
    if (c.bottom_strip < 0 || c.bottom_strip >= L.bottom_strips) {
      return fail(i, "bottom_strip", "= " + std::to_string(c.bottom_strip) + " is not a bottom strip; use 0-" +
                                         std::to_string(L.bottom_strips - 1) + " (bottom_strips = " +
                                         std::to_string(L.bottom_strips) + ")");
    }
    const auto pair = static_cast<std::size_t>(c.top_strip) * static_cast<std::size_t>(L.bottom_strips) +
                      static_cast<std::size_t>(c.bottom_strip);
    if (pair_owner[pair] != kNoCell) {
      return fail(i, "bottom_strip",
                  "= " + std::to_string(c.bottom_strip) + " with top strip " + std::to_string(c.top_strip) +
                      ": these two strips already cross at cell '" + L.cells[pair_owner[pair]].name +
                      "'; two strips can overlap at most once, so give one of the cells another strip");
    }
    pair_owner[pair] = i;
    if (!is_glove_segment(c.segment)) {
      return fail(i, "segment", "= \"" + std::string(to_string(c.segment)) + "\" is not a segment a cell can sit on");
    }
    if (!(c.along_fraction >= 0.0 && c.along_fraction <= 1.0)) {
      return fail(i, "along_fraction", "must be a fraction 0-1");
    }
    if (!(c.across_fraction >= -0.5 && c.across_fraction <= 0.5)) {
      return fail(i, "across_fraction", "must be a fraction of hand width, -0.5 to 0.5");
    }
    if (c.segment != HandJoint::wrist && c.across_fraction != 0.0) {
      return fail(i, "across_fraction", "only applies on the dorsum; on a finger segment leave it out");
    }
    if (c.category == StretchCellCategory::abduction) {
      const auto f = finger_of(c.segment);
      if (!f || *f == Finger::little) {
        return fail(i, "segment",
                    "must be on the thumb, index, middle or ring finger for an abduction cell: it sits in the web "
                    "toward the next finger, and names the radial one of the two");
      }
    }
    if (!(c.length_m > 0.0 && c.length_m < 0.1) || !(c.width_m > 0.0 && c.width_m < 0.1)) {
      return fail(i, c.length_m > 0.0 && c.length_m < 0.1 ? "width_mm" : "length_mm",
                  "must be a cell size above 0 and below 100 mm");
    }
    if (!(c.rest_capacitance_pf > 0.0 && c.rest_capacitance_pf < 1e4)) {
      return fail(i, "rest_capacitance_pf", "must be a capacitance in picofarads above 0 and below 10000");
    }
    if (c.grid_layer < 0 || c.grid_layer >= kStretchInputLayers || c.grid_row < 0 ||
        c.grid_row >= kStretchGridSize || c.grid_col < 0 || c.grid_col >= kStretchGridSize) {
      return fail(i, "grid", "= [" + std::to_string(c.grid_layer) + ", " + std::to_string(c.grid_row) + ", " +
                                 std::to_string(c.grid_col) +
                                 "] is outside the input grid; use [layer 0-1, row 0-4, col 0-4]");
    }
    const auto slot = static_cast<std::size_t>(c.grid_layer * kGridCells + c.grid_row * kStretchGridSize + c.grid_col);
    if (slot_owner[slot] != kNoCell) {
      return fail(i, "grid", "= [" + std::to_string(c.grid_layer) + ", " + std::to_string(c.grid_row) + ", " +
                                 std::to_string(c.grid_col) + "], a slot that already holds cell '" +
                                 L.cells[slot_owner[slot]].name + "'; each grid slot holds one cell");
    }
    slot_owner[slot] = i;
  }

  std::set<HandDof> seen;
  for (std::size_t k = 0; k < L.output_grid.size(); ++k) {
    if (!L.output_grid[k]) continue;
    if (index_of(*L.output_grid[k]) >= kHandDofCount) return fail(kNoCell, "output_grid", "holds an invalid DoF");
    if (!seen.insert(*L.output_grid[k]).second) {
      return fail(kNoCell, "output_grid",
                  "names '" + std::string(to_string(*L.output_grid[k])) + "' twice (entries are row-major, row " +
                      std::to_string(k / kStretchGridSize) + " col " + std::to_string(k % kStretchGridSize) +
                      "); each DoF has one output cell");
    }
  }

  // Full column rank: otherwise some cells cannot be separated by any
  // combination of measurements, whatever the solver.
  const Eigen::MatrixXd M = L.measurement_matrix();
  Eigen::FullPivLU<Eigen::MatrixXd> lu(M);
  if (lu.rank() < static_cast<Eigen::Index>(L.cells.size())) {
    const Eigen::MatrixXd K = lu.kernel();
    std::string names;
    for (std::size_t i = 0; i < L.cells.size(); ++i) {
      if (K.row(static_cast<Eigen::Index>(i)).cwiseAbs().maxCoeff() > 1e-9) {
        names += (names.empty() ? "" : ", ") + L.cells[i].name;
      }
    }
    return fail(kNoCell, "cell",
                "gives a measurement matrix of rank " + std::to_string(lu.rank()) + " for " +
                    std::to_string(L.cells.size()) + " cells, so these cells cannot be told apart: " + names +
                    ". Move some of them to other strips (a full grid of 2 x 2 strips, for example, is not "
                    "solvable); see docs/stretch-glove-layout.md");
  }
  return {};
}

}  // namespace

// --- names -------------------------------------------------------------------

std::string_view to_string(StretchDirection d) noexcept {
  const auto i = static_cast<std::size_t>(d);
  return i < kDirectionNames.size() ? kDirectionNames[i] : std::string_view("invalid_direction");
}

std::optional<StretchDirection> parse_stretch_direction(std::string_view s) noexcept {
  for (std::size_t i = 0; i < kDirectionNames.size(); ++i) {
    if (s == kDirectionNames[i]) return static_cast<StretchDirection>(i);
  }
  return std::nullopt;
}

std::string_view to_string(StretchCellCategory c) noexcept {
  const auto i = static_cast<std::size_t>(c);
  return i < kCategoryNames.size() ? kCategoryNames[i] : std::string_view("invalid_category");
}

std::optional<StretchCellCategory> parse_stretch_cell_category(std::string_view s) noexcept {
  for (std::size_t i = 0; i < kCategoryNames.size(); ++i) {
    if (s == kCategoryNames[i]) return static_cast<StretchCellCategory>(i);
  }
  return std::nullopt;
}

std::optional<HandDof> parse_hand_dof(std::string_view s) noexcept {
  for (std::size_t i = 0; i < kHandDofCount; ++i) {
    if (to_string(static_cast<HandDof>(i)) == s) return static_cast<HandDof>(i);
  }
  return std::nullopt;
}

// --- the thesis-like glove -------------------------------------------------------

StretchGloveLayout StretchGloveLayout::thesis_default() {
  StretchGloveLayout L;
  L.name = "Stretch-sensing glove (Glauser 2019, ch. 5), thesis-like layout";
  L.origin = "StretchGloveLayout::thesis_default()";
  L.top_strips = 13;
  L.bottom_strips = 14;
  L.frame_rate_hz = 60.0;

  // Cell i plays the part of the thesis's sensor i (Sec. 5.2.1 names the
  // numbers of each category; where exactly each sits is our guess, as the
  // figure is not in the text). config/stretch_glove.toml explains the
  // placement; a unit test keeps the two identical.
  using C = StretchCellCategory;
  using D = StretchDirection;
  using J = HandJoint;
  struct Row {
    const char* name;
    int top, bottom;
    C category;
    D direction;
    J segment;
    double along, across, length_mm, width_mm, c0_pf;
    int layer, row, col;
  };
  // Rest capacitance: eps0 * eps_r * A / d with eps_r = 2.9 (silicone) and a
  // 150 um dielectric: 9.8 pF for a 5 x 11.5 mm cell, 6.4 pF for 5 x 7.5 mm.
  constexpr double kLong = 11.5, kShort = 7.5, kWidth = 5.0, kC0Long = 9.8, kC0Short = 6.4;
  const Row rows[] = {
      {"thumb_mcp_along", 0, 11, C::joint, D::along, J::thumb_proximal, 0.10, 0, kLong, kWidth, kC0Long, 0, 1, 0},
      {"thumb_proximal_across", 1, 12, C::perpendicular, D::across, J::thumb_proximal, 0.55, 0, kShort, kWidth,
       kC0Short, 1, 1, 0},
      {"thumb_metacarpal_across", 1, 5, C::dorsum, D::across, J::thumb_metacarpal, 0.70, 0, kShort, kWidth,
       kC0Short, 1, 2, 0},
      {"dorsum_proximal_along_1", 12, 11, C::dorsum, D::along, J::wrist, 0.16, -0.09, kLong, kWidth, kC0Long, 0, 4,
       1},
      {"dorsum_across_0", 11, 0, C::dorsum, D::across, J::wrist, 0.24, -0.20, kShort, kWidth, kC0Short, 1, 4, 0},
      {"dorsum_proximal_along_2", 11, 12, C::dorsum, D::along, J::wrist, 0.16, 0.03, kLong, kWidth, kC0Long, 0, 4,
       2},
      {"dorsum_proximal_along_3", 12, 13, C::dorsum, D::along, J::wrist, 0.16, 0.15, kLong, kWidth, kC0Long, 0, 4,
       3},
      {"dorsum_ulnar_across", 11, 10, C::dorsum, D::across, J::wrist, 0.29, 0.30, kShort, kWidth, kC0Short, 1, 3, 4},
      {"little_proximal_across", 9, 10, C::perpendicular, D::across, J::little_proximal, 0.55, 0, kShort, kWidth,
       kC0Short, 1, 2, 4},
      {"little_intermediate_across", 9, 8, C::perpendicular, D::across, J::little_intermediate, 0.55, 0, kShort,
       kWidth, kC0Short, 1, 1, 4},
      {"dorsum_across_1", 12, 1, C::dorsum, D::across, J::wrist, 0.24, -0.09, kShort, kWidth, kC0Short, 1, 4, 1},
      {"thumb_metacarpal_along", 0, 13, C::dorsum, D::along, J::thumb_metacarpal, 0.35, 0, kLong, kWidth, kC0Long, 0,
       2, 0},
      {"dorsum_distal_along_1", 11, 6, C::dorsum, D::along, J::wrist, 0.36, -0.155, kLong, kWidth, kC0Long, 0, 3, 1},
      {"dorsum_distal_along_2", 12, 7, C::dorsum, D::along, J::wrist, 0.36, -0.01, kLong, kWidth, kC0Long, 0, 3, 2},
      {"dorsum_distal_along_3", 11, 8, C::dorsum, D::along, J::wrist, 0.36, 0.135, kLong, kWidth, kC0Long, 0, 3, 3},
      {"dorsum_distal_along_4", 12, 9, C::dorsum, D::along, J::wrist, 0.36, 0.275, kLong, kWidth, kC0Long, 0, 3, 4},
      {"thumb_index_web", 0, 7, C::abduction, D::across, J::thumb_metacarpal, 0.75, 0, kShort, kWidth, kC0Short, 1, 3,
       0},
      {"dorsum_across_2", 11, 2, C::dorsum, D::across, J::wrist, 0.24, 0.02, kShort, kWidth, kC0Short, 1, 4, 2},
      {"dorsum_across_3", 12, 3, C::dorsum, D::across, J::wrist, 0.24, 0.13, kShort, kWidth, kC0Short, 1, 4, 3},
      {"dorsum_across_4", 11, 4, C::dorsum, D::across, J::wrist, 0.24, 0.24, kShort, kWidth, kC0Short, 1, 4, 4},
      {"thumb_ip_along", 0, 1, C::joint, D::along, J::thumb_distal, 0.12, 0, kShort, kWidth, kC0Short, 0, 0, 0},
      {"index_dip_along", 2, 5, C::joint, D::along, J::index_distal, 0.15, 0, kShort, kWidth, kC0Short, 0, 0, 1},
      {"middle_dip_along", 5, 11, C::joint, D::along, J::middle_distal, 0.15, 0, kShort, kWidth, kC0Short, 0, 0, 2},
      {"ring_dip_along", 7, 0, C::joint, D::along, J::ring_distal, 0.15, 0, kShort, kWidth, kC0Short, 0, 0, 3},
      {"little_dip_along", 9, 0, C::joint, D::along, J::little_distal, 0.15, 0, kShort, kWidth, kC0Short, 0, 0, 4},
      {"index_middle_web", 2, 7, C::abduction, D::across, J::index_proximal, 0.15, 0, kShort, kWidth, kC0Short, 1, 3,
       1},
      {"middle_ring_web", 6, 7, C::abduction, D::across, J::middle_proximal, 0.15, 0, kShort, kWidth, kC0Short, 1, 3,
       2},
      {"ring_little_web", 8, 9, C::abduction, D::across, J::ring_proximal, 0.15, 0, kShort, kWidth, kC0Short, 1, 3,
       3},
      {"thumb_distal_across", 1, 10, C::perpendicular, D::across, J::thumb_distal, 0.55, 0, kShort, kWidth, kC0Short,
       1, 0, 0},
      {"index_proximal_across", 4, 5, C::perpendicular, D::across, J::index_proximal, 0.55, 0, kShort, kWidth,
       kC0Short, 1, 2, 1},
      {"middle_proximal_across", 5, 5, C::perpendicular, D::across, J::middle_proximal, 0.55, 0, kShort, kWidth,
       kC0Short, 1, 2, 2},
      {"ring_proximal_across", 7, 8, C::perpendicular, D::across, J::ring_proximal, 0.55, 0, kShort, kWidth, kC0Short,
       1, 2, 3},
      {"little_pip_along", 10, 6, C::joint, D::along, J::little_intermediate, 0.12, 0, kLong, kWidth, kC0Long, 0, 1,
       4},
      {"index_mcp_along", 3, 4, C::joint, D::along, J::index_proximal, 0.10, 0, kLong, kWidth, kC0Long, 0, 2, 1},
      {"middle_mcp_along", 6, 4, C::joint, D::along, J::middle_proximal, 0.10, 0, kLong, kWidth, kC0Long, 0, 2, 2},
      {"ring_mcp_along", 8, 6, C::joint, D::along, J::ring_proximal, 0.10, 0, kLong, kWidth, kC0Long, 0, 2, 3},
      {"little_mcp_along", 10, 9, C::joint, D::along, J::little_proximal, 0.10, 0, kLong, kWidth, kC0Long, 0, 2, 4},
      {"index_intermediate_across", 2, 3, C::perpendicular, D::across, J::index_intermediate, 0.55, 0, kShort, kWidth,
       kC0Short, 1, 1, 1},
      {"middle_intermediate_across", 5, 13, C::perpendicular, D::across, J::middle_intermediate, 0.55, 0, kShort,
       kWidth, kC0Short, 1, 1, 2},
      {"ring_intermediate_across", 7, 3, C::perpendicular, D::across, J::ring_intermediate, 0.55, 0, kShort, kWidth,
       kC0Short, 1, 1, 3},
      {"index_pip_along", 4, 2, C::joint, D::along, J::index_intermediate, 0.12, 0, kLong, kWidth, kC0Long, 0, 1, 1},
      {"middle_pip_along", 6, 12, C::joint, D::along, J::middle_intermediate, 0.12, 0, kLong, kWidth, kC0Long, 0, 1,
       2},
      {"ring_pip_along", 8, 2, C::joint, D::along, J::ring_intermediate, 0.12, 0, kLong, kWidth, kC0Long, 0, 1, 3},
      {"index_distal_across", 3, 1, C::perpendicular, D::across, J::index_distal, 0.55, 0, kShort, kWidth, kC0Short,
       1, 0, 1},
  };
  for (const Row& r : rows) {
    StretchCell c;
    c.name = r.name;
    c.top_strip = r.top;
    c.bottom_strip = r.bottom;
    c.category = r.category;
    c.direction = r.direction;
    c.segment = r.segment;
    c.along_fraction = r.along;
    c.across_fraction = r.across;
    c.length_m = r.length_mm / 1000.0;
    c.width_m = r.width_mm / 1000.0;
    c.rest_capacitance_pf = r.c0_pf;
    c.grid_layer = r.layer;
    c.grid_row = r.row;
    c.grid_col = r.col;
    L.cells.push_back(std::move(c));
  }

  // Rows: thumb, index, middle, ring, little. Columns: abduction, base
  // flexion, middle flexion, distal flexion, and a fifth the thesis uses for
  // DoFs (twist, wrist) our 20-DoF hand does not have.
  using H = HandDof;
  const std::array<std::array<std::optional<HandDof>, 4>, kFingerCount> out = {{
      {H::thumb_cmc_abduction, H::thumb_cmc_flexion, H::thumb_mcp_flexion, H::thumb_ip_flexion},
      {H::index_mcp_abduction, H::index_mcp_flexion, H::index_pip_flexion, H::index_dip_flexion},
      {H::middle_mcp_abduction, H::middle_mcp_flexion, H::middle_pip_flexion, H::middle_dip_flexion},
      {H::ring_mcp_abduction, H::ring_mcp_flexion, H::ring_pip_flexion, H::ring_dip_flexion},
      {H::little_mcp_abduction, H::little_mcp_flexion, H::little_pip_flexion, H::little_dip_flexion},
  }};
  for (std::size_t r = 0; r < kFingerCount; ++r) {
    for (std::size_t c = 0; c < 4; ++c) L.output_grid[r * kStretchGridSize + c] = out[r][c];
  }
  return L;
}

// --- derived quantities ----------------------------------------------------------

Eigen::MatrixXd StretchGloveLayout::measurement_matrix() const {
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(measurement_count()),
                                            static_cast<Eigen::Index>(cell_count()));
  for (int t = 0; t < top_strips; ++t) {
    for (int b = 0; b < bottom_strips; ++b) {
      const auto row = static_cast<Eigen::Index>(t * bottom_strips + b);
      for (std::size_t c = 0; c < cells.size(); ++c) {
        // A cell charges when exactly one of its plates is on the source
        // electrode; with both (or neither) its plates are at one potential.
        const bool on_top = cells[c].top_strip == t;
        const bool on_bottom = cells[c].bottom_strip == b;
        if (on_top != on_bottom) M(row, static_cast<Eigen::Index>(c)) = 1.0;
      }
    }
  }
  return M;
}

std::vector<int> StretchGloveLayout::input_grid_index() const {
  std::vector<int> out;
  out.reserve(cells.size());
  for (const auto& c : cells) out.push_back(c.grid_layer * kGridCells + c.grid_row * kStretchGridSize + c.grid_col);
  return out;
}

std::optional<std::size_t> StretchGloveLayout::find_cell(std::string_view cell_name) const {
  for (std::size_t i = 0; i < cells.size(); ++i) {
    if (cells[i].name == cell_name) return i;
  }
  return std::nullopt;
}

Status StretchGloveLayout::validate() const {
  const std::string who = name.empty() ? std::string("stretch-glove layout") : "layout '" + name + "'";
  return check_layout(*this, [&](std::size_t cell, std::string_view key) {
    if (cell == kNoCell) return who + ": '" + std::string(key) + "'";
    return who + ": cell " + std::to_string(cell) + " (" + cells[cell].name + ") '" + std::string(key) + "'";
  });
}

std::string StretchGloveLayout::describe() const {
  std::array<std::size_t, kCategoryNames.size()> per_category{};
  std::array<std::size_t, kDirectionNames.size()> per_direction{};
  for (const auto& c : cells) {
    ++per_category[static_cast<std::size_t>(c.category)];
    ++per_direction[static_cast<std::size_t>(c.direction)];
  }
  std::size_t dofs = 0;
  for (const auto& d : output_grid) dofs += d.has_value() ? 1 : 0;
  std::ostringstream s;
  s << (name.empty() ? std::string("unnamed stretch glove") : name) << ": " << cells.size() << " cells on "
    << top_strips + bottom_strips << " leads (" << top_strips << " top + " << bottom_strips << " bottom strips), "
    << measurement_count() << " measurements per cycle; ";
  for (std::size_t i = 0; i < kCategoryNames.size(); ++i) s << (i ? ", " : "") << kCategoryNames[i] << " " << per_category[i];
  s << "; along " << per_direction[0] << ", across " << per_direction[1] << "; output grid " << dofs << " DoFs, "
    << output_grid.size() - dofs << " empty; " << frame_rate_hz << " Hz frames";
  return s.str();
}

// --- file format -------------------------------------------------------------

namespace {

constexpr const char* kSegmentChoices =
    "dorsum (or wrist), or a joint that starts a bone: thumb_metacarpal, thumb_proximal, thumb_distal, "
    "index_metacarpal, index_proximal, index_intermediate, index_distal, and the same for middle, ring and little";

class LayoutParser {
 public:
  explicit LayoutParser(const Config& cfg) : cfg_(cfg) {}

  Result<StretchGloveLayout> run() {
    StretchGloveLayout L;
    L.origin = cfg_.source_name();
    if (auto st = only_keys(cfg_, "", {"name", "top_strips", "bottom_strips", "frame_rate_hz", "output_grid", "cell"});
        !st) {
      return st.error();
    }
    auto name = cfg_.get_string_or("name", "");
    if (!name) return name.error();
    L.name = *name;
    auto top = strip_count("top_strips");
    if (!top) return top.error();
    L.top_strips = *top;
    auto bottom = strip_count("bottom_strips");
    if (!bottom) return bottom.error();
    L.bottom_strips = *bottom;
    auto rate = cfg_.get_double_or("frame_rate_hz", 60.0, 1e-3, 10000.0);
    if (!rate) return rate.error();
    L.frame_rate_hz = *rate;

    if (!cfg_.contains("output_grid")) {
      return make_error(Errc::not_found, cfg_.source_name() +
                                             ": the file has no 'output_grid' (25 HandDof names or \"\", row-major "
                                             "5 x 5: the pose map the network writes); add it, see "
                                             "docs/stretch-glove-layout.md");
    }
    auto grid = cfg_.get_strings("output_grid");
    if (!grid) return grid.error();
    if (grid->size() != L.output_grid.size()) {
      return make_error(Errc::invalid_argument, cfg_.where("output_grid") + ": 'output_grid' must have 25 entries " +
                                                    "(5 rows of 5, row-major), but it has " +
                                                    std::to_string(grid->size()));
    }
    for (std::size_t k = 0; k < grid->size(); ++k) {
      const std::string& entry = (*grid)[k];
      if (entry.empty()) continue;
      auto dof = parse_hand_dof(entry);
      if (!dof) {
        std::vector<std::string_view> names;
        for (std::size_t i = 0; i < kHandDofCount; ++i) names.push_back(to_string(static_cast<HandDof>(i)));
        return make_error(Errc::invalid_argument,
                          cfg_.where("output_grid") + ": entry " + std::to_string(k) + " (row " +
                              std::to_string(k / kStretchGridSize) + ", col " + std::to_string(k % kStretchGridSize) +
                              ") of 'output_grid' is \"" + entry + "\", which is not a hand DoF; use \"\" for an " +
                              "empty cell or one of " + join(names));
      }
      L.output_grid[k] = *dof;
    }

    if (!cfg_.contains("cell")) {
      return make_error(Errc::not_found, cfg_.source_name() +
                                             ": the glove has no cells; add a 'cell' array of tables, see "
                                             "docs/stretch-glove-layout.md");
    }
    auto cells = cfg_.tables("cell");
    if (!cells) return cells.error();
    for (std::size_t i = 0; i < cells->size(); ++i) {
      auto c = parse_cell((*cells)[i], "cell[" + std::to_string(i) + "]");
      if (!c) return c.error();
      L.cells.push_back(std::move(*c));
    }

    // The cross-cell checks, with errors pointing at the offending line.
    if (auto st = check_layout(L, [&](std::size_t cell, std::string_view key) {
          const std::string k = cell == kNoCell ? std::string(key)
                                                : "cell[" + std::to_string(cell) + "]." + std::string(key);
          // A key a cell does not spell out (a default) has no line: point at the cell.
          const std::string at = cfg_.contains(k) || cell == kNoCell ? k : "cell[" + std::to_string(cell) + "]";
          return cfg_.where(at) + ": '" + k + "'";
        });
        !st) {
      return st.error();
    }
    return L;
  }

 private:
  Error error_at(const std::string& key, Errc code, const std::string& what) const {
    return make_error(code, cfg_.where(key) + ": '" + key + "' " + what);
  }

  Status only_keys(const Config& t, const std::string& prefix, const std::vector<std::string_view>& allowed) const {
    return t.check_keys(prefix.empty() ? "top level" : prefix, {allowed.begin(), allowed.end()},
                        "docs/stretch-glove-layout.md");
  }

  Result<int> strip_count(const char* key) const {
    if (!cfg_.contains(key)) {
      return make_error(Errc::not_found, cfg_.source_name() + ": the file has no '" + std::string(key) +
                                             "' (number of electrode strips in that conductive layer); add it");
    }
    auto v = cfg_.get_int(key);
    if (!v) return v.error();
    if (*v < 1 || *v > 1024) return error_at(key, Errc::out_of_range, "must be 1-1024 electrode strips");
    return static_cast<int>(*v);
  }

  Result<int> required_int(const Config& t, const std::string& P, const char* key, const char* what) const {
    if (!t.contains(key)) {
      return make_error(Errc::not_found, cfg_.where(P) + ": " + P + " has no '" + key + "' (" + what + "); add it");
    }
    auto v = t.get_int(key);
    if (!v) return v.error();
    if (*v < 0 || *v > 1 << 20) return error_at(P + "." + key, Errc::out_of_range, "must be a small whole number");
    return static_cast<int>(*v);
  }

  Result<double> required_double(const Config& t, const std::string& P, const char* key, double min, double max,
                                 const char* what) const {
    if (!t.contains(key)) {
      return make_error(Errc::not_found, cfg_.where(P) + ": " + P + " has no '" + key + "' (" + what + "); add it");
    }
    return t.get_double_or(key, 0.0, min, max);
  }

  template <typename E>
  Result<E> named(const Config& t, const std::string& P, const char* key, std::optional<E> (*parse)(std::string_view) noexcept,
                  const std::vector<std::string_view>& choices) const {
    auto s = t.get_string(key);
    if (!s) {
      if (s.error().code == Errc::not_found) {
        return make_error(Errc::not_found, cfg_.where(P) + ": " + P + " has no '" + key + "'; use one of " + join(choices));
      }
      return s.error();
    }
    auto v = parse(*s);
    if (!v) {
      return error_at(P + "." + key, Errc::invalid_argument, "= \"" + *s + "\" is not valid; use one of " + join(choices));
    }
    return *v;
  }

  Result<StretchCell> parse_cell(const Config& t, const std::string& P) const {
    if (auto st = only_keys(t, P,
                            {"name", "top_strip", "bottom_strip", "category", "direction", "segment", "along_fraction",
                             "across_fraction", "length_mm", "width_mm", "rest_capacitance_pf", "grid"});
        !st) {
      return st.error();
    }
    StretchCell c;
    auto name = t.get_string("name");
    if (!name) {
      if (name.error().code == Errc::not_found) {
        return make_error(Errc::not_found, cfg_.where(P) + ": " + P + " has no 'name'; name the cell (e.g. \"index_mcp_along\")");
      }
      return name.error();
    }
    c.name = *name;
    auto top = required_int(t, P, "top_strip", "its strip in the top conductive layer, from 0");
    if (!top) return top.error();
    c.top_strip = *top;
    auto bottom = required_int(t, P, "bottom_strip", "its strip in the bottom conductive layer, from 0");
    if (!bottom) return bottom.error();
    c.bottom_strip = *bottom;
    auto category = named<StretchCellCategory>(t, P, "category", &parse_stretch_cell_category,
                                               {kCategoryNames.begin(), kCategoryNames.end()});
    if (!category) return category.error();
    c.category = *category;
    auto direction = named<StretchDirection>(t, P, "direction", &parse_stretch_direction,
                                             {kDirectionNames.begin(), kDirectionNames.end()});
    if (!direction) return direction.error();
    c.direction = *direction;

    auto seg = t.get_string("segment");
    if (!seg) {
      if (seg.error().code == Errc::not_found) {
        return make_error(Errc::not_found, cfg_.where(P) + ": " + P + " has no 'segment'; name the bone it sits on: " +
                                               kSegmentChoices);
      }
      return seg.error();
    }
    auto j = parse_glove_segment(*seg);
    if (!j) {
      return error_at(P + ".segment", Errc::invalid_argument,
                      "= \"" + *seg + "\" is not a segment a cell can sit on; use " + kSegmentChoices);
    }
    c.segment = *j;
    auto along = required_double(t, P, "along_fraction", 0.0, 1.0,
                                 "fraction of the bone length from its joint, or of hand length on the dorsum, 0-1");
    if (!along) return along.error();
    c.along_fraction = *along;
    if (c.segment != HandJoint::wrist && t.contains("across_fraction")) {
      return error_at(P + ".across_fraction", Errc::invalid_argument,
                      "only applies on the dorsum; on a finger segment leave it out");
    }
    auto across = t.get_double_or("across_fraction", 0.0, -0.5, 0.5);
    if (!across) return across.error();
    c.across_fraction = *across;
    auto length = required_double(t, P, "length_mm", 0.0, 100.0, "cell size in its stretch direction, millimetres");
    if (!length) return length.error();
    auto width = required_double(t, P, "width_mm", 0.0, 100.0, "cell size across its stretch direction, millimetres");
    if (!width) return width.error();
    for (const char* k : {"length_mm", "width_mm"}) {
      if (!(*t.get_double(k) > 0.0)) return error_at(P + "." + k, Errc::out_of_range, "must be greater than zero");
    }
    c.length_m = *length / 1000.0;
    c.width_m = *width / 1000.0;
    auto c0 = required_double(t, P, "rest_capacitance_pf", 0.0, 1e4, "capacitance at rest, picofarads");
    if (!c0) return c0.error();
    if (!(*c0 > 0.0)) return error_at(P + ".rest_capacitance_pf", Errc::out_of_range, "must be greater than zero");
    c.rest_capacitance_pf = *c0;

    if (!t.contains("grid")) {
      return make_error(Errc::not_found, cfg_.where(P) + ": " + P +
                                             " has no 'grid' ([layer, row, col] of the network input; layer 0 = "
                                             "along cells, 1 = across cells); add it");
    }
    auto g = t.get_doubles("grid");
    if (!g) return g.error();
    if (g->size() != 3 || std::any_of(g->begin(), g->end(), [](double v) { return v != std::floor(v); })) {
      return error_at(P + ".grid", Errc::invalid_argument, "must be three whole numbers [layer, row, col]");
    }
    c.grid_layer = static_cast<int>((*g)[0]);
    c.grid_row = static_cast<int>((*g)[1]);
    c.grid_col = static_cast<int>((*g)[2]);
    return c;
  }

  const Config& cfg_;
};

}  // namespace

Result<StretchGloveLayout> StretchGloveLayout::parse(std::string_view toml_text, const std::string& source_name) {
  auto cfg = Config::parse(toml_text, source_name);
  if (!cfg) return cfg.error();
  return LayoutParser(*cfg).run();
}

Result<StretchGloveLayout> StretchGloveLayout::load(const std::filesystem::path& path) {
  auto text = read_input_file(path, "stretch-glove layout", 16 * kMiB);
  if (!text) {
    if (text.error().code != Errc::not_found) return text.error();
    return make_error(Errc::not_found, text.error().message + "; " "config/stretch_glove.toml is the thesis-like glove");
  }
  return parse(*text, path.string());
}

std::string StretchGloveLayout::to_toml() const {
  std::ostringstream s;
  s << "# Stretch-glove layout: electrode strips, sensor cells, network grids.\n"
       "# Format and read-out model: docs/stretch-glove-layout.md. Units are in the key names.\n\n";
  s << "name = " << toml_string(name) << "\n";
  s << "top_strips = " << top_strips << "\n";
  s << "bottom_strips = " << bottom_strips << "\n";
  s << "frame_rate_hz = " << num(frame_rate_hz) << "\n";

  s << "\n# The 5 x 5 pose map the network writes, row-major; \"\" is an empty cell.\n";
  s << "output_grid = [\n";
  for (int r = 0; r < kStretchGridSize; ++r) {
    s << " ";
    for (int c = 0; c < kStretchGridSize; ++c) {
      const auto& d = output_grid[static_cast<std::size_t>(r * kStretchGridSize + c)];
      s << " " << toml_string(d ? to_string(*d) : "") << ",";
    }
    s << "\n";
  }
  s << "]\n";

  std::size_t name_w = 0, seg_w = 0;
  for (const auto& c : cells) {
    name_w = std::max(name_w, toml_string(c.name).size());
    seg_w = std::max(seg_w, toml_string(segment_text(c.segment)).size());
  }
  auto padded = [](std::string text, std::size_t width) {
    text += ",";
    if (text.size() < width + 1) text.append(width + 1 - text.size(), ' ');
    return text;
  };
  s << "\n# top_strip/bottom_strip: the two electrode strips that cross at the cell; category: joint,\n"
       "# abduction, perpendicular or dorsum (Sec. 5.2.1); direction: along or across the bone; segment:\n"
       "# \"dorsum\" or the XR joint that starts the bone; along_fraction: of the bone from that joint\n"
       "# (dorsum: of hand length from the wrist); across_fraction (dorsum only): of hand width, + toward\n"
       "# the little finger; length_mm: in the stretch direction; grid: [layer, row, col] of the input.\n";
  s << "cell = [\n";
  for (const auto& c : cells) {
    s << "  { name = " << padded(toml_string(c.name), name_w) << " top_strip = " << padded(std::to_string(c.top_strip), 2)
      << " bottom_strip = " << padded(std::to_string(c.bottom_strip), 2)
      << " category = " << padded(toml_string(to_string(c.category)), 15)
      << " direction = " << padded(toml_string(to_string(c.direction)), 8)
      << " segment = " << padded(toml_string(segment_text(c.segment)), seg_w)
      << " along_fraction = " << num(c.along_fraction);
    if (c.segment == HandJoint::wrist) s << ", across_fraction = " << num(c.across_fraction);
    s << ", length_mm = " << mm_text(c.length_m) << ", width_mm = " << mm_text(c.width_m)
      << ", rest_capacitance_pf = " << num(c.rest_capacitance_pf) << ", grid = [" << c.grid_layer << ", "
      << c.grid_row << ", " << c.grid_col << "] },\n";
  }
  s << "]\n";
  return s.str();
}

}  // namespace proprio
