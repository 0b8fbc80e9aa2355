// The body proxies and their motion signals (input/elastic_sheet, issue 30).
#include <gtest/gtest.h>

#include <cmath>

#include <Eigen/Geometry>

#include "proprio/elastic_sheet/body_proxy.hpp"

namespace es = proprio::elastic_sheet;

TEST(MotionSignal, SeededBoundedStartsAtRestAndIsSmooth) {
  es::MotionSignalOptions o;
  o.seed = 3;
  const es::MotionSignal a(o), b(o);
  o.seed = 4;
  const es::MotionSignal c(o);
  EXPECT_EQ(a.bipolar(0.0), 0.0);
  EXPECT_EQ(a.unipolar(0.0), 0.0);
  double differs = 0.0, lo = 1.0, hi = -1.0, peak_speed = 0.0;
  const double dt = 0.01;
  for (int k = 0; k < 12000; ++k) {  // two minutes
    const double t = k * dt;
    EXPECT_EQ(a.bipolar(t), b.bipolar(t));
    differs = std::max(differs, std::abs(a.bipolar(t) - c.bipolar(t)));
    ASSERT_GT(a.bipolar(t), -1.0);
    ASSERT_LT(a.bipolar(t), 1.0);
    ASSERT_GE(a.unipolar(t), 0.0);
    ASSERT_LT(a.unipolar(t), 1.0);
    lo = std::min(lo, a.bipolar(t));
    hi = std::max(hi, a.bipolar(t));
    // Bounded speed: |d/dt tanh(g z / rms)| <= g omega_max sum(a) / rms
    // <= g omega_max sqrt(2 K) (Cauchy-Schwarz), plus the ramp's 1.5 / ramp_s.
    const double bound = o.gain * 2.0 * 3.14159265 / o.min_period_s * std::sqrt(2.0 * o.components) + 1.5 / o.ramp_s;
    ASSERT_LT(std::abs(a.bipolar(t + dt) - a.bipolar(t)) / dt, bound);
    peak_speed = std::max(peak_speed, std::abs(a.bipolar(t + dt) - a.bipolar(t)) / dt);
  }
  EXPECT_GT(differs, 0.2);
  // Not a jerky signal either: the full range (2) takes more than half a second.
  EXPECT_LT(peak_speed, 4.0);
  // It visits most of its range.
  EXPECT_LT(lo, -0.6);
  EXPECT_GT(hi, 0.6);
  es::MotionSignalOptions bad;
  bad.min_period_s = 0.0;
  EXPECT_FALSE(bad.validate().ok());
}

TEST(BodyProxy, NamesRoundTrip) {
  for (auto kind : es::all_body_kinds()) {
    auto parsed = es::parse_body_kind(es::to_string(kind));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, kind);
  }
  EXPECT_FALSE(es::parse_body_kind("knee").ok());
}

class EveryBody : public ::testing::TestWithParam<es::BodyKind> {};

TEST_P(EveryBody, SurfaceIsRegularOutwardAndProjectable) {
  auto body = es::make_body(GetParam(), 11);
  ASSERT_NE(body, nullptr);
  const es::Vec2 site = body->default_site_uv_m();
  for (double t : {0.0, 2.5, 7.0, 13.0}) {
    for (const es::Vec2& d : {es::Vec2(0.0, 0.0), es::Vec2(0.03, 0.04), es::Vec2(-0.05, -0.06)}) {
      const es::Vec2 uv = site + d;
      const es::Vec3 x = body->skin_point_m(uv, t);
      const es::Mat32 j = body->skin_jacobian(uv, t);
      // u and v are arc lengths at rest; the skin stretches at most ~2x and
      // never folds, so both tangents stay near unit length and apart.
      for (int c = 0; c < 2; ++c) {
        EXPECT_GT(j.col(c).norm(), 0.5);
        EXPECT_LT(j.col(c).norm(), 2.0);
      }
      const es::Vec3 n = body->normal(uv, t);
      EXPECT_NEAR(n.norm(), 1.0, 1e-9);
      EXPECT_GT(j.col(0).cross(j.col(1)).norm(), 0.3);
      // A point 4 mm off the skin projects back onto it.
      const es::Vec3 off = x + 0.004 * n;
      const auto s = body->project(off, t, &uv);
      EXPECT_NEAR(s.distance_m, 0.004, 1e-5);
      EXPECT_NEAR((s.point_m - x).norm(), 0.0, 1e-5);
      EXPECT_GT(s.normal.dot(n), 0.999);
      // Without a hint (coarse search first) it finds the same foot point.
      const auto s2 = body->project(off, t);
      EXPECT_NEAR((s2.point_m - x).norm(), 0.0, 1e-5);
    }
    // The normal points away from the axis (for the jointed bodies the axis
    // is straight only at rest, t = 0).
    const bool jointed = GetParam() == es::BodyKind::elbow || GetParam() == es::BodyKind::wrist;
    if (t == 0.0 || !jointed) {
      for (const es::Vec2& d : {es::Vec2(0.0, 0.0), es::Vec2(0.05, 0.02), es::Vec2(-0.07, -0.05)}) {
        const es::Vec3 x = body->skin_point_m(site + d, t);
        EXPECT_GT(body->normal(site + d, t).dot(x - es::Vec3(0.0, 0.0, x.z())), 0.0);
      }
    }
  }
}

TEST_P(EveryBody, PoseValueStaysInItsDocumentedRange) {
  auto body = es::make_body(GetParam(), 2);
  double lo = 1e9, hi = -1e9;
  for (int k = 0; k <= 6000; ++k) {
    const double v = body->pose_value(0.02 * k);
    ASSERT_TRUE(std::isfinite(v));
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  switch (GetParam()) {
    case es::BodyKind::balloon: EXPECT_GE(lo, 90.0); EXPECT_LE(hi, 120.0); EXPECT_GT(hi, 110.0); break;
    case es::BodyKind::biceps: EXPECT_GE(lo, 0.0); EXPECT_LE(hi, 15.0); EXPECT_GT(hi, 10.0); break;
    case es::BodyKind::elbow: EXPECT_GE(lo, 0.0); EXPECT_LE(hi, 130.0); EXPECT_GT(hi, 100.0); break;
    case es::BodyKind::wrist: EXPECT_GE(lo, 0.0); EXPECT_LE(hi, std::hypot(60.0, 30.0)); EXPECT_GT(hi, 40.0); break;
    case es::BodyKind::forearm: EXPECT_GE(lo, -80.0); EXPECT_LE(hi, 80.0); EXPECT_LT(lo, -40.0); EXPECT_GT(hi, 40.0); break;
  }
  EXPECT_EQ(body->pose_values(3.0).front().first, body->pose_name());
  EXPECT_EQ(body->pose_values(3.0).front().second, body->pose_value(3.0));
}

INSTANTIATE_TEST_SUITE_P(Bodies, EveryBody, ::testing::ValuesIn(es::all_body_kinds()),
                         [](const auto& test) { return std::string(es::to_string(test.param)); });
