// The cell capacitance model (eqs. 4.1-4.8) and the 555 read-out's conversion,
// against closed forms.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "proprio/stretch_array/capacitance.hpp"

namespace proprio::stretch_array {
namespace {

TEST(CellCapacitance, PlateCapacitorAndTheThesisRatios) {
  // A 15 x 50 mm cell over 0.5 mm of er = 2.8 silicone: 37.2 pF.
  const double C0 = plate_capacitance_f(2.8, 0.015 * 0.050, 0.5e-3);
  EXPECT_NEAR(C0, 2.8 * 8.8541878128e-12 * 7.5e-4 / 0.5e-3, 1e-18);
  EXPECT_NEAR(C0 * 1e12, 37.19, 0.01);
  EXPECT_DOUBLE_EQ(uniaxial_capacitance_ratio(1.3), 1.3);
  EXPECT_DOUBLE_EQ(area_capacitance_ratio(1.5), 2.25);
  EXPECT_DOUBLE_EQ(area_ratio_from_capacitance(2.25), 1.5);
  EXPECT_TRUE(std::isnan(area_ratio_from_capacitance(-0.1)));
  EXPECT_TRUE(std::isnan(plate_capacitance_f(2.8, 1e-4, 0.0)));
}

TEST(CellCapacitance, NonUniformStretchSumsItsTriangles) {
  // Uniform stretch of every triangle: (4.8) is (4.3).
  const std::vector<double> rest = {1.0, 2.0, 3.0};
  const std::vector<double> uniform = {1.4, 2.8, 4.2};
  EXPECT_NEAR(cell_capacitance_ratio(rest, uniform), 1.4 * 1.4, 1e-12);
  // Half the cell doubled, half unchanged: (1/A0)(4 + 1) = 2.5, not (1.5)^2 = 2.25.
  EXPECT_NEAR(cell_capacitance_ratio(std::vector<double>{1.0, 1.0}, std::vector<double>{2.0, 1.0}), 2.5, 1e-12);
  EXPECT_TRUE(std::isnan(cell_capacitance_ratio(std::vector<double>{1.0}, std::vector<double>{1.0, 2.0})));
  EXPECT_TRUE(std::isnan(cell_capacitance_ratio(std::vector<double>{0.0}, std::vector<double>{1.0})));
  EXPECT_TRUE(std::isnan(cell_capacitance_ratio(std::vector<double>{1.0}, std::vector<double>{NAN})));
}

TEST(Timer555, FrequencyAndCapacitanceAreInverse) {
  const Timer555 t;
  ASSERT_TRUE(t.validate().ok());
  // f = 1 / ((470k + 94k) 100 pF ln 2) = 25.58 kHz.
  EXPECT_NEAR(t.frequency_hz(100e-12), 1.0 / (564e3 * 100e-12 * std::log(2.0)), 1e-6);
  EXPECT_NEAR(t.frequency_hz(100e-12), 25580.0, 1.0);
  for (double c : {10e-12, 100e-12, 500e-12}) EXPECT_NEAR(t.capacitance_f(t.frequency_hz(c)), c, 1e-21);
  EXPECT_TRUE(std::isnan(t.capacitance_f(0.0)));
  EXPECT_TRUE(std::isnan(t.frequency_hz(-1e-12)));
  EXPECT_GT(t.resolution_f(100e-12), 0.0);
  Timer555 bad = t;
  bad.r2_ohm = 0.0;
  EXPECT_FALSE(bad.validate().ok());
}

}  // namespace
}  // namespace proprio::stretch_array
