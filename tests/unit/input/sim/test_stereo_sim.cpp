#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <iostream>
#include <vector>

#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/sim/stereo_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "support/temp_dir.hpp"

using namespace proprio;
using namespace proprio::sim;

namespace {

// A ZED-Mini-like rig with the left camera at the head origin, axes aligned
// with it: with T_world_head = identity, world coordinates are left-camera
// coordinates (x right, y down, z forward).
StereoRig test_rig() {
  StereoRig rig;
  rig.camera = PinholeCamera{};  // 1280x720, fx 640, fy 623.5, cx 639.5, cy 359.5
  rig.baseline_m = 0.063;
  rig.rate_hz = 30.0;
  rig.T_head_leftcam = Pose::identity();
  return rig;
}

// Noise, shuffling and randomness off: exact geometry.
StereoSimOptions exact_options() {
  StereoSimOptions o;
  o.pixel_noise_px = 0.0;
  o.shuffle = false;
  return o;
}

// A "hand" whose every joint is at T (radius 0: nothing occludes), so a marker
// on the wrist segment sits wherever T puts it.
HandPose point_hand(const Pose& T) {
  HandPose h;
  h.active = true;
  h.T_world_joint.fill(T);
  h.radius_m.fill(0.0);
  h.set_all_flags(kJointFullyTracked);
  return h;
}

PlacedMarker marker(const Vec3& p_in_wrist, const Vec3& normal, MarkerHue hue = MarkerHue::red,
                    double diameter_m = 0.012, std::size_t index = 0) {
  PlacedMarker m;
  m.index = index;
  m.segment = HandJoint::wrist;
  m.hue = hue;
  m.p_in_segment = p_in_wrist;
  m.normal_in_segment = normal.normalized();
  m.diameter_m = diameter_m;
  return m;
}

// Observes a single marker with the point hand at the origin.
struct Single {
  StereoFrame frame;
  StereoGroundTruth truth;
};
Single observe_single(const PlacedMarker& m, StereoSimOptions o = exact_options(), TimeNs t = 0) {
  const StereoMarkerSimulator sim(test_rig(), {m}, o);
  Single s;
  s.frame = sim.simulate(point_hand(Pose::identity()), Pose::identity(), t, &s.truth);
  return s;
}

HandShape subject_shape(int id = 3) { return *sim_subject(id)->shape(); }

// Dorsal markers of our own on a flat hand: one per finger bone at mid-length,
// on the back of the finger, plus a 3x3 grid on the back of the hand. They
// test the occlusion model independently of any glove file.
std::vector<PlacedMarker> dorsal_markers(const HandShape& shape) {
  const HandModel model(shape);
  const HandAngles flat{};
  const auto T = model.joint_poses_in_wrist(Handedness::right, flat);
  const HandPose pose = model.forward(Handedness::right, flat, Pose::identity(), 0);
  std::vector<PlacedMarker> out;
  for (std::size_t fi = 0; fi < kFingerCount; ++fi) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(fi));
    const std::size_t first = (fi == 0) ? 0 : 1;  // finger metacarpals belong to the dorsum
    for (std::size_t k = first; k + 1 < fj.count; ++k) {
      const double len = (T[index_of(fj.joints[k + 1])].p - T[index_of(fj.joints[k])].p).norm();
      const double r = std::max(pose.radius_m[index_of(fj.joints[k])], pose.radius_m[index_of(fj.joints[k + 1])]);
      PlacedMarker m;
      m.index = out.size();
      m.segment = fj.joints[k];
      m.p_in_segment = Vec3(0.0, r, -0.5 * len);
      m.normal_in_segment = Vec3::UnitY();
      m.diameter_m = 0.008;
      out.push_back(m);
    }
  }
  const double L = shape.hand_length_m;
  const double B = shape.hand_width_m;
  for (double along : {0.15, 0.3, 0.45}) {
    // Within the palm: the radial edge of the model's palm is the index
    // metacarpal capsule (about -0.2 B near the wrist).
    for (double across : {-0.15, 0.0, 0.2}) {
      PlacedMarker m;
      m.index = out.size();
      m.segment = HandJoint::wrist;
      m.p_in_segment = Vec3(across * B, 0.012, -along * L);
      m.normal_in_segment = Vec3::UnitY();
      m.diameter_m = 0.012;
      out.push_back(m);
    }
  }
  return out;
}

// A flat right hand 35 cm in front of the camera, fingers up in the image,
// showing the camera its back (dorsal) or its palm.
Pose flat_hand_facing_camera(bool dorsal_side) {
  const Vec3 z_w(0.0, 1.0, 0.0);  // wrist +Z (toward the forearm) points down the image
  const Vec3 y_w = dorsal_side ? Vec3(0.0, 0.0, -1.0) : Vec3(0.0, 0.0, 1.0);
  return Pose{quat_from_axes(y_w.cross(z_w), y_w, z_w), Vec3(0.0, 0.09, 0.35)};
}

double mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}
double stddev(const std::vector<double>& v) {
  const double m = mean(v);
  double s = 0.0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / static_cast<double>(v.size() - 1));
}

std::vector<unsigned char> bytes_of(const StereoFrame& f) {
  std::vector<unsigned char> out;
  auto put = [&](const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    out.insert(out.end(), c, c + n);
  };
  put(&f.time_ns, sizeof f.time_ns);
  out.push_back(f.dropped ? 1 : 0);
  for (const auto& cam : f.cameras) {
    out.push_back(cam.camera_id);
    for (const auto& m : cam.markers) {
      put(&m.hue, 1);
      put(&m.u_px, 4);
      put(&m.v_px, 4);
      put(&m.area_px2, 4);
    }
    out.push_back(0xff);
  }
  return out;
}

}  // namespace

TEST(StereoSimHue, HsvFullCodesRoundTrip) {
  EXPECT_EQ(marker_hue_code(MarkerHue::red), 0);
  EXPECT_EQ(marker_hue_code(MarkerHue::yellow), 43);  // 60 deg * 256/360 = 42.7
  EXPECT_EQ(marker_hue_code(MarkerHue::green), 85);   // 120 deg -> 85.3
  EXPECT_EQ(marker_hue_code(MarkerHue::blue), 171);   // 240 deg -> 170.7
  for (auto h : {MarkerHue::red, MarkerHue::yellow, MarkerHue::green, MarkerHue::blue}) {
    EXPECT_EQ(marker_hue_from_code(marker_hue_code(h)), h);
  }
  EXPECT_EQ(marker_hue_from_code(250), MarkerHue::red);  // hue wraps around
  EXPECT_EQ(marker_hue_from_code(160), MarkerHue::blue);
}

TEST(StereoSimProjection, HandComputedPixelsInBothCameras) {
  // Marker at (0.05, -0.02, 0.40) m in the left camera, facing it.
  const Vec3 p(0.05, -0.02, 0.40);
  const auto s = observe_single(marker(p, -p, MarkerHue::green));
  ASSERT_EQ(s.frame.cameras[0].markers.size(), 1u);
  ASSERT_EQ(s.frame.cameras[1].markers.size(), 1u);
  const Marker& l = s.frame.cameras[0].markers[0];
  const Marker& r = s.frame.cameras[1].markers[0];
  EXPECT_EQ(s.frame.cameras[0].camera_id, 0);
  EXPECT_EQ(s.frame.cameras[1].camera_id, 1);
  EXPECT_EQ(l.hue, 85);
  // u = fx x / z + cx, v = fy y / z + cy.
  EXPECT_NEAR(l.u_px, 640.0 * 0.05 / 0.40 + 639.5, 1e-4);     // 719.5
  EXPECT_NEAR(l.v_px, 623.5 * -0.02 / 0.40 + 359.5, 1e-4);    // 328.325
  EXPECT_NEAR(r.u_px, 640.0 * (0.05 - 0.063) / 0.40 + 639.5, 1e-4);  // 618.7
  EXPECT_NEAR(r.v_px, l.v_px, 1e-4);
  EXPECT_NEAR(l.u_px - r.u_px, 640.0 * 0.063 / 0.40, 1e-4);  // disparity fx b / z = 100.8
  // Facing the left camera exactly: area = pi (d/2)^2 fx fy r / z^3 (cos = 1).
  const double range = p.norm();
  EXPECT_NEAR(l.area_px2, M_PI * 0.006 * 0.006 * 640.0 * 623.5 * range / (0.4 * 0.4 * 0.4), 1e-2);
  EXPECT_NEAR(s.truth.cameras[0][0].facing_deg, 0.0, 1e-6);
  EXPECT_TRUE((s.truth.cameras[0][0].p_in_leftcam - p).norm() < 1e-12);
}

TEST(StereoSimProjection, AreaOnAxisIsDiscAreaTimesCosine) {
  // On the optical axis, tilted 60 deg: pi (d/2)^2 f^2 cos(60) / z^2.
  const Vec3 p(0.0, 0.0, 0.30);
  const Vec3 n(std::sin(M_PI / 3), 0.0, -std::cos(M_PI / 3));
  const auto s = observe_single(marker(p, n));
  ASSERT_EQ(s.frame.cameras[0].markers.size(), 1u);
  EXPECT_NEAR(s.truth.cameras[0][0].area_px2, M_PI * 0.006 * 0.006 * 640.0 * 623.5 * 0.5 / (0.3 * 0.3), 1e-9);
  EXPECT_NEAR(s.truth.cameras[0][0].facing_deg, 60.0, 1e-9);
}

TEST(StereoSimProjection, RectifiedRowsAgreeAndDisparityTriangulates) {
  const StereoRig rig = test_rig();
  std::vector<PlacedMarker> ms;
  Rng rng(42);
  for (std::size_t i = 0; i < 30; ++i) {
    const Vec3 p(rng.uniform(-0.12, 0.12), rng.uniform(-0.10, 0.10), rng.uniform(0.2, 0.6));
    ms.push_back(marker(p, -p, MarkerHue::blue, 0.012, i));
  }
  // A head somewhere in the world: the cameras move with it.
  const Pose T_world_head{so3_exp(Vec3(0.1, -0.3, 0.05)), Vec3(0.2, 1.6, -0.1)};
  const Pose T_world_leftcam = T_world_head * rig.T_head_leftcam;
  // Put the markers' segment at the left camera so their coordinates are camera coordinates.
  const StereoMarkerSimulator sim(rig, ms, exact_options());
  StereoGroundTruth truth;
  const StereoFrame f = sim.simulate(point_hand(T_world_leftcam), T_world_head, 123, &truth);
  ASSERT_EQ(f.cameras[0].markers.size(), ms.size());
  ASSERT_EQ(f.cameras[1].markers.size(), ms.size());
  const auto& k = rig.camera;
  for (std::size_t i = 0; i < ms.size(); ++i) {
    const MarkerTruth& l = truth.cameras[0][i];
    const MarkerTruth& r = truth.cameras[1][i];
    ASSERT_EQ(l.marker, i);
    ASSERT_EQ(r.marker, i);
    EXPECT_EQ(l.v_px, r.v_px);  // rectified: same row, bit for bit
    EXPECT_EQ(f.cameras[0].markers[i].v_px, f.cameras[1].markers[i].v_px);
    // Triangulate from the noise-free pixels: z = fx b / d, x = (u - cx) z / fx, y = (v - cy) z / fy.
    const double z = k.fx_px * rig.baseline_m / (l.u_px - r.u_px);
    const Vec3 p((l.u_px - k.cx_px) * z / k.fx_px, (l.v_px - k.cy_px) * z / k.fy_px, z);
    EXPECT_LT((p - ms[i].p_in_segment).norm(), 1e-9) << "marker " << i;
    EXPECT_LT((l.p_in_leftcam - ms[i].p_in_segment).norm(), 1e-12);
    // Observations are the truth rounded to float when noise is off.
    EXPECT_NEAR(f.cameras[0].markers[i].u_px, l.u_px, 1e-4);
  }
}

TEST(StereoSimFov, OutsideTheFrustumOrBehindIsNotObserved) {
  auto vis = [](const Vec3& p) {
    const auto s = observe_single(marker(p, -p));
    return std::array<MarkerVisibility, 2>{s.truth.visibility[0][0], s.truth.visibility[1][0]};
  };
  // Far to the right: horizontal half-FOV is atan(640/640) = 45 deg.
  EXPECT_EQ(vis({0.5, 0.0, 0.3})[0], MarkerVisibility::outside_fov);
  EXPECT_EQ(vis({0.0, 0.3, 0.3})[1], MarkerVisibility::outside_fov);  // below: vertical half-FOV 30 deg
  EXPECT_EQ(vis({0.0, 0.0, -0.3})[0], MarkerVisibility::behind);
  EXPECT_EQ(vis({0.0, 0.0, 0.03})[0], MarkerVisibility::behind);  // closer than min_depth
  // Near the left edge: the left camera sees it, the right camera (shifted +x) does not.
  const double z = 0.4;
  const double x_edge_left = (-0.5 - 639.5) * z / 640.0;  // u = -0.5 in the left camera
  const auto v = vis({x_edge_left + 0.02, 0.0, z});
  EXPECT_EQ(v[0], MarkerVisibility::visible);
  EXPECT_EQ(v[1], MarkerVisibility::outside_fov);
  // A blob that would straddle the border is dropped even though its centre is inside.
  const auto straddle = vis({x_edge_left + 0.002, 0.0, z});  // centre ~3 px inside, radius ~9.6 px
  EXPECT_EQ(straddle[0], MarkerVisibility::outside_fov);
}

TEST(StereoSimFacing, MarkerFacingAwayIsNotObserved) {
  const Vec3 p(0.0, 0.0, 0.4);
  auto vis_at = [&](double alpha_deg, StereoSimOptions o = exact_options()) {
    const double a = alpha_deg * M_PI / 180.0;
    // Tilted about y away from the left camera's ray (which is -z here).
    const auto s = observe_single(marker(p, Vec3(std::sin(a), 0.0, -std::cos(a))), o);
    return s.truth.visibility[0][0];
  };
  EXPECT_EQ(vis_at(180.0), MarkerVisibility::facing_away);  // normal points straight away
  EXPECT_EQ(vis_at(100.0), MarkerVisibility::facing_away);
  EXPECT_EQ(vis_at(82.0), MarkerVisibility::facing_away);  // default cutoff 80 deg
  EXPECT_EQ(vis_at(75.0), MarkerVisibility::visible);
  EXPECT_EQ(vis_at(0.0), MarkerVisibility::visible);
  // Grazing but allowed: the blob gets too small instead.
  StereoSimOptions wide = exact_options();
  wide.facing_max_deg = 90.0;
  wide.min_area_px2 = 20.0;
  EXPECT_EQ(vis_at(89.5, wide), MarkerVisibility::too_small);
}

TEST(StereoSimFacing, LinearRampMatchesLee2021Probability) {
  StereoSimOptions o = exact_options();
  o.facing = FacingModel::linear_ramp;  // alpha_min 45, alpha_max 90
  o.min_area_px2 = 0.0;
  const Vec3 p(0.0, 0.0, 0.4);
  auto seen_fraction = [&](double alpha_deg) {
    const double a = alpha_deg * M_PI / 180.0;
    const StereoMarkerSimulator sim(test_rig(), {marker(p, Vec3(std::sin(a), 0.0, -std::cos(a)))}, o);
    int seen = 0;
    const int frames = 4000;
    for (int f = 0; f < frames; ++f) {
      seen += sim.simulate(point_hand(Pose::identity()), Pose::identity(), f * 33'333'333LL).cameras[0].markers.size() > 0;
    }
    return static_cast<double>(seen) / frames;
  };
  EXPECT_EQ(seen_fraction(30.0), 1.0);
  EXPECT_EQ(seen_fraction(95.0), 0.0);
  EXPECT_NEAR(seen_fraction(67.5), 0.5, 0.03);   // (90 - 67.5) / 45
  EXPECT_NEAR(seen_fraction(81.0), 0.2, 0.025);  // (90 - 81) / 45
}

TEST(StereoSimOcclusion, SegmentCapsuleDistance) {
  const Vec3 o(0, 0, 0);
  // Crossing segments 1 apart.
  EXPECT_NEAR(segment_segment_distance_sq({-1, 0, 0}, {1, 0, 0}, {0, -1, 1}, {0, 1, 1}), 1.0, 1e-15);
  // Closest points at end points.
  EXPECT_NEAR(segment_segment_distance_sq({0, 0, 0}, {1, 0, 0}, {2, 1, 0}, {3, 1, 0}), 2.0, 1e-15);
  // Parallel, overlapping.
  EXPECT_NEAR(segment_segment_distance_sq({0, 0, 0}, {2, 0, 0}, {1, 0.5, 0}, {3, 0.5, 0}), 0.25, 1e-15);
  // Degenerate: point to segment, point to point.
  EXPECT_NEAR(segment_segment_distance_sq(o, o, {1, -1, 2}, {1, 1, 2}), 5.0, 1e-15);
  EXPECT_NEAR(segment_segment_distance_sq(o, o, {0, 3, 4}, {0, 3, 4}), 25.0, 1e-15);
  const Capsule cap{{-0.05, 0.0, 0.2}, {0.05, 0.0, 0.2}, 0.01};
  EXPECT_TRUE(segment_hits_capsule({0, 0, 0.4}, o, cap));                 // straight through
  EXPECT_TRUE(segment_hits_capsule({0, 0.018, 0.4}, o, cap));             // clips the side (0.009 from the axis)
  EXPECT_FALSE(segment_hits_capsule({0, 0.025, 0.4}, o, cap));            // passes beside
  EXPECT_FALSE(segment_hits_capsule({0, 0, 0.4}, {0, 0, 0.25}, cap));     // stops before it
  EXPECT_TRUE(segment_hits_capsule({0.055, 0, 0.4}, {0.055, 0, 0}, cap)); // through the end cap
}

TEST(StereoSimOcclusion, MarkerBehindAFingerIsHiddenAndSeenWithoutIt) {
  // A marker on the dorsum 40 cm away, and a finger bone (index proximal,
  // radius 9 mm) lying across the line of sight at 30 cm.
  HandPose h = point_hand(Pose::identity());
  h.joint(HandJoint::index_proximal).p = Vec3(-0.03, 0.0, 0.30);
  h.joint(HandJoint::index_intermediate).p = Vec3(0.03, 0.0, 0.30);
  h.radius_m[index_of(HandJoint::index_proximal)] = 0.009;
  h.radius_m[index_of(HandJoint::index_intermediate)] = 0.009;
  const auto m = marker(Vec3(0.0, 0.0, 0.4), Vec3(0, 0, -1));
  auto visible = [&](const HandPose& hand, bool occlusion) {
    StereoSimOptions o = exact_options();
    o.occlusion = occlusion;
    const StereoMarkerSimulator sim(test_rig(), {m}, o);
    StereoGroundTruth t;
    sim.simulate(hand, Pose::identity(), 0, &t);
    return t.visibility[0][0];
  };
  EXPECT_EQ(visible(h, true), MarkerVisibility::occluded);
  EXPECT_EQ(visible(h, false), MarkerVisibility::visible);
  HandPose moved = h;  // the finger slides 4 cm aside: the marker shows again
  moved.joint(HandJoint::index_proximal).p.y() += 0.04;
  moved.joint(HandJoint::index_intermediate).p.y() += 0.04;
  EXPECT_EQ(visible(moved, true), MarkerVisibility::visible);
}

TEST(StereoSimOcclusion, FlatHandPalmSideHidesDorsalMarkers) {
  const HandShape shape = subject_shape();
  const HandModel model(shape);
  const auto markers = dorsal_markers(shape);
  StereoSimOptions o = exact_options();
  o.facing_max_deg = 180.0;  // facing off: only the hand's body may hide them
  o.min_area_px2 = 0.0;
  const StereoMarkerSimulator sim(test_rig(), markers, o);
  StereoSimOptions o_free = o;
  o_free.occlusion = false;
  const StereoMarkerSimulator sim_free(test_rig(), markers, o_free);

  const HandPose palm_side = model.forward(Handedness::right, HandAngles{}, flat_hand_facing_camera(false), 0);
  const HandPose back_side = model.forward(Handedness::right, HandAngles{}, flat_hand_facing_camera(true), 0);
  StereoGroundTruth t;
  sim.simulate(back_side, Pose::identity(), 0, &t);
  for (std::size_t c = 0; c < 2; ++c) {
    for (std::size_t j = 0; j < markers.size(); ++j) {
      EXPECT_EQ(t.visibility[c][j], MarkerVisibility::visible)
          << "back of the hand, camera " << c << ", marker " << j << " on " << to_string(markers[j].segment);
    }
  }
  sim.simulate(palm_side, Pose::identity(), 0, &t);
  for (std::size_t c = 0; c < 2; ++c) {
    for (std::size_t j = 0; j < markers.size(); ++j) {
      EXPECT_EQ(t.visibility[c][j], MarkerVisibility::occluded)
          << "palm side, camera " << c << ", marker " << j << " on " << to_string(markers[j].segment);
    }
  }
  sim_free.simulate(palm_side, Pose::identity(), 0, &t);
  EXPECT_EQ(t.visible_count(0), markers.size());
  // With the facing test on (default 80 deg), the palm side hides them regardless.
  const StereoMarkerSimulator sim_facing(test_rig(), markers, exact_options());
  sim_facing.simulate(palm_side, Pose::identity(), 0, &t);
  EXPECT_EQ(t.visible_count(0), 0u);
  EXPECT_EQ(t.visible_count(1), 0u);
}

TEST(StereoSimOcclusion, LeftHandIsTheMirrorImage) {
  // The same markers on a left hand, mirrored through the camera's x = 0
  // plane: every marker keeps its visibility and its pixel mirrors about cx.
  const HandShape shape = subject_shape();
  const HandModel model(shape);
  const auto markers = dorsal_markers(shape);
  StereoRig rig = test_rig();
  rig.baseline_m = 0.0;  // a mirrored stereo pair would swap cameras; one viewpoint keeps it simple
  StereoSimOptions o = exact_options();
  const StereoMarkerSimulator sim(rig, markers, o);
  HandAngles a{};
  a[index_of(HandDof::index_mcp_flexion)] = 0.8;
  a[index_of(HandDof::middle_pip_flexion)] = 1.2;
  a[index_of(HandDof::thumb_cmc_abduction)] = 0.4;
  const Pose T_right{so3_exp(Vec3(0.5, 0.3, 0.1)) * flat_hand_facing_camera(true).q, Vec3(0.02, 0.08, 0.33)};
  const Pose T_left{Quat(T_right.q.w(), T_right.q.x(), -T_right.q.y(), -T_right.q.z()),
                    Vec3(-T_right.p.x(), T_right.p.y(), T_right.p.z())};
  StereoGroundTruth tr, tl;
  sim.simulate(model.forward(Handedness::right, a, T_right, 0), Pose::identity(), 0, &tr);
  sim.simulate(model.forward(Handedness::left, a, T_left, 0), Pose::identity(), 0, &tl);
  EXPECT_GT(tr.visible_count(0), 5u);
  EXPECT_EQ(tr.visibility[0], tl.visibility[0]);
  ASSERT_EQ(tr.cameras[0].size(), tl.cameras[0].size());
  for (std::size_t i = 0; i < tr.cameras[0].size(); ++i) {
    EXPECT_NEAR(tr.cameras[0][i].u_px - 639.5, 639.5 - tl.cameras[0][i].u_px, 1e-9);
    EXPECT_NEAR(tr.cameras[0][i].v_px, tl.cameras[0][i].v_px, 1e-9);
  }
}

TEST(StereoSimNoise, PixelNoiseHasTheConfiguredSigma) {
  std::vector<PlacedMarker> ms;
  Rng rng(7);
  for (std::size_t i = 0; i < 20; ++i) {
    const Vec3 p(rng.uniform(-0.1, 0.1), rng.uniform(-0.08, 0.08), rng.uniform(0.25, 0.5));
    ms.push_back(marker(p, -p, MarkerHue::red, 0.012, i));
  }
  StereoSimOptions o;  // default sigma 0.3 px, shuffled
  o.seed = 99;
  const StereoMarkerSimulator sim(test_rig(), ms, o);
  std::vector<double> du, dv;
  StereoGroundTruth t;
  bool reordered = false;
  for (int f = 0; f < 200; ++f) {
    const StereoFrame fr = sim.simulate(point_hand(Pose::identity()), Pose::identity(), f * 33'333'333LL, &t);
    for (std::size_t c = 0; c < 2; ++c) {
      ASSERT_EQ(fr.cameras[c].markers.size(), ms.size());
      for (std::size_t i = 0; i < ms.size(); ++i) {
        du.push_back(fr.cameras[c].markers[i].u_px - t.cameras[c][i].u_px);
        dv.push_back(fr.cameras[c].markers[i].v_px - t.cameras[c][i].v_px);
        reordered |= t.cameras[c][i].marker != i;
      }
    }
  }
  EXPECT_TRUE(reordered);  // the order is shuffled, and the truth follows it
  EXPECT_NEAR(stddev(du), 0.3, 0.015);
  EXPECT_NEAR(stddev(dv), 0.3, 0.015);
  EXPECT_NEAR(mean(du), 0.0, 0.01);
  EXPECT_NEAR(mean(dv), 0.0, 0.01);
  std::cout << "[ pixel noise ] n=" << du.size() << " sigma_u=" << stddev(du) << " sigma_v=" << stddev(dv) << " px\n";
}

TEST(StereoSimNoise, DroppedFramesAreEmptyAtTheConfiguredRate) {
  StereoSimOptions o = exact_options();
  o.drop_probability = 0.3;
  const StereoMarkerSimulator sim(test_rig(), {marker({0, 0, 0.4}, {0, 0, -1})}, o);
  int dropped = 0;
  const int frames = 3000;
  for (int f = 0; f < frames; ++f) {
    StereoGroundTruth t;
    const StereoFrame fr = sim.simulate(point_hand(Pose::identity()), Pose::identity(), f * 33'333'333LL, &t);
    if (fr.dropped) {
      ++dropped;
      EXPECT_TRUE(fr.cameras[0].markers.empty() && fr.cameras[1].markers.empty());
      EXPECT_EQ(t.visibility[0][0], MarkerVisibility::dropped);
    } else {
      EXPECT_EQ(fr.cameras[0].markers.size(), 1u);
    }
  }
  EXPECT_NEAR(static_cast<double>(dropped) / frames, 0.3, 0.03);
}

TEST(StereoSimDeterminism, SameSeedSameFramesDifferentSeedDifferent) {
  const HandShape shape = subject_shape();
  const HandModel model(shape);
  const auto markers = dorsal_markers(shape);
  StereoSimOptions o;
  o.seed = 5;
  o.drop_probability = 0.1;
  o.area_noise_fraction = 0.05;
  o.facing = FacingModel::linear_ramp;
  const StereoMarkerSimulator a(test_rig(), markers, o);
  const StereoMarkerSimulator b(test_rig(), markers, o);
  o.seed = 6;
  const StereoMarkerSimulator c(test_rig(), markers, o);
  HandAngles angles{};
  angles[index_of(HandDof::index_mcp_flexion)] = 0.5;
  const HandPose hand = model.forward(Handedness::right, angles, flat_hand_facing_camera(true), 0);
  std::vector<unsigned char> fa, fb, fc;
  for (int f = 0; f < 50; ++f) {
    const TimeNs t = f * 33'333'333LL;
    const auto x = bytes_of(a.simulate(hand, Pose::identity(), t));
    fa.insert(fa.end(), x.begin(), x.end());
    const auto y = bytes_of(c.simulate(hand, Pose::identity(), t));
    fc.insert(fc.end(), y.begin(), y.end());
  }
  // b simulates the frames backwards: each frame depends only on (seed, t).
  std::vector<std::vector<unsigned char>> back(50);
  for (int f = 49; f >= 0; --f) back[static_cast<std::size_t>(f)] = bytes_of(b.simulate(hand, Pose::identity(), f * 33'333'333LL));
  for (const auto& x : back) fb.insert(fb.end(), x.begin(), x.end());
  EXPECT_EQ(fa, fb);
  EXPECT_NE(fa, fc);
}

TEST(StereoSimOptions, ValidateAndDescribe) {
  StereoSimOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_NE(o.describe().find("seed=1"), std::string::npos);
  o.drop_probability = 1.5;
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.facing_alpha_min_deg = 95.0;
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.pixel_noise_px = -1.0;
  EXPECT_FALSE(o.validate().ok());
  o = {};
  o.min_depth_m = 0.0;
  EXPECT_FALSE(o.validate().ok());
  ImuGloveDescription g = ImuGloveDescription::vist_default();
  g.rig.baseline_m = 0.0;
  auto r = StereoMarkerSimulator::create(g, subject_shape(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("baseline"), std::string::npos);
}

TEST(StereoSimSession, FreeMotionWithTheDefaultGloveSeesASensibleShare) {
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  ASSERT_EQ(glove.markers.size(), 37u);
  for (Handedness hand : {Handedness::right, Handedness::left}) {
    const HandShape shape = subject_shape(3);
    auto sim = StereoMarkerSimulator::create(glove, shape, {});
    ASSERT_TRUE(sim.ok()) << sim.error().message;
    HandMotionOptions mo;
    mo.protocol = MotionProtocol::free_motion;
    mo.hand = hand;
    mo.seed = 11;
    HandMotionGenerator gen(HandModel(shape), mo);
    double sum[2] = {0, 0};
    double stereo = 0;
    std::size_t frames = 0, empty = 0;
    std::array<std::array<double, 9>, 2> why{};
    // 60 s: 20 free-motion targets; long enough for stable means, short
    // enough for the sanitizer builds.
    simulate_session(gen, *sim, 60.0, [&](const HandMotionFrame& mf, const StereoFrame& fr, const StereoGroundTruth& t) {
      EXPECT_EQ(fr.time_ns, mf.time_ns);
      for (std::size_t c = 0; c < 2; ++c) {
        sum[c] += static_cast<double>(fr.cameras[c].markers.size());
        EXPECT_EQ(fr.cameras[c].markers.size(), t.visible_count(c));
        for (auto v : t.visibility[c]) why[c][static_cast<std::size_t>(v)] += 1.0;
      }
      stereo += static_cast<double>(t.stereo_count());
      empty += fr.cameras[0].markers.empty();
      ++frames;
    });
    ASSERT_EQ(frames, 1800u);  // 60 s at 30 Hz
    const double n = static_cast<double>(frames);
    std::cout << "[ free motion " << to_string(hand) << " ] mean visible: left " << sum[0] / n << ", right "
              << sum[1] / n << ", both " << stereo / n << " of " << glove.markers.size() << "; frames with none "
              << empty << "/" << frames << "\n  left camera, share of marker-frames:";
    for (std::size_t v = 0; v < why[0].size(); ++v) {
      if (why[0][v] > 0) {
        std::cout << " " << to_string(static_cast<MarkerVisibility>(v)) << " "
                  << 100.0 * why[0][v] / (n * static_cast<double>(glove.markers.size())) << "%";
      }
    }
    std::cout << "\n";
    for (std::size_t c = 0; c < 2; ++c) {
      EXPECT_GT(sum[c] / n, 8.0);
      EXPECT_LT(sum[c] / n, 30.0);
    }
  }
}

TEST(StereoSimSession, WritesARecordingTheReaderUnderstands) {
  testing_support::TempDir dir;
  const auto path = dir / "stereo.prec";
  const HandShape shape = subject_shape();
  StereoSimOptions o;
  o.drop_probability = 0.2;
  const StereoMarkerSimulator sim(test_rig(), dorsal_markers(shape), o);
  std::size_t written_frames = 0, records = 0;
  {
    auto w = RecordingWriter::create(path);
    ASSERT_TRUE(w.ok()) << w.error().message;
    auto id = add_stereo_stream(*w, sim, "vist");
    ASSERT_TRUE(id.ok()) << id.error().message;
    HandMotionOptions mo;
    mo.protocol = MotionProtocol::wrist_sweep;
    HandMotionGenerator gen(HandModel(shape), mo);
    simulate_session(gen, sim, 2.0, [&](const HandMotionFrame&, const StereoFrame& fr, const StereoGroundTruth&) {
      ASSERT_TRUE(write_stereo_frame(*w, *id, fr).ok());
      if (!fr.dropped) {
        ++written_frames;
        records += 2;
      }
    });
    ASSERT_TRUE(w->close().ok());
  }
  EXPECT_GT(written_frames, 30u);
  EXPECT_LT(written_frames, 60u);
  auto r = RecordingReader::open(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  std::size_t got = 0;
  while (true) {
    auto rec = r->next();
    ASSERT_TRUE(rec.ok()) << rec.error().message;
    if (!rec->has_value()) break;
    const auto& obs = std::get<MarkerObservations>((*rec)->payload);
    EXPECT_EQ(obs.camera_id, got % 2);
    ++got;
  }
  EXPECT_EQ(got, records);
  const StreamInfo* s = r->find_stream("cam/vist/markers");
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->kind, StreamKind::markers);
  EXPECT_NE(s->meta.find("\"baseline_m\": 0.063"), std::string::npos) << s->meta;
  EXPECT_NE(s->meta.find("opencv_hsv_full_256"), std::string::npos);
}

TEST(StereoSimGlove, MarkersPlacedForTheLeftHandMatchTheRuntimeMirror) {
  // One simulator with right-hand markers mirrors them for a left pose; one
  // with markers placed for the left hand uses them as they are. Same frames.
  const ImuGloveDescription glove = ImuGloveDescription::vist_default();
  const HandShape shape = subject_shape(5);
  StereoSimOptions o;
  o.seed = 3;
  const StereoMarkerSimulator from_right(glove.rig, glove.place_markers(shape, Handedness::right), o,
                                         Handedness::right);
  const StereoMarkerSimulator from_left(glove.rig, glove.place_markers(shape, Handedness::left), o,
                                        Handedness::left);
  HandMotionOptions mo;
  mo.hand = Handedness::left;
  HandMotionGenerator gen(HandModel(shape), mo);
  std::size_t seen = 0;
  for (int f = 0; f < 90; ++f) {
    const TimeNs t = f * 100'000'000LL;
    const HandMotionFrame mf = gen.sample(t);
    const auto a = bytes_of(from_right.simulate(mf.pose, mf.T_world_head, t));
    const auto b = bytes_of(from_left.simulate(mf.pose, mf.T_world_head, t));
    EXPECT_EQ(a, b) << "frame " << f;
    seen += a.size();
  }
  EXPECT_GT(seen, 90u * 200u);  // markers were seen, not just empty frames
}
