// The matrix read-out on array layouts (issue 30): cell capacitances from the
// stretch model go through the measurement plan and come back out of the
// least-squares solve, for the thesis's 2 x 3 example (which M^I alone cannot
// read) and the 92-cell stand-in.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/capacitance.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"

namespace proprio::stretch_array {
namespace {

// The true cell capacitances (pF) for a stretch field over the sheet, and
// what the board measures for them, row by row.
struct Truth {
  std::vector<double> cells_pf;
  std::vector<double> measured_pf;
};
Truth stretched(const StripArrayLayout& L, double noise_pf, std::uint32_t seed) {
  Truth t;
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_pf);
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    const double c0 = 1e12 * plate_capacitance_f(L.sheet.relative_permittivity, L.rest_area_m2(c),
                                                 L.sheet.dielectric_thickness_m);
    // Area stretch growing across the sheet, 1.0 to 1.5 (eq. 4.3).
    const double area_ratio = 1.0 + 0.5 * (L.centroid(c).x() + L.centroid(c).y()) / 0.3;
    t.cells_pf.push_back(c0 * area_capacitance_ratio(area_ratio));
  }
  const Eigen::MatrixXd M = L.measurement_matrix(true);
  for (Eigen::Index r = 0; r < M.rows(); ++r) {
    double sum = 0.0;
    for (Eigen::Index c = 0; c < M.cols(); ++c) sum += M(r, c) * t.cells_pf[static_cast<std::size_t>(c)];
    t.measured_pf.push_back(sum + noise(rng));
  }
  return t;
}

TEST(ArrayReadout, RecoversTheCellsOfTheThesisExampleThatMIAloneCannot) {
  const StripArrayLayout L = StripArrayLayout::grid("fig_4_6", 2, 3, 0.02, 0.015);
  auto readout = make_array_readout(L);
  ASSERT_TRUE(readout) << readout.error().message;
  EXPECT_EQ(readout->measurement_count(), 11u);
  const Truth t = stretched(L, 0.0, 1);
  CellFrame frame = readout->make_frame();
  ASSERT_TRUE(readout->solve(t.measured_pf, 1000, frame).ok());
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    EXPECT_TRUE(frame.valid(c));
    EXPECT_NEAR(frame.cells_pf[c], t.cells_pf[c], 1e-3 * t.cells_pf[c]) << L.cells[c].name;
  }
  // The same cells from M^I alone: refused, not solved wrongly.
  std::vector<double> rest(L.cell_count(), 10.0);
  auto m1_only = MatrixReadout::create(L.measurement_matrix(false), rest);
  ASSERT_FALSE(m1_only);
  EXPECT_NE(m1_only.error().message.find("rank 4 for 6 cells"), std::string::npos) << m1_only.error().message;
}

TEST(ArrayReadout, TheNinetyTwoCellStandInWithBoardNoise) {
  const StripArrayLayout L = StripArrayLayout::prototype_92();
  auto readout = make_array_readout(L);
  ASSERT_TRUE(readout) << readout.error().message;
  const Truth t = stretched(L, 0.05, 7);  // 0.05 pF rms per measurement
  CellFrame frame = readout->make_frame();
  ASSERT_TRUE(readout->solve(t.measured_pf, 1000, frame).ok());
  double worst = 0.0;
  for (std::size_t c = 0; c < L.cell_count(); ++c) {
    worst = std::max(worst, std::abs(frame.cells_pf[c] - t.cells_pf[c]) / t.cells_pf[c]);
  }
  // 8 x 8 mm cells are 3.2-7.1 pF; least squares over 168 rows keeps the
  // cells' error near the rows' (condition number 9.1).
  EXPECT_LT(worst, 0.05) << "worst relative cell error";
  std::printf("92-cell stand-in, 0.05 pF noise per row: worst cell error %.2f %%\n", 100.0 * worst);
}

TEST(ArrayReadout, RefusesMismatchedInput) {
  Eigen::MatrixXd M = Eigen::MatrixXd::Identity(3, 3);
  EXPECT_FALSE(MatrixReadout::create(M, {1.0, 2.0}));
  EXPECT_FALSE(MatrixReadout::create(M, {1.0, 2.0, NAN}));
  EXPECT_FALSE(MatrixReadout::create(Eigen::MatrixXd::Identity(2, 3), {1.0, 2.0, 3.0}));
  EXPECT_TRUE(MatrixReadout::create(M, {1.0, 2.0, 3.0}));
}

}  // namespace
}  // namespace proprio::stretch_array
