// Fingertip device models: hand-derived inverse/forward values, round trips
// over the renderable set, clamping, load torques, and configuration errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "proprio/haptics/device_model.hpp"
#include "support/text.hpp"

using namespace proprio;
using namespace proprio::haptics;

namespace {

std::string config_path(const std::string& file) {
  return std::string(PROPRIO_SOURCE_DIR) + "/config/haptics/" + file;
}

std::unique_ptr<FingertipDeviceModel> load(const std::string& file) {
  auto m = load_device_model(config_path(file));
  EXPECT_TRUE(m.ok()) << (m.ok() ? "" : m.error().message);
  return m.ok() ? std::move(*m) : nullptr;
}

using proprio::testing_support::contains;

std::string error_of(std::string_view toml, std::string_view name = "dev.toml") {
  auto m = parse_device_model(toml, name);
  EXPECT_FALSE(m.ok()) << "expected an error for:\n" << toml;
  return m.ok() ? std::string() : m.error().message;
}

double max_component_error(const FingertipForce& a, const FingertipForce& b) {
  return std::max({std::abs(a.normal_n - b.normal_n), std::abs(a.shear_x_n - b.shear_x_n),
                   std::abs(a.shear_z_n - b.shear_z_n)});
}

// A grid over the renderable set: normal in 0..max, shear magnitude at
// fractions of what the limits allow at that normal, in 16 directions.
template <typename Fn>
void for_renderable_grid(const FingertipDeviceModel& m, Fn fn) {
  const DeviceLimits& l = m.limits();
  for (int i = 0; i <= 20; ++i) {
    const double fn_n = l.max_normal_n * i / 20.0;
    const double bound = std::min(l.max_shear_n, l.friction_coefficient * fn_n);
    for (const double frac : {0.0, 0.3, 0.7, 1.0}) {
      for (int j = 0; j < 16; ++j) {
        const double a = 2.0 * M_PI * j / 16.0;
        const FingertipForce r =
            m.renderable(FingertipForce{fn_n, frac * bound * std::cos(a), frac * bound * std::sin(a)});
        fn(r);
      }
    }
  }
}

// The three shipped minimal texts the config-error tests mutate.
constexpr const char* kForceVector = R"(
kind = "force_vector"
[limits]
max_normal_n = 3.0
max_shear_n = 2.0
max_rate_n_per_s = 100.0
friction_coefficient = 1.0
ramp_in_s = 0.3
)";

std::string band_text(const std::string& table, const std::string& limits_extra = "") {
  return R"(kind = "band_2dof"
[limits]
max_normal_n = 2.0
max_shear_n = 1.0
max_rate_n_per_s = 50.0
friction_coefficient = 0.9
ramp_in_s = 0.4
)" + limits_extra +
         R"(
[motors]
pulley_radius_m = 0.004
[band]
shear_stiffness_n_per_m = 500.0
force_table = [
)" + table + "]\n";
}

constexpr const char* kGoodTable =
    "{ takeup_mm = 0.0, normal_n = 0.3 },\n{ takeup_mm = 2.0, normal_n = 1.2 },\n"
    "{ takeup_mm = 4.0, normal_n = 3.4 },\n";

}  // namespace

// --- shipped configurations --------------------------------------------------

TEST(DeviceModels, ShippedConfigsLoadAndDescribeThemselves) {
  const auto band = load("band_2dof.toml");
  const auto platform = load("platform_3dof.toml");
  const auto fv = load("force_vector.toml");
  ASSERT_TRUE(band && platform && fv);
  EXPECT_EQ(band->kind(), "band_2dof");
  EXPECT_EQ(band->motor_count(), 2u);
  EXPECT_FALSE(band->axes().shear_x);
  EXPECT_TRUE(contains(band->describe(), "no shear_x")) << band->describe();
  EXPECT_EQ(platform->kind(), "platform_3dof");
  EXPECT_EQ(platform->motor_count(), 3u);
  EXPECT_EQ(fv->kind(), "force_vector");
  EXPECT_EQ(fv->motor_count(), 3u);
  for (const auto* m : {band.get(), platform.get(), fv.get()}) {
    EXPECT_EQ(m->limits().watchdog_ns, 50 * kNsPerMillisecond) << m->describe();
    EXPECT_TRUE(contains(m->describe(), "watchdog 50 ms")) << m->describe();
    EXPECT_GE(m->limits().ramp_in_s, 0.3);
    EXPECT_LE(m->limits().ramp_in_s, 0.5);
  }
  // Thesis motor: 1024 counts per motor turn through 16:1 = 2 pi / 16384 rad per count.
  EXPECT_NEAR(band->motor_spec().output_resolution_rad(), 2.0 * M_PI / 16384.0, 1e-15);
  EXPECT_EQ(fv->motor_spec().output_resolution_rad(), 0.0);
}

TEST(DeviceModels, RestRendersZeroForce) {
  for (const char* file : {"band_2dof.toml", "platform_3dof.toml", "force_vector.toml"}) {
    const auto m = load(file);
    ASSERT_TRUE(m);
    const FingertipForce f = m->forward(m->rest());
    EXPECT_NEAR(f.normal_n, 0.0, 1e-12) << file;
    EXPECT_NEAR(f.shear_magnitude_n(), 0.0, 1e-12) << file;
    const MotorAngles q = m->inverse(FingertipForce{});
    for (std::size_t i = 0; i < kMaxDeviceMotors; ++i) EXPECT_NEAR(q.rad[i], m->rest().rad[i], 1e-12) << file;
  }
}

// --- band_2dof, by hand --------------------------------------------------------

TEST(BandDevice, InverseAndForwardMatchHandDerivedValues) {
  const auto band = load("band_2dof.toml");
  ASSERT_TRUE(band);
  // Table rows (mm, N): (1.0, 0.65) (1.5, 0.90) (2.0, 1.20), pretension 0.30 N,
  // r = 4 mm, winding [+1, -1], k_t = 500 N/m.
  // 0.6 N above pretension = 0.90 N on the belt: total take-up 1.5 mm, 0.75 mm
  // per pulley = 0.1875 rad; motor 1 winds in with negative angle.
  MotorAngles q = band->inverse(FingertipForce{0.6, 0.0, 0.0});
  EXPECT_NEAR(q.rad[0], 0.1875, 1e-12);
  EXPECT_NEAR(q.rad[1], -0.1875, 1e-12);
  EXPECT_EQ(q.rad[2], 0.0);
  // Adding 0.5 N of proximal shear (<= 0.9 * 0.6): belt travel (s0 - s1)/2 =
  // 0.5 / 500 = 1 mm, so s0 = 1.75 mm, s1 = -0.25 mm: 0.4375 rad and +0.0625 rad.
  q = band->inverse(FingertipForce{0.6, 0.0, 0.5});
  EXPECT_NEAR(q.rad[0], 0.4375, 1e-12);
  EXPECT_NEAR(q.rad[1], 0.0625, 1e-12);
  // Opposite rotation, 0.25 rad each: 1 mm per pulley, 2 mm in all: 1.20 N on
  // the belt, 0.90 N rendered; no shear.
  FingertipForce f = band->forward(MotorAngles{{0.25, -0.25, 0.0}});
  EXPECT_NEAR(f.normal_n, 0.90, 1e-12);
  EXPECT_NEAR(f.shear_z_n, 0.0, 1e-12);
  EXPECT_EQ(f.shear_x_n, 0.0);
  // Between rows: 2.25 mm is halfway from 2.0 (1.20 N) to 2.5 mm (1.60 N): 1.40 N, 1.10 N rendered.
  f = band->forward(MotorAngles{{0.28125, -0.28125, 0.0}});
  EXPECT_NEAR(f.normal_n, 1.10, 1e-12);
  // Same rotation, 0.1 rad each: motor 0 winds 0.4 mm in, motor 1 pays 0.4 mm
  // out. Total take-up 0 (pretension only), travel 0.4 mm: 0.2 N of shear.
  f = band->forward(MotorAngles{{0.1, 0.1, 0.0}});
  EXPECT_NEAR(f.normal_n, 0.0, 1e-12);
  EXPECT_NEAR(f.shear_z_n, 0.2, 1e-12);
}

TEST(BandDevice, LoadTorquesFollowTheBeltStatics) {
  const auto band = load("band_2dof.toml");
  ASSERT_TRUE(band);
  // At rest each belt end carries half the 0.30 N pretension; tension unwinds
  // its pulley: tau_i = -w_i * r * T_i = -/+ 0.004 * 0.15.
  auto tau = band->load_torques(band->rest());
  EXPECT_NEAR(tau[0], -6e-4, 1e-15);
  EXPECT_NEAR(tau[1], +6e-4, 1e-15);
  EXPECT_EQ(tau[2], 0.0);
  // 0.6 N normal + 0.5 N shear: belt N = 0.90 N, T0 = (0.9 + 0.5)/2 = 0.70 N,
  // T1 = (0.9 - 0.5)/2 = 0.20 N.
  tau = band->load_torques(band->inverse(FingertipForce{0.6, 0.0, 0.5}));
  EXPECT_NEAR(tau[0], -0.004 * 0.70, 1e-12);
  EXPECT_NEAR(tau[1], +0.004 * 0.20, 1e-12);
}

// --- platform_3dof, by hand ----------------------------------------------------

TEST(PlatformDevice, NormalPressLiftsThePlateStraightUp) {
  const auto platform = load("platform_3dof.toml");
  ASSERT_TRUE(platform);
  // Exits 10 mm outside the plate attachments (17 - 7 mm) and 5 mm up; rest
  // wire length sqrt(10^2 + 5^2) mm. Exponential pad: d = ln(1 + m F / b) / m
  // = ln(1 + 1000 * 1.0 / 250) / 1000 = ln(5) mm for 1 N.
  const double d = std::log(5.0) * 1e-3;
  const double rest_len = std::sqrt(0.010 * 0.010 + 0.005 * 0.005);
  const double len = std::sqrt(0.010 * 0.010 + (0.005 - d) * (0.005 - d));
  const double expect = (rest_len - len) / 0.003;  // pulley r = 3 mm, winding shortens
  const MotorAngles q = platform->inverse(FingertipForce{1.0, 0.0, 0.0});
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(q.rad[i], expect, 1e-12) << i;
  const FingertipForce f = platform->forward(q);
  EXPECT_NEAR(f.normal_n, 1.0, 1e-12);
  EXPECT_NEAR(f.shear_magnitude_n(), 0.0, 1e-12);
  // Symmetric wires share the load: 3 t (5 mm - d) / len = 1 N.
  const double t = 1.0 / (3.0 * (0.005 - d) / len);
  const auto tau = platform->load_torques(q);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(tau[i], -0.003 * t, 1e-12) << i;
}

TEST(PlatformDevice, ShearMovesThePlateSideways) {
  const auto platform = load("platform_3dof.toml");
  ASSERT_TRUE(platform);
  // 0.6 N along +Z at 1 N normal: the plate moves 0.6 / 600 = 1 mm toward
  // +Z. Wire 0 (at 90 deg, on the +Z side) gets 1 mm closer horizontally to its
  // exit: horizontal 9 mm instead of 10 mm, so it is shorter and winds in more.
  const double d = std::log(5.0) * 1e-3;
  const double rest_len = std::sqrt(0.010 * 0.010 + 0.005 * 0.005);
  const double len0 = std::sqrt(0.009 * 0.009 + (0.005 - d) * (0.005 - d));
  const MotorAngles q = platform->inverse(FingertipForce{1.0, 0.0, 0.6});
  EXPECT_NEAR(q.rad[0], (rest_len - len0) / 0.003, 1e-12);
  EXPECT_NEAR(q.rad[1], q.rad[2], 1e-12) << "wires 1 and 2 are mirror images across the Z axis";
  const FingertipForce f = platform->forward(q);
  EXPECT_NEAR(f.normal_n, 1.0, 1e-12);
  EXPECT_NEAR(f.shear_x_n, 0.0, 1e-12);
  EXPECT_NEAR(f.shear_z_n, 0.6, 1e-12);
  // All wires taut: every shaft is pulled toward unwinding.
  for (double tau : platform->load_torques(q)) EXPECT_LT(tau, 0.0);
}

TEST(PlatformDevice, LinearFingertipModelFromConfig) {
  auto m = parse_device_model(R"(
kind = "platform_3dof"
[limits]
max_normal_n = 1.0
max_shear_n = 0.5
max_rate_n_per_s = 50.0
friction_coefficient = 0.5
ramp_in_s = 0.4
[motors]
pulley_radius_m = 0.003
[platform]
plate_radius_m = 0.007
anchor_radius_m = 0.017
anchor_height_m = 0.005
[fingertip]
normal_model = "linear"
normal_stiffness_n_per_m = 1000.0
shear_stiffness_x_n_per_m = 600.0
shear_stiffness_z_n_per_m = 600.0
)",
                              "linear.toml");
  ASSERT_TRUE(m.ok()) << m.error().message;
  // 0.5 N on 1000 N/m lifts the plate 0.5 mm.
  const double rest_len = std::sqrt(0.010 * 0.010 + 0.005 * 0.005);
  const double len = std::sqrt(0.010 * 0.010 + 0.0045 * 0.0045);
  const MotorAngles q = (*m)->inverse(FingertipForce{0.5, 0.0, 0.0});
  EXPECT_NEAR(q.rad[1], (rest_len - len) / 0.003, 1e-12);
  EXPECT_NEAR((*m)->forward(q).normal_n, 0.5, 1e-12);
  EXPECT_TRUE(contains((*m)->describe(), "linear normal stiffness 1000 N/m")) << (*m)->describe();
}

TEST(PlatformDevice, GeometryThatCannotHoldShearIsRejected) {
  // Exits 1 mm outside the plate and 20 mm up: nearly vertical wires cannot
  // pull the plate sideways with mu = 0.8.
  const std::string err = error_of(R"(
kind = "platform_3dof"
[limits]
max_normal_n = 1.5
max_shear_n = 1.0
max_rate_n_per_s = 50.0
friction_coefficient = 0.8
ramp_in_s = 0.4
[motors]
pulley_radius_m = 0.003
[platform]
plate_radius_m = 0.007
anchor_radius_m = 0.008
anchor_height_m = 0.020
[fingertip]
normal_model = "exponential"
exp_initial_stiffness_n_per_m = 250.0
exp_rate_per_m = 1000.0
shear_stiffness_x_n_per_m = 600.0
shear_stiffness_z_n_per_m = 600.0
)",
                                   "steep.toml");
  EXPECT_TRUE(contains(err, "steep.toml")) << err;
  EXPECT_TRUE(contains(err, "would have to push")) << err;
  EXPECT_TRUE(contains(err, "platform.anchor_radius_m")) << err;
}

// --- force_vector ----------------------------------------------------------------

TEST(ForceVectorDevice, IsTheIdentityAfterTheClamp) {
  const auto fv = load("force_vector.toml");
  ASSERT_TRUE(fv);
  const MotorAngles q = fv->inverse(FingertipForce{1.0, 0.5, -0.25});
  EXPECT_EQ(q.rad[0], 1.0);
  EXPECT_EQ(q.rad[1], 0.5);
  EXPECT_EQ(q.rad[2], -0.25);
  const FingertipForce f = fv->forward(q);
  EXPECT_EQ(f.normal_n, 1.0);
  EXPECT_EQ(f.shear_x_n, 0.5);
  EXPECT_EQ(f.shear_z_n, -0.25);
  // Over the limit: 5 N -> 3 N.
  EXPECT_EQ(fv->inverse(FingertipForce{5.0, 0.0, 0.0}).rad[0], 3.0);
  for (double tau : fv->load_torques(q)) EXPECT_EQ(tau, 0.0);
}

// --- clamping ------------------------------------------------------------------

TEST(DeviceModels, ClampToNormalShearAndFrictionConeKeepsShearDirection) {
  const auto band = load("band_2dof.toml");          // 2 N, 1 N, mu 0.9, no shear_x
  const auto platform = load("platform_3dof.toml");  // 1.5 N, 1 N, mu 0.8
  ASSERT_TRUE(band && platform);
  std::uint8_t why = 0;

  // Above both maxima: normal 2 N; shear_x dropped; |shear_z| to min(1, 0.9 * 2) = 1.
  FingertipForce f = clamp_to_limits(FingertipForce{3.0, 0.5, 2.0}, band->limits(), band->axes(), &why);
  EXPECT_EQ(f.normal_n, 2.0);
  EXPECT_EQ(f.shear_x_n, 0.0);
  EXPECT_DOUBLE_EQ(f.shear_z_n, 1.0);
  EXPECT_EQ(why, kClampNormalMax | kClampAxisDropped | kClampShearMax | kClampFrictionCone);
  EXPECT_DOUBLE_EQ(band->renderable(FingertipForce{3.0, 0.5, 2.0}).shear_z_n, 1.0);

  // Inside the maxima but outside the cone: 1 N presses, so at most 0.9 N of shear.
  f = band->renderable(FingertipForce{1.0, 0.0, -1.0});
  EXPECT_EQ(f.normal_n, 1.0);
  EXPECT_DOUBLE_EQ(f.shear_z_n, -0.9);

  // Both shear axes: (0.6, 0.8) has magnitude 1.0 > 0.8 * 1.0; scaled by 0.8
  // to (0.48, 0.64), direction kept.
  f = clamp_to_limits(FingertipForce{1.0, 0.6, 0.8}, platform->limits(), platform->axes(), &why);
  EXPECT_DOUBLE_EQ(f.shear_x_n, 0.48);
  EXPECT_DOUBLE_EQ(f.shear_z_n, 0.64);
  EXPECT_EQ(why, kClampFrictionCone);
  EXPECT_LE(f.shear_magnitude_n(), 0.8);

  // Pulling on the pad: nothing to press, so nothing to shear.
  f = clamp_to_limits(FingertipForce{-1.0, 0.0, 0.3}, platform->limits(), platform->axes(), &why);
  EXPECT_EQ(f.normal_n, 0.0);
  EXPECT_EQ(f.shear_magnitude_n(), 0.0);
  EXPECT_TRUE(why & kClampNormalNegative);

  // Non-finite: zero.
  f = clamp_to_limits(FingertipForce{std::nan(""), 0.1, 0.1}, platform->limits(), platform->axes(), &why);
  EXPECT_EQ(why, kClampNonFinite);
  EXPECT_EQ(f.normal_n, 0.0);
  EXPECT_EQ(f.shear_magnitude_n(), 0.0);

  // Renderable forces pass unchanged.
  f = clamp_to_limits(FingertipForce{1.0, 0.3, 0.4}, platform->limits(), platform->axes(), &why);
  EXPECT_EQ(why, kClampNone);
  EXPECT_EQ(f.shear_x_n, 0.3);
}

// --- round trips ---------------------------------------------------------------

TEST(DeviceModels, RoundTripForceMotorsForceOverTheRenderableSet) {
  for (const char* file : {"band_2dof.toml", "platform_3dof.toml", "force_vector.toml"}) {
    const auto m = load(file);
    ASSERT_TRUE(m);
    double worst = 0.0;
    int n = 0;
    for_renderable_grid(*m, [&](const FingertipForce& r) {
      const FingertipForce back = m->forward(m->inverse(r));
      worst = std::max(worst, max_component_error(back, r));
      ++n;
    });
    // Both maps are exact inverses on paper; what is left is rounding.
    EXPECT_LT(worst, 1e-9) << file;
    std::printf("[ round trip ] %-20s %d forces, max error %.3g N\n", file, n, worst);
  }
}

TEST(DeviceModels, RoundTripThroughEncoderCountsStaysWithinTheQuantisationBound) {
  // Angles rounded to whole encoder counts, as a driver sends them: the error
  // is the force change of half a count on each motor.
  //   band: half a count is r * pi / 16384 = 0.767 um of take-up per pulley;
  //   steepest table segment 1.4 N/mm (3.5 -> 4.0 mm), so normal <= 2 * 0.767 um
  //   * 1.4 N/mm = 2.15 mN; shear <= 500 N/m * 0.767 um = 0.38 mN.
  //   platform: 0.575 um of wire per motor; the plate moves at most
  //   |J^-1| * 0.575 um and the pad's steepest stiffness is 1750 N/m at
  //   1.5 N. A bound of 10 mN leaves room for the wire Jacobian.
  struct Case {
    const char* file;
    double normal_bound, shear_bound;
  };
  for (const Case c : {Case{"band_2dof.toml", 2.15e-3, 0.39e-3}, Case{"platform_3dof.toml", 10e-3, 10e-3}}) {
    const auto m = load(c.file);
    ASSERT_TRUE(m);
    const double res = m->motor_spec().output_resolution_rad();
    ASSERT_GT(res, 0.0);
    double worst_n = 0.0, worst_s = 0.0;
    for_renderable_grid(*m, [&](const FingertipForce& r) {
      MotorAngles q = m->inverse(r);
      for (auto& a : q.rad) a = std::round(a / res) * res;
      const FingertipForce back = m->forward(q);
      worst_n = std::max(worst_n, std::abs(back.normal_n - r.normal_n));
      worst_s = std::max({worst_s, std::abs(back.shear_x_n - r.shear_x_n), std::abs(back.shear_z_n - r.shear_z_n)});
    });
    EXPECT_LE(worst_n, c.normal_bound) << c.file;
    EXPECT_LE(worst_s, c.shear_bound) << c.file;
    std::printf("[ encoder    ] %-20s max error normal %.3g N, shear %.3g N\n", c.file, worst_n, worst_s);
  }
}

TEST(DeviceModels, LoadTorquesDoVirtualWork) {
  // Independent of the statics in the models: the motors' work equals the
  // pad's. For a small motion dq about q, -tau . dq = F . dp where dp is the
  // plate/belt displacement. Checked through the energy stored in the pad: a
  // conservative pad makes sum(-tau_i dq_i) path-independent, so integrating
  // around a closed loop in q gives zero work.
  for (const char* file : {"band_2dof.toml", "platform_3dof.toml"}) {
    const auto m = load(file);
    ASSERT_TRUE(m);
    const MotorAngles q0 = m->inverse(FingertipForce{0.8, 0.0, 0.3});
    const std::size_t n = m->motor_count();
    // A square loop in the (q0, q1) plane of side 0.02 rad, trapezoid rule.
    const double side = 0.02;
    const int steps = 400;
    double work = 0.0, scale = 0.0;
    const double corners[5][2] = {{0, 0}, {side, 0}, {side, side}, {0, side}, {0, 0}};
    for (int e = 0; e < 4; ++e) {
      for (int k = 0; k < steps; ++k) {
        MotorAngles a = q0, b = q0;
        const double u0 = double(k) / steps, u1 = double(k + 1) / steps;
        for (std::size_t i = 0; i < 2 && i < n; ++i) {
          a.rad[i] += corners[e][i] + u0 * (corners[e + 1][i] - corners[e][i]);
          b.rad[i] += corners[e][i] + u1 * (corners[e + 1][i] - corners[e][i]);
        }
        const auto ta = m->load_torques(a), tb = m->load_torques(b);
        for (std::size_t i = 0; i < n; ++i) {
          const double dw = -0.5 * (ta[i] + tb[i]) * (b.rad[i] - a.rad[i]);
          work += dw;
          scale += std::abs(dw);
        }
      }
    }
    EXPECT_LT(std::abs(work), 1e-3 * scale) << file << ": loop work " << work << " of " << scale;
  }
}

// The emulator reads force and load from plant(): the same numbers as
// forward() and load_torques(), at rest, pressing, and with a slack wire.
// (The platform's load_torques() is plant()'s, which the torque tests above
// check; its force here is computed apart, by forward().)
TEST(DeviceModels, PlantIsForwardAndLoadTorquesAtOnce) {
  for (const char* file : {"band_2dof.toml", "platform_3dof.toml", "force_vector.toml"}) {
    const auto m = load(file);
    ASSERT_TRUE(m) << file;
    std::vector<MotorAngles> qs = {m->rest(), m->inverse(FingertipForce{0.8, 0.2, 0.3}),
                                   m->inverse(FingertipForce{2.0, -0.5, 0.0})};
    MotorAngles slack = m->rest();
    slack.rad[0] -= 0.5;
    qs.push_back(slack);
    for (const MotorAngles& q : qs) {
      const FingertipDeviceModel::Plant p = m->plant(q);
      const FingertipForce f = m->forward(q);
      EXPECT_EQ(p.force.normal_n, f.normal_n) << file;
      EXPECT_EQ(p.force.shear_x_n, f.shear_x_n) << file;
      EXPECT_EQ(p.force.shear_z_n, f.shear_z_n) << file;
      EXPECT_EQ(p.load_torques_nm, m->load_torques(q)) << file;
    }
  }
}

// --- band force table validation -------------------------------------------------

TEST(BandDevice, NonMonotoneTableIsRejectedNamingTheRow) {
  const std::string err = error_of(band_text("{ takeup_mm = 0.0, normal_n = 0.3 },\n"
                                             "{ takeup_mm = 1.0, normal_n = 0.6 },\n"
                                             "{ takeup_mm = 2.0, normal_n = 1.1 },\n"
                                             "{ takeup_mm = 3.0, normal_n = 0.9 },\n"
                                             "{ takeup_mm = 4.0, normal_n = 3.4 },\n"),
                                   "band.toml");
  EXPECT_TRUE(contains(err, "band.toml")) << err;
  EXPECT_TRUE(contains(err, "band.force_table[3]")) << err;
  EXPECT_TRUE(contains(err, "normal_n must increase")) << err;
}

TEST(BandDevice, TakeUpOutOfOrderIsRejectedNamingTheRow) {
  const std::string err = error_of(band_text("{ takeup_mm = 0.0, normal_n = 0.3 },\n"
                                             "{ takeup_mm = 2.0, normal_n = 1.2 },\n"
                                             "{ takeup_mm = 2.0, normal_n = 2.0 },\n"
                                             "{ takeup_mm = 4.0, normal_n = 3.4 },\n"),
                                   "band.toml");
  EXPECT_TRUE(contains(err, "band.force_table[2]")) << err;
  EXPECT_TRUE(contains(err, "takeup_mm must increase")) << err;
}

TEST(BandDevice, TableMustStartAtRestAndReachTheLimit) {
  std::string err = error_of(band_text("{ takeup_mm = 0.5, normal_n = 0.3 },\n{ takeup_mm = 4.0, normal_n = 3.4 },\n"));
  EXPECT_TRUE(contains(err, "band.force_table[0]")) << err;
  EXPECT_TRUE(contains(err, "rest position")) << err;
  // 2.0 N allowed but the table only reaches 1.5 - 0.3 = 1.2 N above pretension.
  err = error_of(band_text("{ takeup_mm = 0.0, normal_n = 0.3 },\n{ takeup_mm = 4.0, normal_n = 1.5 },\n"));
  EXPECT_TRUE(contains(err, "limits.max_normal_n")) << err;
  EXPECT_TRUE(contains(err, "1.2 N")) << err;
  err = error_of(band_text("{ takeup_mm = 0.0, normal_n = 0.3 },\n"));
  EXPECT_TRUE(contains(err, "at least 2")) << err;
  err = error_of(band_text("{ takeup_mm = 0.0, force_n = 0.3 },\n{ takeup_mm = 4.0, normal_n = 3.4 },\n"));
  EXPECT_TRUE(contains(err, "band.force_table[0].force_n")) << err;
}

TEST(BandDevice, FrictionAboveWhatTheBeltCanHoldIsRejected) {
  // mu = 1.5 would ask for 1.0 N shear at 0.667 N normal; both belt ends stay
  // taut only while |shear| <= pretension + normal = 0.3 + 0.667 = 0.967 N.
  std::string text = band_text(kGoodTable);
  text.replace(text.find("friction_coefficient = 0.9"), 26, "friction_coefficient = 1.5");
  const std::string err = error_of(text);
  EXPECT_TRUE(contains(err, "limits.friction_coefficient")) << err;
  EXPECT_TRUE(contains(err, "taut")) << err;
}

// --- configuration errors ---------------------------------------------------------

TEST(DeviceConfig, BrokenTomlNamesFileAndLine) {
  const std::string err = error_of("kind = \"force_vector\"\n[limits\nmax_normal_n = 2\n", "broken.toml");
  EXPECT_TRUE(contains(err, "broken.toml:2:")) << err;
  EXPECT_TRUE(contains(err, "TOML syntax error")) << err;
}

TEST(DeviceConfig, MissingKeyNamesFileAndKey) {
  std::string text = kForceVector;
  text.erase(text.find("max_shear_n"), std::string("max_shear_n = 2.0\n").size());
  const std::string err = error_of(text, "fv.toml");
  EXPECT_TRUE(contains(err, "fv.toml")) << err;
  EXPECT_TRUE(contains(err, "'limits.max_shear_n'")) << err;
  EXPECT_TRUE(contains(err, "missing")) << err;

  EXPECT_TRUE(contains(error_of("[limits]\nmax_normal_n = 1\n", "nokind.toml"), "'kind'"));
  const std::string no_limits = error_of("kind = \"force_vector\"\n", "nolimits.toml");
  EXPECT_TRUE(contains(no_limits, "nolimits.toml")) << no_limits;
  EXPECT_TRUE(contains(no_limits, "[limits]")) << no_limits;
  const std::string no_band = error_of(band_text(kGoodTable).substr(0, band_text(kGoodTable).find("[band]")));
  EXPECT_TRUE(contains(no_band, "[band]")) << no_band;
}

TEST(DeviceConfig, NegativeLimitNamesFileLineAndKey) {
  std::string text = kForceVector;
  text.replace(text.find("max_normal_n = 3.0"), 18, "max_normal_n = -1.0");
  std::string err = error_of(text, "neg.toml");
  EXPECT_TRUE(contains(err, "neg.toml:4:")) << err;
  EXPECT_TRUE(contains(err, "'limits.max_normal_n' = -1")) << err;

  text = kForceVector;
  text.replace(text.find("ramp_in_s = 0.3"), 15, "ramp_in_s = -0.1");
  err = error_of(text, "neg.toml");
  EXPECT_TRUE(contains(err, "'limits.ramp_in_s'")) << err;

  // A fingertip is not a robot arm: 20 N is a typo, not a limit.
  text = kForceVector;
  text.replace(text.find("max_normal_n = 3.0"), 18, "max_normal_n = 20");
  err = error_of(text, "big.toml");
  EXPECT_TRUE(contains(err, "'limits.max_normal_n' = 20")) << err;

  err = error_of(std::string(kForceVector) + "watchdog_ms = 0\n", "wd.toml");
  EXPECT_TRUE(contains(err, "'limits.watchdog_ms'")) << err;
}

TEST(DeviceConfig, UnknownKeysKindsAndFilesAreErrors) {
  std::string err = error_of(std::string(kForceVector) + "max_normal = 2.0\n", "typo.toml");
  EXPECT_TRUE(contains(err, "typo.toml:")) << err;
  EXPECT_TRUE(contains(err, "unknown key 'max_normal' in [limits]")) << err;
  EXPECT_TRUE(contains(err, "known keys")) << err;

  std::string text = kForceVector;
  text.replace(text.find("force_vector"), 12, "exoskeleton");
  err = error_of(text, "kind.toml");
  EXPECT_TRUE(contains(err, "kind.toml:2:")) << err;
  EXPECT_TRUE(contains(err, "\"exoskeleton\" is not a device kind")) << err;

  auto m = load_device_model(config_path("no_such_device.toml"));
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.error().code, Errc::not_found);
  EXPECT_TRUE(contains(m.error().message, "no_such_device.toml")) << m.error().message;

  std::string band = band_text(kGoodTable);
  band.replace(band.find("[motors]\n"), 9, "[motors]\nwinding_direction = [1, 2]\n");
  err = error_of(band, "wind.toml");
  EXPECT_TRUE(contains(err, "'motors.winding_direction'")) << err;
}

TEST(DeviceConfig, ProgrammaticParamsAreValidatedToo) {
  BandParams p;
  p.force_table = {{0.0, 0.3}, {0.002, 0.2}, {0.004, 3.4}};
  auto m = make_band_device(p, DeviceLimits{});
  ASSERT_FALSE(m.ok());
  EXPECT_TRUE(contains(m.error().message, "band.force_table[1]")) << m.error().message;

  DeviceLimits bad;
  bad.max_shear_n = -1.0;
  auto fv = make_force_vector_device(ForceVectorParams{}, bad);
  ASSERT_FALSE(fv.ok());
  EXPECT_TRUE(contains(fv.error().message, "limits.max_shear_n")) << fv.error().message;
}
