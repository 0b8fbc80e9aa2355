#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "support/temp_dir.hpp"
#include "support/text.hpp"

using namespace proprio;

namespace {

using proprio::testing_support::contains;

HandShape shape_of(double length_m, double width_m) {
  auto s = HandShape::from_measurements(length_m, width_m);
  EXPECT_TRUE(s.ok());
  return *s;
}

// Field by field, with a tolerance for the angles that go through degrees.
void expect_same(const ImuGloveDescription& a, const ImuGloveDescription& b) {
  constexpr double tol = 1e-12;
  EXPECT_EQ(a.name, b.name);
  ASSERT_EQ(a.imus.size(), b.imus.size());
  for (std::size_t i = 0; i < a.imus.size(); ++i) {
    SCOPED_TRACE("imu " + std::to_string(i));
    EXPECT_EQ(a.imus[i].name, b.imus[i].name);
    EXPECT_EQ(a.imus[i].segment, b.imus[i].segment);
    EXPECT_NEAR(a.imus[i].along_fraction, b.imus[i].along_fraction, tol);
    EXPECT_NEAR(a.imus[i].across_fraction, b.imus[i].across_fraction, tol);
    EXPECT_NEAR(angle_between(a.imus[i].q_segment_imu, b.imus[i].q_segment_imu), 0.0, 1e-9);
  }
  ASSERT_EQ(a.markers.size(), b.markers.size());
  for (std::size_t i = 0; i < a.markers.size(); ++i) {
    SCOPED_TRACE("marker " + std::to_string(i));
    EXPECT_EQ(a.markers[i].segment, b.markers[i].segment);
    EXPECT_EQ(a.markers[i].hue, b.markers[i].hue);
    EXPECT_NEAR(a.markers[i].along_fraction, b.markers[i].along_fraction, tol);
    EXPECT_NEAR(a.markers[i].around_deg, b.markers[i].around_deg, tol);
    EXPECT_NEAR(a.markers[i].across_fraction, b.markers[i].across_fraction, tol);
    EXPECT_NEAR(a.markers[i].diameter_m, b.markers[i].diameter_m, tol);
  }
  const auto& ca = a.rig.camera;
  const auto& cb = b.rig.camera;
  EXPECT_EQ(ca.width_px, cb.width_px);
  EXPECT_EQ(ca.height_px, cb.height_px);
  EXPECT_NEAR(ca.fx_px, cb.fx_px, 1e-9);
  EXPECT_NEAR(ca.fy_px, cb.fy_px, 1e-9);
  EXPECT_NEAR(ca.cx_px, cb.cx_px, 1e-9);
  EXPECT_NEAR(ca.cy_px, cb.cy_px, 1e-9);
  EXPECT_NEAR(a.rig.baseline_m, b.rig.baseline_m, tol);
  EXPECT_NEAR(a.rig.rate_hz, b.rig.rate_hz, tol);
  EXPECT_NEAR((a.rig.T_head_leftcam.p - b.rig.T_head_leftcam.p).norm(), 0.0, tol);
  EXPECT_NEAR(angle_between(a.rig.T_head_leftcam.q, b.rig.T_head_leftcam.q), 0.0, 1e-9);
}

// Marker centres on the flat hand, in the wrist frame.
std::vector<Vec3> markers_in_wrist(const ImuGloveDescription& g, const HandShape& shape, Handedness hand) {
  const HandModel model(shape);
  const auto T = model.joint_poses_in_wrist(hand, HandAngles{});
  std::vector<Vec3> out;
  for (const auto& m : g.place_markers(shape, hand)) out.push_back(T[index_of(m.segment)] * m.p_in_segment);
  return out;
}

// The bone that starts at a joint ends at the next joint of its finger.
HandJoint next_joint(HandJoint j) { return joint_at(index_of(j) + 1); }

Result<ImuGloveDescription> parse(const std::string& text) { return ImuGloveDescription::parse(text, "test.toml"); }

// A small valid glove; the tests below break one line of it at a time.
// Line numbers matter: tests check them.
const std::string kOkMarker = R"({ segment = "index_proximal", hue = "red", along_fraction = 0.5 })";

std::string small_glove(const std::string& marker_line = kOkMarker, const std::string& rig_extra = "baseline_mm = 63") {
  return "name = \"test glove\"\n"                                          // 1
         "imu = [ { segment = \"dorsum\", along_fraction = 0.35 } ]\n"      // 2
         "marker = [\n"                                                     // 3
         "  { segment = \"dorsum\", hue = \"blue\", along_fraction = 0.2 },\n"  // 4
         "  " + marker_line + ",\n"                                         // 5
         "]\n"                                                              // 6
         "[rig]\n"                                                          // 7
         "width_px = 1280\n"                                                // 8
         "height_px = 720\n"                                                // 9
         "hfov_deg = 90\n"                                                  // 10
         "vfov_deg = 60\n"                                                  // 11
         "rate_hz = 30\n"                                                   // 12
         "left_camera_position_in_head_m = [-0.0315, 0, -0.08]\n"           // 13
         "left_camera_tilt_down_deg = 25\n"                                 // 14
         + rig_extra + "\n";                                                // 15
}

}  // namespace

// --- the default glove -------------------------------------------------------

TEST(GloveDefault, HasSevenImusThirtySevenMarkersInFourHuesOnTheTrackedSegments) {
  const auto g = ImuGloveDescription::vist_default();
  ASSERT_EQ(g.imus.size(), 7u);
  EXPECT_EQ(g.markers.size(), 37u);

  const std::vector<HandJoint> tracked = {HandJoint::wrist,          HandJoint::thumb_metacarpal,
                                          HandJoint::thumb_proximal, HandJoint::index_proximal,
                                          HandJoint::index_intermediate, HandJoint::middle_proximal,
                                          HandJoint::middle_intermediate};
  std::vector<HandJoint> imu_segments;
  for (const auto& m : g.imus) imu_segments.push_back(m.segment);
  EXPECT_EQ(imu_segments, tracked);
  EXPECT_EQ(g.imus[0].name, "dorsum");
  EXPECT_EQ(g.segments(), tracked) << "IMUs come first, so segments() lists them in IMU order";

  std::set<MarkerHue> hues;
  std::size_t on_dorsum = 0;
  for (const auto& m : g.markers) {
    hues.insert(m.hue);
    EXPECT_NE(std::find(tracked.begin(), tracked.end(), m.segment), tracked.end()) << to_string(m.segment);
    EXPECT_DOUBLE_EQ(m.diameter_m, 0.012);
    if (m.segment == HandJoint::wrist) ++on_dorsum;
  }
  EXPECT_EQ(hues.size(), 4u);
  EXPECT_GE(on_dorsum, 9u);
  EXPECT_LE(on_dorsum, 11u);
}

TEST(GloveDefault, MarkersDoNotOverlapAndSameHuesAreFarApart) {
  const auto g = ImuGloveDescription::vist_default();
  const auto shape = shape_of(0.19, 0.10);
  const auto p = markers_in_wrist(g, shape, Handedness::right);
  double closest = 1.0, closest_same_hue = 1.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    for (std::size_t j = i + 1; j < p.size(); ++j) {
      const double d = (p[i] - p[j]).norm();
      closest = std::min(closest, d);
      if (g.markers[i].hue == g.markers[j].hue) closest_same_hue = std::min(closest_same_hue, d);
    }
  }
  EXPECT_GE(closest, 0.012) << "two 12 mm markers overlap";
  EXPECT_GE(closest_same_hue, 0.024) << "same-hue markers closer than two diameters";
}

TEST(GloveDefault, RigIsZedMiniLike) {
  const StereoRig rig = ImuGloveDescription::vist_default().rig;
  EXPECT_EQ(rig.camera.width_px, 1280);
  EXPECT_EQ(rig.camera.height_px, 720);
  // Independently: f = (W/2) / tan(FOV/2).
  EXPECT_NEAR(rig.camera.fx_px, 640.0 / std::tan(M_PI / 4.0), 1e-9);
  EXPECT_NEAR(rig.camera.fx_px, 640.0, 0.5);
  EXPECT_NEAR(rig.camera.fy_px, 623.5, 0.5);
  EXPECT_DOUBLE_EQ(rig.camera.cx_px, 639.5);
  EXPECT_DOUBLE_EQ(rig.camera.cy_px, 359.5);
  EXPECT_NEAR(rad_to_deg(rig.camera.hfov_rad()), 90.0, 1e-9);
  EXPECT_NEAR(rad_to_deg(rig.camera.vfov_rad()), 60.0, 1e-9);
  EXPECT_DOUBLE_EQ(rig.baseline_m, 0.063);
  EXPECT_DOUBLE_EQ(rig.rate_hz, 30.0);

  // Left of the head centre by half the baseline, in front of it.
  EXPECT_NEAR(rig.T_head_leftcam.p.x(), -0.0315, 1e-12);
  EXPECT_LT(rig.T_head_leftcam.p.z(), 0.0);
  // The optical axis (camera +z) points forward (head -Z) and 25 deg down.
  const Vec3 axis = rig.T_head_leftcam.q * Vec3::UnitZ();
  EXPECT_NEAR(axis.x(), 0.0, 1e-12);
  EXPECT_NEAR(axis.y(), -std::sin(deg_to_rad(25.0)), 1e-12);
  EXPECT_NEAR(axis.z(), -std::cos(deg_to_rad(25.0)), 1e-12);
  // Image x is head right; image y (down) has a downward component.
  EXPECT_NEAR((rig.T_head_leftcam.q * Vec3::UnitX() - Vec3::UnitX()).norm(), 0.0, 1e-12);
  EXPECT_LT((rig.T_head_leftcam.q * Vec3::UnitY()).y(), 0.0);
  // The right camera is a baseline to the right, in the head frame too.
  EXPECT_NEAR((rig.T_head_rightcam().p - rig.T_head_leftcam.p - Vec3(0.063, 0, 0)).norm(), 0.0, 1e-12);
}

TEST(GloveDefault, DescribeCountsSegmentsHuesAndTheRig) {
  const std::string d = ImuGloveDescription::vist_default().describe();
  EXPECT_TRUE(contains(d, "7 IMUs")) << d;
  EXPECT_TRUE(contains(d, "37 markers of 12.0 mm")) << d;
  EXPECT_TRUE(contains(d, "dorsum 11")) << d;
  EXPECT_TRUE(contains(d, "red 10, yellow 9, green 9, blue 9")) << d;
  EXPECT_TRUE(contains(d, "1280x720")) << d;
  EXPECT_TRUE(contains(d, "baseline 63.0 mm")) << d;
  EXPECT_TRUE(contains(d, "tilted 25.0 deg down")) << d;
}

// --- the file format ---------------------------------------------------------

TEST(GloveConfigFile, ShippedFileIsTheDefaultGlove) {
  // PROPRIO_TEST_DATA_DIR is <repo>/tests/data (which need not exist).
  const auto path =
      std::filesystem::path(PROPRIO_TEST_DATA_DIR).parent_path().parent_path() / "config" / "vist_glove.toml";
  auto g = ImuGloveDescription::load(path);
  ASSERT_TRUE(g.ok()) << g.error().message;
  expect_same(*g, ImuGloveDescription::vist_default());
  EXPECT_EQ(g->origin, path.string());
}

TEST(GloveConfigFile, ToTomlRoundTripsTheDefault) {
  const auto def = ImuGloveDescription::vist_default();
  auto g = ImuGloveDescription::parse(def.to_toml(), "dump.toml");
  ASSERT_TRUE(g.ok()) << g.error().message;
  expect_same(*g, def);
}

TEST(GloveConfigFile, ToTomlRoundTripsACustomGlove) {
  ImuGloveDescription def = ImuGloveDescription::vist_default();
  def.name = "lab glove \"v2\" \\ test";
  def.imus[1].q_segment_imu = so3_exp(Vec3(0.1, -0.2, 0.3));
  def.imus[0].across_fraction = 0.1;
  def.markers[3].diameter_m = 0.0085;
  def.rig.camera.fx_px = 700.25;
  def.rig.camera.fy_px = 701.5;
  def.rig.camera.cx_px = 641.0;
  def.rig.baseline_m = 0.12;
  def.rig.T_head_leftcam.q = so3_exp(Vec3(2.9, 0.1, -0.05));
  auto g = ImuGloveDescription::parse(def.to_toml(), "dump.toml");
  ASSERT_TRUE(g.ok()) << g.error().message << "\n" << def.to_toml();
  expect_same(*g, def);
}

TEST(GloveConfigFile, LoadReportsAMissingFile) {
  testing_support::TempDir dir;
  auto g = ImuGloveDescription::load(dir / "nope.toml");
  ASSERT_FALSE(g.ok());
  EXPECT_EQ(g.error().code, Errc::not_found);
  EXPECT_TRUE(contains(g.error().message, "nope.toml")) << g.error().message;
}

TEST(GloveConfigFile, SmallGloveParsesWithDefaults) {
  auto g = parse(small_glove());
  ASSERT_TRUE(g.ok()) << g.error().message;
  EXPECT_EQ(g->name, "test glove");
  ASSERT_EQ(g->imus.size(), 1u);
  EXPECT_EQ(g->imus[0].name, "dorsum") << "an IMU is named after its segment by default";
  ASSERT_EQ(g->markers.size(), 2u);
  EXPECT_DOUBLE_EQ(g->markers[1].diameter_m, 0.012);
  EXPECT_DOUBLE_EQ(g->rig.baseline_m, 0.063);
  EXPECT_EQ(g->segments(), (std::vector<HandJoint>{HandJoint::wrist, HandJoint::index_proximal}));
}

TEST(GloveParseErrors, BadHueNamesLineKeyAndChoices) {
  auto g = parse(small_glove(R"({ segment = "index_proximal", hue = "purple", along_fraction = 0.5 })"));
  ASSERT_FALSE(g.ok());
  const auto& m = g.error().message;
  EXPECT_TRUE(contains(m, "test.toml:5:")) << m;
  EXPECT_TRUE(contains(m, "marker[1].hue")) << m;
  EXPECT_TRUE(contains(m, "purple")) << m;
  EXPECT_TRUE(contains(m, "red, yellow, green, blue")) << m;
}

TEST(GloveParseErrors, UnknownSegmentNamesLineKeyAndChoices) {
  auto g = parse(small_glove(R"({ segment = "index_tip", hue = "red", along_fraction = 0.5 })"));
  ASSERT_FALSE(g.ok());
  const auto& m = g.error().message;
  EXPECT_TRUE(contains(m, "test.toml:5:")) << m;
  EXPECT_TRUE(contains(m, "marker[1].segment")) << m;
  EXPECT_TRUE(contains(m, "index_tip")) << m;
  EXPECT_TRUE(contains(m, "dorsum")) << m;
  EXPECT_TRUE(contains(m, "index_proximal")) << m;
}

TEST(GloveParseErrors, FractionOutsideZeroOneNamesLineKeyAndRange) {
  auto g = parse(small_glove(R"({ segment = "index_proximal", hue = "red", along_fraction = 1.5 })"));
  ASSERT_FALSE(g.ok());
  const auto& m = g.error().message;
  EXPECT_TRUE(contains(m, "test.toml:5:")) << m;
  EXPECT_TRUE(contains(m, "marker[1].along_fraction")) << m;
  EXPECT_TRUE(contains(m, "1.5")) << m;
  EXPECT_TRUE(contains(m, "[0, 1]")) << m;
}

TEST(GloveParseErrors, MissingRigKeyNamesTheKeyAndTheRigTable) {
  auto g = parse(small_glove(kOkMarker, ""));
  ASSERT_FALSE(g.ok());
  const auto& m = g.error().message;
  EXPECT_EQ(g.error().code, Errc::not_found);
  EXPECT_TRUE(contains(m, "test.toml:7:")) << m;
  EXPECT_TRUE(contains(m, "baseline_mm")) << m;
  EXPECT_TRUE(contains(m, "millimetres")) << m;
}

TEST(GloveParseErrors, EachRuleHasAnActionableMessage) {
  struct Case {
    std::string text;
    std::string_view expect;
  };
  const std::vector<Case> cases = {
      {small_glove(R"({ segment = "index_proximal", hue = "red", along_fraction = 0.5, around_deg = 270 })"),
       "marker[1].around_deg"},
      {small_glove(R"({ segment = "dorsum", hue = "red", along_fraction = 0.5, around_deg = 10 })"),
       "on the dorsum use across_fraction"},
      {small_glove(R"({ segment = "index_proximal", hue = "red", along_fraction = 0.5, across_fraction = 0.1 })"),
       "only applies on the dorsum"},
      {small_glove(R"({ segment = "index_proximal", hue = "red", along_fraction = 0.5, diameter_mm = -3 })"),
       "marker[1].diameter_mm"},
      {small_glove(R"({ segment = "index_proximal", hue = "red", along_frac = 0.5 })"), "unknown key 'along_frac'"},
      {small_glove(R"({ segment = "index_proximal", hue = "red" })"), "has no 'along_fraction'"},
      {small_glove(R"({ segment = "index_proximal", hue = 3, along_fraction = 0.5 })"), "must be a string"},
      {small_glove(kOkMarker, "baseline_mm = 0"), "must be greater than zero"},
      {small_glove(kOkMarker, "baseline_mm = 63\nfx_px = 640"), "conflicts with hfov_deg"},
      {small_glove(kOkMarker, "baseline_mm = 63\nleft_camera_rotation_in_head_deg = [180, 0, 0]"), "exactly one of"},
      {small_glove(kOkMarker, "baseline_mm = 63\nfocal_mm = 2.8"), "known keys"},
      {"name = \"no imu\"\n[rig]\nwidth_px = 1\n", "no IMU"},
      {"imu = [ { segment = \"dorsum\", along_fraction = 0.3 } ]\n", "no [rig] table"},
      {"imu = [ { segment = \"dorsum\", along_fraction = 0.3 }, { segment = \"dorsum\", along_fraction = 0.2 } ]\n"
       "[rig]\n",
       "two IMUs are named 'dorsum'"},
  };
  for (const auto& c : cases) {
    auto g = parse(c.text);
    ASSERT_FALSE(g.ok()) << c.text;
    EXPECT_TRUE(contains(g.error().message, c.expect)) << g.error().message << "\n--- for ---\n" << c.text;
    EXPECT_TRUE(contains(g.error().message, "test.toml")) << g.error().message;
  }
}

TEST(GloveParseErrors, PositionGivenInMillimetresIsCaught) {
  std::string text = small_glove();
  const std::string from = "[-0.0315, 0, -0.08]";
  text.replace(text.find(from), from.size(), "[-31.5, 0, -80]");
  auto g = parse(text);
  ASSERT_FALSE(g.ok());
  EXPECT_TRUE(contains(g.error().message, "test.toml:13:")) << g.error().message;
  EXPECT_TRUE(contains(g.error().message, "not millimetres")) << g.error().message;
}

TEST(GloveNames, HuesAndSegmentsParseTheirNames) {
  for (std::size_t i = 0; i < kMarkerHueCount; ++i) {
    const auto h = static_cast<MarkerHue>(i);
    EXPECT_EQ(parse_marker_hue(to_string(h)), h);
  }
  EXPECT_FALSE(parse_marker_hue("Red").has_value());
  EXPECT_EQ(opencv_hue(MarkerHue::red), 0);
  EXPECT_EQ(opencv_hue(MarkerHue::yellow), 30);
  EXPECT_EQ(opencv_hue(MarkerHue::green), 60);
  EXPECT_EQ(opencv_hue(MarkerHue::blue), 120);

  EXPECT_EQ(parse_glove_segment("dorsum"), HandJoint::wrist);
  EXPECT_EQ(parse_glove_segment("wrist"), HandJoint::wrist);
  EXPECT_EQ(parse_glove_segment("thumb_distal"), HandJoint::thumb_distal);
  EXPECT_EQ(parse_glove_segment("little_metacarpal"), HandJoint::little_metacarpal);
  EXPECT_FALSE(parse_glove_segment("palm").has_value());
  EXPECT_FALSE(parse_glove_segment("thumb_tip").has_value());
  EXPECT_FALSE(parse_glove_segment("index_tip").has_value());
  std::size_t n = 0;
  for (std::size_t i = 0; i < kHandJointCount; ++i) n += is_glove_segment(joint_at(i)) ? 1 : 0;
  EXPECT_EQ(n, 1u + 3u + 4u * 4u) << "wrist, 3 thumb bones, 4 bones on each finger";
}

// --- placement on a hand -------------------------------------------------------

TEST(GlovePlacement, MarkersLieOnTheSkinWithOutwardUnitNormals) {
  const auto g = ImuGloveDescription::vist_default();
  const auto shape = shape_of(0.185, 0.095);
  // Independent geometry: bone end points from forward kinematics, radii from
  // the HandPose the model fills, not from HandShape's arrays.
  const HandModel model(shape);
  const HandPose pose = model.forward(Handedness::right, HandAngles{}, Pose::identity(), 0);
  const auto placed = g.place_markers(shape);
  ASSERT_EQ(placed.size(), g.markers.size());
  for (const auto& m : placed) {
    SCOPED_TRACE("marker " + std::to_string(m.index) + " on " + std::string(to_string(m.segment)));
    EXPECT_NEAR(m.normal_in_segment.norm(), 1.0, 1e-12);
    EXPECT_DOUBLE_EQ(m.diameter_m, 0.012);
    EXPECT_EQ(m.hue, g.markers[m.index].hue);
    const Pose& T_seg = pose.joint(m.segment);
    const Vec3 p = T_seg * m.p_in_segment;
    const Vec3 n = T_seg.q * m.normal_in_segment;
    if (m.segment == HandJoint::wrist) {
      EXPECT_NEAR(m.p_in_segment.y(), shape.palm_radius_m, 1e-12);
      EXPECT_NEAR((m.normal_in_segment - Vec3::UnitY()).norm(), 0.0, 1e-12);
      continue;
    }
    const Vec3 a = pose.joint(m.segment).p;
    const Vec3 b = pose.joint(next_joint(m.segment)).p;
    const double t = (p - a).dot(b - a) / (b - a).squaredNorm();
    EXPECT_GE(t, 0.0);
    EXPECT_LE(t, 1.0);
    EXPECT_NEAR(t, g.markers[m.index].along_fraction, 1e-9);
    const Vec3 radial = p - (a + t * (b - a));
    const double r = (1 - t) * pose.radius_m[index_of(m.segment)] + t * pose.radius_m[index_of(next_joint(m.segment))];
    EXPECT_NEAR(radial.norm(), r, 1e-9);
    EXPECT_NEAR(n.dot(radial.normalized()), 1.0, 1e-9) << "normal points straight away from the bone axis";
  }
}

TEST(GlovePlacement, DorsalMarkersFaceTheBackOfTheHand) {
  const auto g = ImuGloveDescription::vist_default();
  for (const auto& m : g.place_markers(shape_of(0.19, 0.10))) {
    const auto& spec = g.markers[m.index];
    if (m.segment == HandJoint::wrist || std::abs(spec.around_deg) < 90.0) {
      EXPECT_GT(m.normal_in_segment.dot(Vec3::UnitY()), 0.0) << "marker " << m.index;
      EXPECT_GT(m.p_in_segment.y(), 0.0) << "marker " << m.index;
    }
    if (spec.around_deg > 1.0) {
      EXPECT_GT(m.normal_in_segment.x(), 0.0) << "+around is toward +X (the little finger)";
    }
  }
}

TEST(GlovePlacement, ImusSitOnTheBackOfTheirSegments) {
  const auto g = ImuGloveDescription::vist_default();
  const auto shape = shape_of(0.19, 0.10);
  const auto imus = g.place_imus(shape);
  ASSERT_EQ(imus.size(), 7u);
  for (const auto& imu : imus) {
    SCOPED_TRACE(g.imus[imu.index].name);
    EXPECT_EQ(imu.segment, g.imus[imu.index].segment);
    EXPECT_NEAR(imu.T_segment_imu.p.x(), 0.0, 1e-12);
    EXPECT_GT(imu.T_segment_imu.p.y(), 0.0);
    EXPECT_NEAR(angle_between(imu.T_segment_imu.q, Quat::Identity()), 0.0, 1e-12);
  }
  // The dorsum IMU at 35 % of hand length from the wrist.
  EXPECT_NEAR(imus[0].T_segment_imu.p.z(), -0.35 * 0.19, 1e-12);
  EXPECT_NEAR(imus[0].T_segment_imu.p.y(), shape.palm_radius_m, 1e-12);
  // Index proximal IMU halfway along its bone.
  EXPECT_NEAR(imus[3].T_segment_imu.p.z(), -0.5 * shape.fingers[1].bone_length_m[1], 1e-12);
}

TEST(GlovePlacement, LeftHandIsTheMirrorImageOfTheRight) {
  ImuGloveDescription g = ImuGloveDescription::vist_default();
  g.imus[2].q_segment_imu = so3_exp(Vec3(0.2, 0.3, -0.4));  // a non-trivial mount
  const auto shape = shape_of(0.19, 0.10);
  const auto right = g.place_markers(shape, Handedness::right);
  const auto left = g.place_markers(shape, Handedness::left);
  ASSERT_EQ(right.size(), left.size());
  const auto one_arg = g.place_markers(shape);
  for (std::size_t i = 0; i < right.size(); ++i) {
    EXPECT_EQ(one_arg[i].p_in_segment, right[i].p_in_segment) << "one-argument placement is the right hand";
    EXPECT_DOUBLE_EQ(left[i].p_in_segment.x(), -right[i].p_in_segment.x());
    EXPECT_DOUBLE_EQ(left[i].p_in_segment.y(), right[i].p_in_segment.y());
    EXPECT_DOUBLE_EQ(left[i].p_in_segment.z(), right[i].p_in_segment.z());
    EXPECT_DOUBLE_EQ(left[i].normal_in_segment.x(), -right[i].normal_in_segment.x());
  }
  // In the wrist frame, the left hand's markers are the right's through x = 0.
  const auto pr = markers_in_wrist(g, shape, Handedness::right);
  const auto pl = markers_in_wrist(g, shape, Handedness::left);
  for (std::size_t i = 0; i < pr.size(); ++i) {
    EXPECT_NEAR((pl[i] - Vec3(-pr[i].x(), pr[i].y(), pr[i].z())).norm(), 0.0, 1e-12) << "marker " << i;
  }
  // IMU axes mirror as the hand model mirrors joint frames: R -> S R S.
  const HandModel model(shape);
  const auto Tr = model.joint_poses_in_wrist(Handedness::right, HandAngles{});
  const auto Tl = model.joint_poses_in_wrist(Handedness::left, HandAngles{});
  const auto ir = g.place_imus(shape, Handedness::right);
  const auto il = g.place_imus(shape, Handedness::left);
  const Mat3 S = Vec3(-1, 1, 1).asDiagonal();
  for (std::size_t i = 0; i < ir.size(); ++i) {
    const Pose wr = Tr[index_of(ir[i].segment)] * ir[i].T_segment_imu;
    const Pose wl = Tl[index_of(il[i].segment)] * il[i].T_segment_imu;
    EXPECT_NEAR((wl.p - S * wr.p).norm(), 0.0, 1e-12);
    EXPECT_NEAR((wl.q.toRotationMatrix() - S * wr.q.toRotationMatrix() * S).norm(), 0.0, 1e-12);
  }
}

TEST(GlovePlacement, MarkersScaleWithHandSize) {
  const auto g = ImuGloveDescription::vist_default();
  const auto small = markers_in_wrist(g, shape_of(0.17, 0.09), Handedness::right);
  const auto big = markers_in_wrist(g, shape_of(0.21, 0.11), Handedness::right);
  ASSERT_EQ(small.size(), big.size());
  for (std::size_t i = 0; i < small.size(); ++i) {
    EXPECT_GT(big[i].norm(), small[i].norm()) << "marker " << i << " should be farther from the wrist";
  }
}
