// Stretch sensor array layouts (issue 30): the measurement plan, the
// readability check against the thesis's own example, the shipped stand-ins,
// and the TOML format with its errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>

#include "proprio/stretch_array/array_layout.hpp"

namespace proprio::stretch_array {
namespace {

TEST(StripArrayLayout, TheThesisTwoByThreeExampleNeedsTheExtraMeasurements) {
  // Fig. 4.6: two strips on one layer, three on the other, all six crossings.
  const StripArrayLayout L = StripArrayLayout::grid("fig_4_6", 2, 3, 0.01, 0.005);
  ASSERT_TRUE(L.validate().ok());
  const LayoutCheck r = check_layout(L);
  EXPECT_EQ(r.cells, 6u);
  EXPECT_EQ(r.rows_m1, 6u);
  EXPECT_EQ(r.rank_m1, 4) << "M^I alone cannot separate the six cells";
  EXPECT_TRUE(std::isinf(r.condition_m1));
  EXPECT_EQ(r.rows_all, 11u) << "plus the five single strips";
  EXPECT_EQ(r.rank_all, 6);
  EXPECT_NEAR(r.condition_all, 2.6457513, 1e-6) << "sqrt(7), by numpy on the same matrix";
  EXPECT_TRUE(r.readable());
  EXPECT_TRUE(require_readable(L).ok());
}

TEST(StripArrayLayout, AMeasurementChargesTheCellsWithExactlyOnePlateOnTheSource) {
  const StripArrayLayout L = StripArrayLayout::grid("g", 2, 3, 0.01, 0.005);
  const auto plan = L.measurement_plan();
  const Eigen::MatrixXd M = L.measurement_matrix();
  // Row (top 0, bottom 2): the thesis's C(1 Gamma, 2 A B) = C_1A + C_1B + C_2Gamma.
  const auto row = static_cast<Eigen::Index>(0 * 3 + 2);
  ASSERT_EQ(plan[static_cast<std::size_t>(row)].top_sources, std::vector<std::size_t>{0});
  ASSERT_EQ(plan[static_cast<std::size_t>(row)].bottom_sources, std::vector<std::size_t>{2});
  const auto cell = [&](std::size_t t, std::size_t b) { return static_cast<Eigen::Index>(t * 3 + b); };
  EXPECT_EQ(M(row, cell(0, 0)), 1.0);
  EXPECT_EQ(M(row, cell(0, 1)), 1.0);
  EXPECT_EQ(M(row, cell(1, 2)), 1.0);
  EXPECT_EQ(M(row, cell(0, 2)), 0.0) << "both plates on the source";
  EXPECT_EQ(M(row, cell(1, 0)), 0.0) << "both plates grounded";
  EXPECT_EQ(M.row(row).sum(), 3.0);
  // The single top strip 0: every cell on it.
  EXPECT_EQ(M.row(6).sum(), 3.0);
  EXPECT_FALSE(plan[6].mandatory);
}

// With the single-strip rows every layout is readable: a cell on top strip t
// and bottom strip b is (S_t + S_b - P_tb) / 2 from the two single-strip
// sums and the pair's row. M^I alone is not: random layouts show both.
TEST(StripArrayLayout, EveryValidLayoutIsReadableWithTheSingleStripRows) {
  std::uint32_t seed = 29;
  const auto next = [&] { return seed = seed * 1664525u + 1013904223u; };
  int m1_deficient = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const std::size_t n = 1 + next() % 6, k = 1 + next() % 6;
    StripArrayLayout L = StripArrayLayout::grid("random", n, k, 0.01, 0.005);
    std::erase_if(L.cells, [&](const ArrayCell&) { return next() % 3 == 0; });
    if (L.cells.empty()) continue;
    ASSERT_TRUE(L.validate().ok());
    const LayoutCheck r = check_layout(L);
    EXPECT_TRUE(r.readable()) << n << " x " << k << ", " << r.describe();
    EXPECT_TRUE(require_readable(L).ok());
    m1_deficient += r.rank_m1 < static_cast<long>(r.cells);
  }
  EXPECT_GT(m1_deficient, 10) << "M^I alone leaves some of them unreadable (18 of these 200)";
  // What is refused is a layout whose strips cross twice: no plan can split those cells.
  StripArrayLayout twice = StripArrayLayout::grid("g", 1, 2, 0.01, 0.005);
  twice.cells.push_back({"again", 0, 1, {}});
  const auto st = twice.validate();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("cross twice"), std::string::npos) << st.error().message;
}

TEST(StripArrayLayout, TheShippedStandInsHaveTheThesisCountsAndAreReadable) {
  const StripArrayLayout p = StripArrayLayout::prototype_92();
  EXPECT_EQ(p.top_strips.size(), 12u);
  EXPECT_EQ(p.bottom_strips.size(), 12u);
  EXPECT_EQ(p.cell_count(), 92u);
  ASSERT_TRUE(p.validate().ok());
  const LayoutCheck rp = check_layout(p);
  EXPECT_TRUE(rp.readable()) << rp.describe();
  EXPECT_LT(rp.condition_all, 20.0) << rp.describe();
  const StripArrayLayout b = StripArrayLayout::biceps_144();
  EXPECT_EQ(b.cell_count(), 144u);
  const LayoutCheck rb = check_layout(b);
  EXPECT_TRUE(rb.readable()) << rb.describe();
  EXPECT_EQ(rb.rank_m1, 144) << "a full 12 x 12 grid is readable with M^I alone";
}

TEST(StripArrayLayout, OutlinesAreasAndCentroids) {
  const StripArrayLayout L = StripArrayLayout::grid("g", 2, 2, 0.012, 0.008);
  EXPECT_NEAR(L.rest_area_m2(0), 0.008 * 0.008, 1e-15);
  EXPECT_NEAR((L.centroid(3) - Point2(0.012, 0.012)).norm(), 0.0, 1e-12);
  StripArrayLayout T = L;
  T.cells[0].outline_m = {{0, 0}, {0.004, 0}, {0, 0.003}};  // a right triangle
  ASSERT_TRUE(T.validate().ok());
  EXPECT_NEAR(T.rest_area_m2(0), 0.5 * 0.004 * 0.003, 1e-15);
  EXPECT_NEAR((T.centroid(0) - Point2(0.004 / 3, 0.001)).norm(), 0.0, 1e-12);
  T.cells[0].outline_m = {{0, 0}, {0, 0.003}, {0.004, 0}};  // clockwise
  EXPECT_FALSE(T.validate().ok());
  T.cells[0].outline_m = {{0, 0}, {0.004, 0.004}, {0.004, 0}, {0, 0.004}};  // a bow tie
  const auto st = T.validate();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("crosses itself"), std::string::npos) << st.error().message;
}

TEST(StripArrayLayout, TomlRoundTripsAndErrorsNameTheFileAndKey) {
  StripArrayLayout L = StripArrayLayout::prototype_92();
  L.cells[3].outline_m = {{0.0, 0.0}, {0.01, 0.0}, {0.01, 0.01}, {0.0, 0.01}};
  auto back = StripArrayLayout::parse(L.to_toml(), "round.toml");
  ASSERT_TRUE(back.ok()) << back.error().message;
  ASSERT_EQ(back->cell_count(), L.cell_count());
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    EXPECT_EQ(back->cells[c].name, L.cells[c].name);
    EXPECT_NEAR(back->rest_area_m2(c), L.rest_area_m2(c), 1e-15);
  }
  EXPECT_NEAR(back->sheet.youngs_modulus_pa, L.sheet.youngs_modulus_pa, 1e-3);

  const std::string strips = "[[top_strip]]\nname = \"1\"\n[[bottom_strip]]\nname = \"A\"\n";
  auto unknown = StripArrayLayout::parse(strips + "[[cell]]\ntop = \"2\"\nbottom = \"A\"\n", "l.toml");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("l.toml:"), std::string::npos) << unknown.error().message;
  EXPECT_NE(unknown.error().message.find("no top strip named '2'"), std::string::npos) << unknown.error().message;
  auto typo = StripArrayLayout::parse(strips + "[[cell]]\ntop = \"1\"\nbottom = \"A\"\noutline = [0, 0]\n", "l.toml");
  ASSERT_FALSE(typo.ok());
  EXPECT_NE(typo.error().message.find("outline"), std::string::npos) << typo.error().message;
  auto odd = StripArrayLayout::parse(strips + "[[cell]]\ntop = \"1\"\nbottom = \"A\"\noutline_m = [0, 0, 1]\n", "l.toml");
  ASSERT_FALSE(odd.ok());
  EXPECT_NE(odd.error().message.find("x1, y1, x2, y2"), std::string::npos) << odd.error().message;
  auto nan = StripArrayLayout::parse(strips + "[[cell]]\ntop = \"1\"\nbottom = \"A\"\n[sheet]\npoisson_ratio = nan\n",
                                     "l.toml");
  EXPECT_FALSE(nan.ok());
  EXPECT_FALSE(StripArrayLayout::parse(strips, "l.toml").ok()) << "no cells";
}

}  // namespace
}  // namespace proprio::stretch_array
