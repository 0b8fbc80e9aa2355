// The perception-threshold sample's parts: the protocol as published, the
// blind phase's arrow, graphical penetration removal and the force law, the
// observer's decisions against its documented closed form, and the live
// frame hook's trial loop driven with synthetic frames.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/perception_threshold/live.hpp"
#include "proprio/perception_threshold/observer.hpp"
#include "proprio/perception_threshold/trial.hpp"
#include "proprio/study/csv.hpp"

namespace proprio::perception {
namespace {

namespace fs = std::filesystem;

PerceptionProtocol defaults() { return PerceptionProtocol::defaults(PROPRIO_SOURCE_DIR); }

TEST(PerceptionProtocol, DefaultsAreThePublishedOnes) {
  const PerceptionProtocol p = defaults();
  ASSERT_TRUE(p.validate());
  EXPECT_DOUBLE_EQ(p.fingertip_radius_m, 0.01);
  EXPECT_DOUBLE_EQ(p.cylinder_radius_m, 0.25);
  EXPECT_DOUBLE_EQ(p.cylinder_length_m, 0.50);
  // (45 cm, 0 deg, -60 deg) in the head frame: below and ahead of the eyes.
  const Vec3 c = p.T_head_cylinder().p;
  EXPECT_NEAR(c.x(), 0.0, 1e-12);
  EXPECT_NEAR(c.y(), -0.45 * std::sin(kPi / 3), 1e-12);
  EXPECT_NEAR(c.z(), -0.45 * std::cos(kPi / 3), 1e-12);
  EXPECT_DOUBLE_EQ(p.adaptation_s, 5.0);
  EXPECT_DOUBLE_EQ(p.blind_s, 3.0);
  EXPECT_DOUBLE_EQ(p.cue_update_s, 1.0);
  // 0.042 N/cm is 4.2 N/m.
  EXPECT_DOUBLE_EQ(p.contact_law().stiffness_n_per_m, 4.2);
  EXPECT_DOUBLE_EQ(p.contact_law().onset_force_n, 0.45);
  auto design = study::StudyDesign::load_file(p.design_file);
  ASSERT_TRUE(design) << design.error().message;
  EXPECT_EQ(design->procedure.levels, (std::vector<double>{1.5, 3.0, 4.5, 6.0, 7.5}));
  EXPECT_EQ(design->procedure.repetitions, 8);
}

TEST(PerceptionProtocol, FilesOverrideDefaultsAndRejectTypos) {
  const fs::path dir = fs::path(PROPRIO_TEST_OUT_DIR) / "protocol";
  fs::create_directories(dir);
  {
    std::ofstream f(dir / "ok.toml");
    f << "design = \"" << PROPRIO_SOURCE_DIR << "/config/studies/perception_threshold.toml\"\n"
      << "[haptics]\nstiffness_n_per_cm = 0.1\n[phases]\nblind_s = 2\n";
  }
  auto p = PerceptionProtocol::load_file(dir / "ok.toml");
  ASSERT_TRUE(p) << p.error().message;
  EXPECT_DOUBLE_EQ(p->contact_law().stiffness_n_per_m, 10.0);
  EXPECT_DOUBLE_EQ(p->blind_s, 2.0);
  EXPECT_DOUBLE_EQ(p->adaptation_s, 5.0);
  {
    std::ofstream f(dir / "typo.toml");
    f << "design = \"x.toml\"\n[haptics]\nstifness_n_per_cm = 0.1\n";
  }
  auto bad = PerceptionProtocol::load_file(dir / "typo.toml");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("stifness_n_per_cm"), std::string::npos) << bad.error().message;
  // The shipped protocol file loads.
  auto shipped = PerceptionProtocol::load_file(fs::path(PROPRIO_SOURCE_DIR) / "config/samples/perception_threshold.toml");
  ASSERT_TRUE(shipped) << shipped.error().message;
  EXPECT_TRUE(fs::exists(shipped->design_file));
}

TEST(PerceptionTrial, BlindCuePointsTowardTheViewCentre) {
  const double dead = 3.0 * kPi / 180;
  EXPECT_EQ(blind_cue(Vec3(0.1, 0.0, -0.4), dead), Cue::left);   // finger right of centre: move left
  EXPECT_EQ(blind_cue(Vec3(-0.1, 0.0, -0.4), dead), Cue::right);
  EXPECT_EQ(blind_cue(Vec3(0.0, -0.1, -0.4), dead), Cue::up);
  EXPECT_EQ(blind_cue(Vec3(0.0, 0.1, -0.4), dead), Cue::down);
  EXPECT_EQ(blind_cue(Vec3(0.005, 0.0, -0.4), dead), Cue::none);
  // The larger angular error wins.
  EXPECT_EQ(blind_cue(Vec3(0.02, -0.15, -0.4), dead), Cue::up);
}

TEST(PerceptionTrial, PenetrationIsRemovedFromTheDrawingAndTurnedIntoForce) {
  const PerceptionProtocol p = defaults();
  const PlacedScene scene = PlacedScene::place(p, Pose{Quat::Identity(), Vec3(0, 1.6, 0)});
  // 5 mm into the top of the cylinder.
  const Vec3 top = scene.cylinder.T_world_object * Vec3(0, p.cylinder_radius_m + p.fingertip_radius_m - 0.005, 0);
  const DrawnSphere d = drawn_sphere(p, scene, top);
  ASSERT_TRUE(d.contact.in_contact);
  EXPECT_NEAR(d.contact.penetration_m, 0.005, 1e-9);
  EXPECT_NEAR((d.p_in_world - top).norm(), 0.005, 1e-9);
  EXPECT_GT(d.p_in_world.y(), top.y());
  // F = 0.45 N + 0.042 N/cm x 0.5 cm, along the pad's normal when the pad faces down.
  TrialPresentation t;
  t.haptic = HapticTarget::true_sphere;
  const TrialView v = trial_view(p, scene, t, Phase::adaptation, top, Cue::none);
  ASSERT_TRUE(v.p_haptic_centre_in_world);
  const haptics::FingertipForce f = haptic_force(p, scene, v, Quat::Identity());
  EXPECT_NEAR(f.normal_n, 0.45 + 0.042 * 0.5, 1e-9);
  // Experiment 1 has no haptic sphere; the blind phase draws nothing.
  t.haptic = HapticTarget::none;
  EXPECT_FALSE(trial_view(p, scene, t, Phase::answer, top, Cue::none).p_haptic_centre_in_world);
  EXPECT_TRUE(trial_view(p, scene, t, Phase::blind, top, Cue::up).black);
  EXPECT_TRUE(trial_view(p, scene, t, Phase::blind, top, Cue::up).spheres.empty());
  // Haptics on the false sphere: the force follows the false sphere's contact.
  t.haptic = HapticTarget::false_sphere;
  t.offset_m = 0.03;
  t.u_offset_in_world = Vec3::UnitY();  // the false sphere 3 cm above: no contact
  const TrialView above = trial_view(p, scene, t, Phase::answer, top, Cue::none);
  EXPECT_EQ(above.spheres.size(), 2u);
  EXPECT_EQ(haptic_force(p, scene, above, Quat::Identity()).normal_n, 0.0);
}

TEST(PerceptionTrial, PresentationsAreReproducibleFromTheSeed) {
  const PerceptionProtocol p = defaults();
  auto design = study::StudyDesign::load_file(p.design_file);
  ASSERT_TRUE(design);
  study::Trial trial;
  trial.index = 17;
  trial.levels = {"false_sphere"};
  trial.stimulus = 4.5;
  auto a = make_presentation(trial, *design, 99);
  auto b = make_presentation(trial, *design, 99);
  trial.index = 18;
  auto c = make_presentation(trial, *design, 99);
  ASSERT_TRUE(a && b && c);
  EXPECT_EQ(a->u_offset_in_world, b->u_offset_in_world);
  EXPECT_EQ(a->true_is_blue, b->true_is_blue);
  EXPECT_NE(a->u_offset_in_world, c->u_offset_in_world);
  EXPECT_NEAR(a->u_offset_in_world.norm(), 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(a->offset_m, 0.045);  // the design's unit is cm
  EXPECT_EQ(a->haptic, HapticTarget::false_sphere);
  trial.levels = {"sometimes"};
  EXPECT_FALSE(make_presentation(trial, *design, 99));
}

TEST(PerceptionObserver, DefaultThresholdWithoutHapticsIsTheThesisValue) {
  const ObserverParams o;
  EXPECT_NEAR(true_threshold_cm(o, o.proprioceptive_noise_cm, HapticTarget::none, 0.75), 5.11, 0.01);
  // Haptics on the true sphere lowers it, on the false sphere raises it, as in the thesis.
  EXPECT_LT(true_threshold_cm(o, o.proprioceptive_noise_cm, HapticTarget::true_sphere, 0.75), 4.0);
  EXPECT_GT(true_threshold_cm(o, o.proprioceptive_noise_cm, HapticTarget::false_sphere, 0.75), 6.0);
  EXPECT_NEAR(true_max_allowable_error_cm(o, o.proprioceptive_noise_cm), 3.57, 0.01);
  // No offset, no haptics: a coin flip.
  EXPECT_NEAR(p_correct(o, 1.63, HapticTarget::none, 0.0), 0.5, 1e-12);
}

// The observer's sampled decisions follow the closed form it documents.
TEST(PerceptionObserver, DecisionsMatchTheClosedForm) {
  ObserverParams o;
  o.haptic_noise = 0.5;  // exercise every term
  const double sigma_cm = 1.8;
  for (HapticTarget h : {HapticTarget::none, HapticTarget::true_sphere, HapticTarget::false_sphere}) {
    for (double d_cm : {1.5, 4.5}) {
      SimulatedObserver observer(o, sigma_cm, 1234 + static_cast<int>(h));
      const int n = 20000;
      int correct = 0;
      const Vec3 p_true(0.1, 1.2, -0.3);
      const Vec3 p_false = p_true + d_cm * 0.01 * Vec3(0.6, -0.8, 0.0);
      for (int i = 0; i < n; ++i) {
        observer.begin_answer();
        // Blue is the true sphere; the felt force goes with the haptic sphere's contact.
        for (int k = 0; k < 100; ++k) {
          const bool on = k % 3 == 0;
          const double f = (h != HapticTarget::none && on) ? 0.6 : 0.0;
          const bool blue_touch = h == HapticTarget::false_sphere ? !on : on;
          observer.feel(f, blue_touch ? 1.0 : 0.0, blue_touch ? 0.0 : 1.0);
        }
        correct += observer.choose_blue(p_true, p_true, p_false) ? 1 : 0;
        if (h != HapticTarget::none) {
          ASSERT_EQ(observer.last_attribution(), h == HapticTarget::true_sphere ? 1 : -1);
        }
      }
      const double expected = p_correct(o, sigma_cm, h, d_cm);
      EXPECT_NEAR(static_cast<double>(correct) / n, expected, 0.012) << to_string(h) << " at " << d_cm << " cm";
    }
  }
}

std::unique_ptr<ForceChannel> emulated_channel() {
  auto model = haptics::load_device_model(std::string(PROPRIO_SOURCE_DIR) + "/config/haptics/band_2dof.toml");
  EXPECT_TRUE(model);
  std::shared_ptr<const haptics::FingertipDeviceModel> shared(std::move(*model));
  auto sink = haptics::EmulatedFingertip::create(shared);
  EXPECT_TRUE(sink);
  return std::make_unique<ForceChannel>(shared, std::shared_ptr<haptics::FingertipSink>(std::move(*sink)));
}

TEST(PerceptionForceChannel, ZeroWhenDisengagedRampedAndClampedWhenEngaged) {
  auto channel = emulated_channel();
  haptics::FingertipForce big;
  big.normal_n = 50.0;
  TimeNs t = kNsPerSecond;
  channel->update(big, t);
  EXPECT_EQ(channel->sent().normal_n, 0.0);  // never engaged
  channel->engage(t);
  double first = -1, last = 0;
  for (int i = 0; i < 2000; ++i) {
    t += kNsPerMillisecond;
    channel->update(big, t);
    const double out = channel->sent().normal_n;
    if (first < 0) first = out;
    last = out;
  }
  EXPECT_LT(first, 0.1);  // ramped in, not stepped
  EXPECT_GT(last, 0.5);
  EXPECT_LE(last, channel->gate().limits().max_normal_n + 1e-9);  // clamped
  channel->disengage(t);
  EXPECT_EQ(channel->sent().normal_n, 0.0);
}

// The live experiment's trial loop, with synthetic frames instead of a headset.
TEST(PerceptionLive, FrameHookRunsTrialsAndRecordsAnswers) {
  PerceptionProtocol p = defaults();
  p.familiarisation_s = 1.0;
  auto design = study::StudyDesign::load_file(p.design_file);
  ASSERT_TRUE(design);
  const fs::path out = fs::path(PROPRIO_TEST_OUT_DIR) / "live";
  fs::remove_all(out);
  study::SessionOptions so;
  so.out_dir = out;
  so.participant = "P01";
  so.sync_each_trial = false;
  auto e = LiveExperiment::create(p, *design, so, nullptr);
  ASSERT_TRUE(e) << e.error().message;
  const engine::Scene scene = live_scene(p);
  engine::FrameContext f;
  f.entities.push_back({true, scene.entities[0].body.rgba, std::nullopt});
  HandPose hand;
  hand.active = true;
  const Pose head{Quat::Identity(), Vec3(0, 1.6, 0)};
  hand.joint(HandJoint::index_tip) = Pose{Quat::Identity(), head * Vec3(0, -0.1, -0.3)};
  HandPose proxy;
  f.tracked = &hand;
  f.proxy = &proxy;
  f.T_world_head = head;
  TimeNs t = kNsPerSecond;
  auto frame = [&](std::vector<std::string> keys = {}) {
    t += 11 * kNsPerMillisecond;  // 90 Hz
    f.time_ns = t;
    f.keys = std::move(keys);
    f.markers.clear();
    f.prompt.clear();
    f.show_scene = true;
    (*e)->on_frame(f);
  };
  frame();  // places the scene
  ASSERT_TRUE(f.entities[0].T_world_entity);
  EXPECT_FALSE(f.show_hands);
  frame({"enter"});  // ends the familiarisation
  frame();
  EXPECT_TRUE(f.show_scene);
  EXPECT_EQ(f.markers.size(), 1u);  // adaptation: the true sphere alone
  // Into the blind phase: black, an arrow (the finger is below the view's centre line).
  while (static_cast<double>(t) * 1e-9 < 1.0 + p.adaptation_s + 0.5) frame();
  EXPECT_FALSE(f.show_scene);
  EXPECT_GE(f.markers.size(), 3u);  // the arrow's shaft and head
  // The answer phase: two spheres and the question.
  while (static_cast<double>(t) * 1e-9 < 1.0 + p.adaptation_s + p.blind_s + 0.2) frame();
  EXPECT_EQ(f.markers.size(), 2u);
  EXPECT_NE(f.prompt.find("B = blue"), std::string::npos);
  frame({"space"});  // another look: the same trial from its start, nothing recorded
  EXPECT_EQ((*e)->completed_trials(), 0);
  frame();
  EXPECT_EQ(f.markers.size(), 1u);
  while (f.prompt.find("B = blue") == std::string::npos) frame();
  frame({"b"});
  EXPECT_EQ((*e)->completed_trials(), 1);
  ASSERT_TRUE((*e)->status());
  auto table = study::read_csv(out / "perception-threshold_P01_s1.csv");
  ASSERT_TRUE(table) << table.error().message;
  ASSERT_EQ(table->rows.size(), 1u);
  EXPECT_TRUE(table->column("true_sphere_colour"));
}

}  // namespace
}  // namespace proprio::perception
