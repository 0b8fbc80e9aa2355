// The stretch-glove layout: the thesis-like default, the TOML format and its
// errors, and the read-out matrix of Glauser 2019 eqs 4.5-4.7.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <algorithm>
#include <set>
#include <sstream>

#include "proprio/glove_descriptions/stretch_glove_layout.hpp"

namespace proprio {
namespace {

std::string source_path(const char* relative) { return std::string(PROPRIO_SOURCE_DIR) + "/" + relative; }

// The 1-based line of the first line of `text` containing `needle`.
int line_of(const std::string& text, const std::string& needle) {
  const auto pos = text.find(needle);
  if (pos == std::string::npos) return -1;
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(pos), '\n'));
}

// The example of the thesis's Fig. 4.6: top strips 1, 2 and bottom strips
// A, B, Gamma, all six crossings are cells; plus a third top lead without
// cells, which the read-out needs (see Fig46RowMatchesTheThesis).
std::string fig46_toml() {
  return R"(name = "fig 4.6"
top_strips = 3
bottom_strips = 3
output_grid = ["index_mcp_flexion", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", "", ""]
cell = [
  { name = "1A", top_strip = 0, bottom_strip = 0, category = "joint", direction = "along", segment = "index_proximal", along_fraction = 0.1, length_mm = 11.5, width_mm = 5.0, rest_capacitance_pf = 9.8, grid = [0, 0, 0] },
  { name = "2A", top_strip = 1, bottom_strip = 0, category = "joint", direction = "along", segment = "index_intermediate", along_fraction = 0.1, length_mm = 11.5, width_mm = 5.0, rest_capacitance_pf = 9.8, grid = [0, 0, 1] },
  { name = "1B", top_strip = 0, bottom_strip = 1, category = "perpendicular", direction = "across", segment = "index_proximal", along_fraction = 0.6, length_mm = 7.5, width_mm = 5.0, rest_capacitance_pf = 6.4, grid = [1, 0, 0] },
  { name = "2B", top_strip = 1, bottom_strip = 1, category = "perpendicular", direction = "across", segment = "index_intermediate", along_fraction = 0.6, length_mm = 7.5, width_mm = 5.0, rest_capacitance_pf = 6.4, grid = [1, 0, 1] },
  { name = "1G", top_strip = 0, bottom_strip = 2, category = "dorsum", direction = "along", segment = "dorsum", along_fraction = 0.3, across_fraction = -0.1, length_mm = 11.5, width_mm = 5.0, rest_capacitance_pf = 9.8, grid = [0, 1, 0] },
  { name = "2G", top_strip = 1, bottom_strip = 2, category = "dorsum", direction = "across", segment = "dorsum", along_fraction = 0.2, across_fraction = 0.1, length_mm = 7.5, width_mm = 5.0, rest_capacitance_pf = 6.4, grid = [1, 1, 0] },
]
)";
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  if (pos != std::string::npos) text.replace(pos, from.size(), to);
  return text;
}

// Expects parse to fail with a message naming test.toml:<line of `needle`> and containing `what`.
void expect_error_at(const std::string& text, const std::string& needle, const std::string& what) {
  auto r = StretchGloveLayout::parse(text, "test.toml");
  ASSERT_FALSE(r.ok()) << "expected an error about " << what;
  const std::string msg = r.error().message;
  const int line = line_of(text, needle);
  ASSERT_GT(line, 0) << needle;
  EXPECT_NE(msg.find("test.toml:" + std::to_string(line) + ":"), std::string::npos) << msg;
  EXPECT_NE(msg.find(what), std::string::npos) << msg;
}

TEST(StretchLayout, ConfigFileIsTheThesisDefault) {
  auto loaded = StretchGloveLayout::load(source_path("config/stretch_glove.toml"));
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  StretchGloveLayout expected = StretchGloveLayout::thesis_default();
  expected.origin = loaded->origin;
  EXPECT_EQ(*loaded, expected) << "config/stretch_glove.toml and StretchGloveLayout::thesis_default() disagree";
}

TEST(StretchLayout, ThesisDefaultHasTheThesisCounts) {
  const auto L = StretchGloveLayout::thesis_default();
  ASSERT_TRUE(L.validate().ok()) << L.validate().error().message;
  EXPECT_EQ(L.cell_count(), 44u);
  EXPECT_EQ(L.top_strips + L.bottom_strips, 27);  // "only 27 leads in 2 layers are needed"
  EXPECT_EQ(L.measurement_count(), 182u);         // "a full cycle of combined measurements (180 updates)"
  // Sec. 5.2.1 lists the sensor numbers of each category; cell i plays sensor i.
  auto ids = [](std::initializer_list<std::pair<int, int>> ranges) {
    std::set<int> out;
    for (auto [a, b] : ranges) {
      for (int i = a; i <= b; ++i) out.insert(i);
    }
    return out;
  };
  const std::set<int> joint = ids({{21, 24}, {32, 36}, {40, 42}, {0, 0}, {20, 20}});
  const std::set<int> abduction = ids({{16, 16}, {25, 27}});
  const std::set<int> perpendicular = ids({{8, 9}, {29, 31}, {37, 39}, {43, 43}, {1, 1}, {28, 28}});
  const std::set<int> dorsum_across = ids({{2, 2}, {4, 4}, {7, 7}, {10, 10}, {17, 19}});
  const std::set<int> dorsum_along = ids({{3, 3}, {5, 6}, {11, 15}});
  for (int i = 0; i < 44; ++i) {
    const StretchCell& c = L.cells[static_cast<std::size_t>(i)];
    SCOPED_TRACE(c.name);
    if (joint.count(i)) {
      EXPECT_EQ(c.category, StretchCellCategory::joint);
      EXPECT_EQ(c.direction, StretchDirection::along);
    } else if (abduction.count(i)) {
      EXPECT_EQ(c.category, StretchCellCategory::abduction);
    } else if (perpendicular.count(i)) {
      EXPECT_EQ(c.category, StretchCellCategory::perpendicular);
      EXPECT_EQ(c.direction, StretchDirection::across);
    } else {
      EXPECT_EQ(c.category, StretchCellCategory::dorsum);
      EXPECT_EQ(c.direction, dorsum_across.count(i) ? StretchDirection::across : StretchDirection::along);
      EXPECT_TRUE(dorsum_across.count(i) || dorsum_along.count(i));
    }
    // Cell sizes of Sec. 5.2.3: 5 x 7.5 or 5 x 11.5 mm.
    EXPECT_NEAR(c.width_m, 0.005, 1e-12);
    EXPECT_TRUE(std::abs(c.length_m - 0.0075) < 1e-12 || std::abs(c.length_m - 0.0115) < 1e-12);
  }
  // The thesis names 21, 33, 40 as index-joint sensors and 29, 37, 43 as
  // volume-sensitive index sensors.
  for (int i : {21, 33, 40, 29, 37, 43}) {
    EXPECT_NE(L.cells[static_cast<std::size_t>(i)].name.find("index"), std::string::npos) << i;
  }
}

TEST(StretchLayout, ToTomlRoundTrips) {
  const auto L = StretchGloveLayout::thesis_default();
  auto back = StretchGloveLayout::parse(L.to_toml(), "roundtrip");
  ASSERT_TRUE(back.ok()) << back.error().message;
  back->origin = L.origin;
  EXPECT_EQ(*back, L);
}

TEST(StretchLayout, Fig46RowMatchesTheThesis) {
  // "electrodes 1 and Gamma ... serve as the source electrode ... the
  // measurement contributes C(1Gamma, 2AB) = C_1A + C_1B + C_2Gamma".
  auto L = StretchGloveLayout::parse(fig46_toml(), "fig46");
  ASSERT_TRUE(L.ok()) << L.error().message;
  L->top_strips = 2;  // the figure's strips only
  const Eigen::MatrixXd M = L->measurement_matrix();
  ASSERT_EQ(M.rows(), 6);
  ASSERT_EQ(M.cols(), 6);
  const Eigen::Index row = 0 * 3 + 2;  // top strip "1" (0), bottom strip "Gamma" (2)
  Eigen::RowVectorXd expected = Eigen::RowVectorXd::Zero(6);
  expected(*L->find_cell("1A")) = 1;
  expected(*L->find_cell("1B")) = 1;
  expected(*L->find_cell("2G")) = 1;
  EXPECT_EQ(M.row(row), expected);
  // With only two top strips, row (2, b) is the complement of row (1, b), so
  // the six (top, bottom) pairs give rank 4: the figure's example cannot be
  // read out by this rule alone. A third top lead (no cells on it) adds rows
  // that see only a bottom strip's cells and makes it solvable.
  EXPECT_EQ(Eigen::FullPivLU<Eigen::MatrixXd>(M).rank(), 4);
  L->top_strips = 3;
  EXPECT_EQ(Eigen::FullPivLU<Eigen::MatrixXd>(L->measurement_matrix()).rank(), 6);
  EXPECT_TRUE(L->validate().ok());
}

TEST(StretchLayout, MeasurementMatrixHasXorRowsAndFullRank) {
  const auto L = StretchGloveLayout::thesis_default();
  const Eigen::MatrixXd M = L.measurement_matrix();
  ASSERT_EQ(M.rows(), 182);
  ASSERT_EQ(M.cols(), 44);
  // Row (t, b) counts the cells with a plate on exactly one source strip:
  // those on top strip t plus those on bottom strip b, minus twice the one
  // at (t, b) if there is one.
  for (int t = 0; t < L.top_strips; ++t) {
    for (int b = 0; b < L.bottom_strips; ++b) {
      int on_t = 0, on_b = 0, at = 0;
      for (const auto& c : L.cells) {
        on_t += c.top_strip == t;
        on_b += c.bottom_strip == b;
        at += c.top_strip == t && c.bottom_strip == b;
      }
      EXPECT_EQ(M.row(t * L.bottom_strips + b).sum(), on_t + on_b - 2 * at) << t << "," << b;
    }
  }
  EXPECT_TRUE(((M.array() == 0.0) || (M.array() == 1.0)).all());
  EXPECT_EQ(Eigen::FullPivLU<Eigen::MatrixXd>(M).rank(), 44);
}

TEST(StretchLayout, GridsFollowTheHand) {
  const auto L = StretchGloveLayout::thesis_default();
  const auto index = L.input_grid_index();
  ASSERT_EQ(index.size(), 44u);
  EXPECT_EQ(std::set<int>(index.begin(), index.end()).size(), 44u);
  for (std::size_t i = 0; i < L.cells.size(); ++i) {
    const auto& c = L.cells[i];
    EXPECT_EQ(index[i], c.grid_layer * 25 + c.grid_row * 5 + c.grid_col);
    // Layer 0 holds along cells, layer 1 across cells.
    EXPECT_EQ(c.grid_layer, c.direction == StretchDirection::along ? 0 : 1) << c.name;
    // Finger cells sit in their finger's column.
    for (int col = 0; col < 5; ++col) {
      const std::string finger[] = {"thumb", "index", "middle", "ring", "little"};
      if (c.segment != HandJoint::wrist && c.category != StretchCellCategory::abduction &&
          c.name.rfind(finger[col] + "_", 0) == 0) {
        EXPECT_EQ(c.grid_col, col) << c.name;
      }
    }
  }
  // DIP cells distal of PIP cells distal of MCP cells.
  EXPECT_LT(L.cells[*L.find_cell("index_dip_along")].grid_row, L.cells[*L.find_cell("index_pip_along")].grid_row);
  EXPECT_LT(L.cells[*L.find_cell("index_pip_along")].grid_row, L.cells[*L.find_cell("index_mcp_along")].grid_row);

  std::set<HandDof> dofs;
  for (int r = 0; r < 5; ++r) {
    EXPECT_FALSE(L.output_grid[static_cast<std::size_t>(r * 5 + 4)].has_value());
    for (int col = 0; col < 4; ++col) {
      const auto& d = L.output_grid[static_cast<std::size_t>(r * 5 + col)];
      ASSERT_TRUE(d.has_value());
      dofs.insert(*d);
      // Row r is finger r; column 0 its abduction.
      EXPECT_EQ(index_of(*d) / 4, static_cast<std::size_t>(r));
      EXPECT_EQ(is_abduction(*d), col == 0);
    }
  }
  EXPECT_EQ(dofs.size(), kHandDofCount);
  EXPECT_EQ(L.output_grid[0], HandDof::thumb_cmc_abduction);
  EXPECT_EQ(L.output_grid[1], HandDof::thumb_cmc_flexion);
  EXPECT_EQ(L.output_grid[2], HandDof::thumb_mcp_flexion);
  EXPECT_EQ(L.output_grid[3], HandDof::thumb_ip_flexion);
}

TEST(StretchLayout, ParseErrorsNameFileAndLine) {
  const std::string ok = fig46_toml();
  ASSERT_TRUE(StretchGloveLayout::parse(ok, "test.toml").ok());

  expect_error_at(replaced(ok, "name = \"2B\", top_strip = 1", "name = \"2B\", top_strip = 7"), "name = \"2B\"",
                  "top_strip");
  expect_error_at(replaced(ok, "name = \"2G\", top_strip = 1, bottom_strip = 2", "name = \"2G\", top_strip = 1, bottom_strip = 1"),
                  "name = \"2G\"", "already cross at cell '2B'");
  expect_error_at(replaced(ok, "name = \"2G\"", "name = \"1G\""), "name = \"1G\", top_strip = 1", "already the name");
  expect_error_at(replaced(ok, "grid = [1, 1, 0]", "grid = [1, 0, 1]"), "name = \"2G\"", "already holds cell '2B'");
  expect_error_at(replaced(ok, "grid = [1, 1, 0]", "grid = [2, 1, 0]"), "name = \"2G\"", "outside the input grid");
  expect_error_at(replaced(ok, "along_fraction = 0.3,", "along_frac = 0.3,"), "along_frac =", "unknown key");
  expect_error_at(replaced(ok, "segment = \"dorsum\", along_fraction = 0.3", "segment = \"palm\", along_fraction = 0.3"),
                  "\"palm\"", "not a segment");
  expect_error_at(replaced(ok, "category = \"joint\", direction = \"along\", segment = \"index_intermediate\"",
                           "category = \"joints\", direction = \"along\", segment = \"index_intermediate\""),
                  "\"joints\"", "category");
  expect_error_at(replaced(ok, "\"index_mcp_flexion\"", "\"index_mcp_flex\""), "output_grid", "not a hand DoF");
  expect_error_at(replaced(ok, "rest_capacitance_pf = 6.4, grid = [1, 1, 0]", "rest_capacitance_pf = -6.4, grid = [1, 1, 0]"),
                  "-6.4", "rest_capacitance_pf");
}

TEST(StretchLayout, RankDeficientLayoutIsRejected) {
  // A full 2 x 2 grid: rows (0,0) and (1,1) measure the same pair of cells,
  // as do (0,1) and (1,0), so rank 2 for 4 cells.
  std::string text = fig46_toml();
  text = replaced(text, "top_strips = 3", "top_strips = 2");
  text = replaced(text, "bottom_strips = 3", "bottom_strips = 2");
  const auto first = text.find("  { name = \"1G\"");
  const auto end = text.find("]\n", text.find("{ name = \"2G\""));
  text.erase(first, end - first);
  auto r = StretchGloveLayout::parse(text, "test.toml");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("rank 2 for 4 cells"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("1A"), std::string::npos) << r.error().message;
}

TEST(StretchLayout, LoadErrors) {
  auto missing = StretchGloveLayout::load("/nonexistent/stretch.toml");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
  auto syntax = StretchGloveLayout::parse("name = \"x\"\ntop_strips = [\n", "bad.toml");
  ASSERT_FALSE(syntax.ok());
  EXPECT_NE(syntax.error().message.find("bad.toml:"), std::string::npos) << syntax.error().message;
}

TEST(StretchLayout, ValidateCatchesCodeBuiltMistakes) {
  auto L = StretchGloveLayout::thesis_default();
  L.cells[5].bottom_strip = L.cells[4].bottom_strip;
  L.cells[5].top_strip = L.cells[4].top_strip;
  const Status st = L.validate();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find(L.cells[5].name), std::string::npos) << st.error().message;
}

TEST(StretchLayout, DescribeSaysWhatItIs) {
  const std::string d = StretchGloveLayout::thesis_default().describe();
  EXPECT_NE(d.find("44 cells on 27 leads"), std::string::npos) << d;
  EXPECT_NE(d.find("joint 14, abduction 4, perpendicular 11, dorsum 15"), std::string::npos) << d;
}

}  // namespace
}  // namespace proprio
