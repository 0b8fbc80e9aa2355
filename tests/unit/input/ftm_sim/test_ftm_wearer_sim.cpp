// The simulated FTM wearer: determinism, time order and rates, phases, the
// separation of truth and samples, the synergy residuals' R², imperfect
// calibration poses, magnetic disturbance, wrist dropouts and the switches.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::ftm_sim {
namespace ftm_wearer_sim_test {

using ftm::FtmEvent;

FtmWearerOptions fws_short(double task_s = 4.0) {
  FtmWearerOptions o;
  o.seed = 7;
  o.task_s = task_s;
  o.calibration.enabled = false;
  return o;
}

std::unique_ptr<FtmWearerSimulator> fws_make(const FtmWearerOptions& o) {
  auto s = FtmWearerSimulator::create(o);
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
  return s.ok() ? std::move(*s) : nullptr;
}

std::vector<FtmEvent> fws_run(FtmWearerSimulator& s, TimeNs until, DurationNs step = 20 * kNsPerMillisecond) {
  std::vector<FtmEvent> out;
  for (TimeNs t = 0; t < until; t += step) s.advance(t, out);
  s.advance(until, out);
  return out;
}

// Bytes of what matters in an event (FtmEvent has padding: compare fields).
std::vector<double> fws_flatten(const std::vector<FtmEvent>& ev, int kind_filter = -1) {
  std::vector<double> v;
  for (const auto& e : ev) {
    if (kind_filter >= 0 && static_cast<int>(e.kind) != kind_filter) continue;
    v.push_back(static_cast<double>(e.time_ns()));
    v.push_back(e.index);
    switch (e.kind) {
      case FtmEvent::Kind::imu:
        for (int k = 0; k < 3; ++k) v.insert(v.end(), {e.imu.accel_mps2[k], e.imu.gyro_radps[k], e.imu.mag_uT[k]});
        v.push_back(e.imu.mag_fresh);
        v.push_back(e.imu.status);
        break;
      case FtmEvent::Kind::bend: v.push_back(e.bend.capacitance_pF); break;
      case FtmEvent::Kind::wrist:
        v.insert(v.end(), {e.wrist.T_world_wrist.p.x(), e.wrist.T_world_wrist.p.y(), e.wrist.T_world_wrist.p.z(),
                           e.wrist.T_world_wrist.q.w(), e.wrist.T_world_wrist.q.x(), e.wrist.valid ? 1.0 : 0.0});
        break;
    }
  }
  return v;
}

bool fws_same(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

// Accelerometer and gyro only (the compass may see a changed magnetic scene).
std::vector<double> fws_inertial(const std::vector<FtmEvent>& ev) {
  std::vector<double> v;
  for (const auto& e : ev) {
    if (e.kind != FtmEvent::Kind::imu) continue;
    for (int k = 0; k < 3; ++k) v.insert(v.end(), {e.imu.accel_mps2[k], e.imu.gyro_radps[k]});
  }
  return v;
}

TEST(FtmWearerOptions, DefaultsValidateAndBadFieldsAreNamed) {
  FtmWearerOptions o;
  EXPECT_TRUE(o.validate().ok());
  EXPECT_NE(o.describe().find("protocol=free-motion"), std::string::npos) << o.describe();
  auto expect_bad = [](FtmWearerOptions b, const char* field) {
    const Status st = b.validate();
    ASSERT_FALSE(st.ok()) << field;
    EXPECT_NE(st.error().message.find(field), std::string::npos) << st.error().message;
  };
  FtmWearerOptions b;
  b.bend.rate_hz = 0.0;
  expect_bad(b, "bend.rate_hz");
  b = {};
  b.wrist.latency_s = -0.1;
  expect_bad(b, "wrist.latency_s");
  b = {};
  b.protocol = sim::MotionProtocol::wrist_sweep;
  expect_bad(b, "protocol");
  b = {};
  b.imu.magnetometer.enabled = false;
  expect_bad(b, "imu.magnetometer.enabled");
  b = {};
  b.subject.subject_index = 99;
  expect_bad(b, "subject.subject_index");
  b = {};
  b.calibration.figure_eight_s = 1.0;
  expect_bad(b, "calibration.figure_eight_s");
  EXPECT_FALSE(FtmWearerSimulator::create(b).ok());
}

TEST(FtmWearerSimulator, SameOptionsGiveTheSameBytesAndAnotherSeedDoesNot) {
  auto o = fws_short(3.0);
  o.protocol = sim::MotionProtocol::pinch_grasp;
  auto a = fws_make(o), b = fws_make(o);
  ASSERT_TRUE(a && b);
  const auto ea = fws_flatten(fws_run(*a, a->end_ns()));
  // Different advance steps must not change the stream either.
  const auto eb = fws_flatten(fws_run(*b, b->end_ns(), 7'300'000));
  EXPECT_TRUE(fws_same(ea, eb));
  o.seed = 8;
  auto c = fws_make(o);
  EXPECT_FALSE(fws_same(ea, fws_flatten(fws_run(*c, c->end_ns()))));
}

TEST(FtmWearerSimulator, SamplesComeInTimeOrderAtTheBoardRates) {
  auto s = fws_make(fws_short(5.0));
  ASSERT_TRUE(s);
  const auto ev = fws_run(*s, s->end_ns(), 13'000'000);
  std::array<int, 4> imu{}, fresh{};
  std::array<int, 3> bend{};
  int wrist = 0;
  for (std::size_t i = 0; i < ev.size(); ++i) {
    if (i > 0) {
      ASSERT_LE(ev[i - 1].time_ns(), ev[i].time_ns()) << i;
      if (ev[i - 1].time_ns() == ev[i].time_ns()) {
        ASSERT_LE(ev[i - 1].kind, ev[i].kind) << i;
      }
    }
    ASSERT_LE(ev[i].time_ns(), s->end_ns());
    switch (ev[i].kind) {
      case FtmEvent::Kind::imu:
        ++imu[ev[i].index];
        fresh[ev[i].index] += ev[i].imu.mag_fresh ? 1 : 0;
        break;
      case FtmEvent::Kind::bend: ++bend[ev[i].index]; break;
      case FtmEvent::Kind::wrist: ++wrist; break;
    }
  }
  const double secs = ns_to_seconds(s->end_ns());
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(imu[static_cast<std::size_t>(i)] / secs, 200.0, 1.0) << i;
    EXPECT_NEAR(fresh[static_cast<std::size_t>(i)] / secs, 100.0, 1.0) << i;
  }
  for (int b : bend) EXPECT_NEAR(b / secs, 1000.0, 1.0);
  EXPECT_NEAR(wrist / secs, 90.0, 1.0);
  // Nothing past the end, however far one asks.
  std::vector<FtmEvent> more;
  s->advance(s->end_ns() + kNsPerSecond, more);
  EXPECT_TRUE(more.empty());
}

TEST(FtmWearerSimulator, PhasesTileTheSessionInOrder) {
  FtmWearerOptions o;
  o.task_s = 2.0;
  auto s = fws_make(o);
  ASSERT_TRUE(s);
  const auto ph = s->phases();
  ASSERT_EQ(ph.size(), 5u);
  const FtmPhase order[] = {FtmPhase::figure_eight, FtmPhase::pose_flat, FtmPhase::pose_thumb_parallel,
                            FtmPhase::pose_bend_90, FtmPhase::task};
  TimeNs t = 0;
  for (std::size_t i = 0; i < ph.size(); ++i) {
    EXPECT_EQ(ph[i].phase, order[i]);
    EXPECT_EQ(ph[i].begin_ns, t);
    EXPECT_GT(ph[i].end_ns, ph[i].begin_ns);
    EXPECT_GE(ph[i].hold_begin_ns, ph[i].begin_ns);
    t = ph[i].end_ns;
    EXPECT_EQ(s->truth_at((ph[i].begin_ns + ph[i].end_ns) / 2).phase, order[i]);
  }
  EXPECT_EQ(t, s->end_ns());
  EXPECT_NEAR(ns_to_seconds(ph[0].end_ns), 16.0, 1e-9);
  EXPECT_NEAR(ns_to_seconds(ph[1].end_ns - ph[1].hold_begin_ns), 3.0, 1e-9);
  // The figure-eight swings the dorsum through a wide range of orientations
  // (for the compass fit): the largest angle away from the rest is large.
  const Quat q0 = s->truth_at(0).pose.joint(HandJoint::wrist).q;
  double widest = 0.0;
  for (TimeNs tt = 0; tt < ph[0].end_ns; tt += 50 * kNsPerMillisecond) {
    widest = std::max(widest, angle_between(q0, s->truth_at(tt).pose.joint(HandJoint::wrist).q));
  }
  std::printf("[ftm_sim] figure-eight: widest dorsum rotation from rest %.1f deg\n", rad_to_deg(widest));
  EXPECT_GT(widest, deg_to_rad(60.0));
  // The IMUs see it: the dorsum's gyro turns fast but stays inside its
  // range, and no sample is flagged.
  std::vector<FtmEvent> ev;
  s->advance(ph[0].end_ns, ev);
  double fastest = 0.0;
  for (const auto& e : ev) {
    if (e.kind != FtmEvent::Kind::imu) continue;
    EXPECT_EQ(e.imu.status, 0);
    if (e.index == 0) fastest = std::max(fastest, e.imu.gyro_radps.norm());
  }
  std::printf("[ftm_sim] figure-eight: fastest dorsum gyro %.2f rad/s\n", fastest);
  EXPECT_GT(fastest, 1.0);
  EXPECT_LT(fastest, o.imu.gyro_range_radps);
}

TEST(FtmWearerSimulator, SamplesDifferFromTruthByTheModelledNoise) {
  auto o = fws_short(6.0);
  auto s = fws_make(o);
  ASSERT_TRUE(s);
  const auto ev = fws_run(*s, s->end_ns());
  // Bend sensors: against the noise-free capacitance (low-pass lag aside,
  // judged while the hand holds its first posture: the first 3 s).
  double sum2 = 0.0;
  int n = 0;
  for (const auto& e : ev) {
    if (e.kind != FtmEvent::Kind::bend || e.bend.time_ns > 2 * kNsPerSecond || e.bend.time_ns < kNsPerSecond) continue;
    const double d = e.bend.capacitance_pF - s->bend_capacitance_truth_pF(static_cast<ftm::FtmBend>(e.index), e.bend.time_ns);
    sum2 += d * d;
    ++n;
  }
  const double bend_rms = std::sqrt(sum2 / n);
  std::printf("[ftm_sim] bend: rms(sample - truth) at rest %.4f pF (noise sigma %.3f)\n", bend_rms, o.bend.noise_sigma_pF);
  EXPECT_GT(bend_rms, 0.5 * o.bend.noise_sigma_pF);
  EXPECT_LT(bend_rms, 2.0 * o.bend.noise_sigma_pF);
  // Wrist: valid samples against the truth at t − latency (jitter only) and at t.
  double e_lat = 0.0, e_now = 0.0;
  int nw = 0;
  const TimeNs lat = seconds_to_ns(o.wrist.latency_s);
  for (const auto& e : ev) {
    if (e.kind != FtmEvent::Kind::wrist || !e.wrist.valid) continue;
    e_lat += (e.wrist.T_world_wrist.p - s->truth_at(std::max<TimeNs>(e.wrist.time_ns - lat, 0)).pose.joint(HandJoint::wrist).p).norm();
    e_now += (e.wrist.T_world_wrist.p - s->truth_at(e.wrist.time_ns).pose.joint(HandJoint::wrist).p).norm();
    ++nw;
  }
  ASSERT_GT(nw, 100);
  e_lat /= nw;
  e_now /= nw;
  std::printf("[ftm_sim] wrist: mean |sample - truth(t - latency)| %.3f mm, |sample - truth(t)| %.3f mm\n", e_lat * 1e3,
              e_now * 1e3);
  EXPECT_GT(e_lat, 0.5e-3);  // 3-D mean of 0.7 mm per axis ≈ 1.1 mm
  EXPECT_LT(e_lat, 2.0e-3);
  EXPECT_GT(e_now, e_lat);  // the latency shows while the hand moves
  // IMUs: a gyro sample is not the truth's angular rate (noise + bias).
  const auto& gt = s->imus().ground_truth();
  ASSERT_EQ(gt.size(), 4u);
  const FtmEvent* last_imu = nullptr;
  for (auto it = ev.rbegin(); it != ev.rend(); ++it) {
    if (it->kind == FtmEvent::Kind::imu && it->index == 0) {
      last_imu = &*it;
      break;
    }
  }
  ASSERT_NE(last_imu, nullptr);
  ASSERT_EQ(last_imu->imu.time_ns, gt[0].time_ns);
  EXPECT_GT((last_imu->imu.gyro_radps - gt[0].angular_rate_radps).norm(), 1e-4);
}

TEST(FtmWearerSimulator, DistalJointsFollowTheSynergyWithHrabiaLikeR2) {
  // R² of the synergy's prediction (DIP = 2/3 PIP, thumb IP = 1/2 MCP):
  // 1 − Σ(x − x̂)² / Σ(x − x̄)², over 10 min of free motion per seed, 10 Hz.
  for (std::uint64_t seed : {3ull, 11ull, 29ull, 5ull, 6ull}) {
    FtmWearerOptions o = fws_short(600.0);
    o.seed = seed;
    // Seeds 5 and 6 run the pinch-grasp protocol: its postures are fixed, only the residuals vary.
    if (seed == 5 || seed == 6) o.protocol = sim::MotionProtocol::pinch_grasp;
    auto s = fws_make(o);
    ASSERT_TRUE(s);
    struct Acc {
      double res2 = 0, sum = 0, sum2 = 0;
      int n = 0;
      void add(double x, double pred) {
        res2 += (x - pred) * (x - pred);
        sum += x;
        sum2 += x * x;
        ++n;
      }
      double r2() const { return 1.0 - res2 / (sum2 - sum * sum / n); }
    } idx, mid, thb;
    for (TimeNs t = 0; t < s->end_ns(); t += 100 * kNsPerMillisecond) {
      const HandAngles a = s->angles_at(t);
      idx.add(a[index_of(HandDof::index_dip_flexion)], 2.0 / 3.0 * a[index_of(HandDof::index_pip_flexion)]);
      mid.add(a[index_of(HandDof::middle_dip_flexion)], 2.0 / 3.0 * a[index_of(HandDof::middle_pip_flexion)]);
      thb.add(a[index_of(HandDof::thumb_ip_flexion)], 0.5 * a[index_of(HandDof::thumb_mcp_flexion)]);
    }
    std::printf("[ftm_sim] synergy R2 %s seed %llu: index DIP %.3f, middle DIP %.3f, thumb IP %.3f\n",
                std::string(sim::to_string(o.protocol)).c_str(), static_cast<unsigned long long>(seed), idx.r2(),
                mid.r2(), thb.r2());
    for (double r2 : {idx.r2(), mid.r2(), thb.r2()}) {
      // Pinch-grasp's thumb IP is not asserted: HandMotionGenerator's scripted
      // postures put it far off 1/2 MCP while the MCP barely varies (R² ~0.15,
      // printed above); see FtmSynergyOptions.
      if (o.protocol == sim::MotionProtocol::pinch_grasp && r2 == thb.r2()) continue;
      EXPECT_GE(r2, 0.6);
      EXPECT_LE(r2, 0.8);
    }
    if (seed == 3) {  // without residuals the synergy is exact (up to the joint limits)
      o.synergy.enable_residuals = false;
      auto e = fws_make(o);
      double worst = 0.0;
      // From 4 s: the first keyframe is the generator's relaxed posture, whose
      // DIP is not on the synergy (10° vs 2/3 × 20°).
      for (TimeNs t = 4 * kNsPerSecond; t < 60 * kNsPerSecond; t += 100 * kNsPerMillisecond) {
        const HandAngles a = e->angles_at(t);
        worst = std::max(worst, std::abs(a[index_of(HandDof::index_dip_flexion)] -
                                         2.0 / 3.0 * a[index_of(HandDof::index_pip_flexion)]));
      }
      EXPECT_LT(worst, 1e-9);
    }
  }
}

TEST(FtmWearerSimulator, CalibrationPosesAreHeldAFewDegreesOff) {
  double sum = 0.0, worst = 0.0;
  int n = 0;
  for (std::uint64_t seed : {1ull, 2ull, 3ull, 4ull, 5ull}) {
    FtmWearerOptions o;
    o.seed = seed;
    o.task_s = 1.0;
    auto s = fws_make(o);
    ASSERT_TRUE(s);
    for (const auto& span : s->phases()) {
      if (span.phase == FtmPhase::figure_eight || span.phase == FtmPhase::task) continue;
      const HandAngles inst = s->instructed_angles(span.phase);
      const HandAngles held = s->truth_at((span.hold_begin_ns + span.end_ns) / 2).angles;
      for (HandDof d : ftm::kFtmTrackedDofs) {
        const double dev = std::abs(held[index_of(d)] - inst[index_of(d)]);
        sum += dev;
        worst = std::max(worst, dev);
        ++n;
      }
    }
    if (seed == 1) {  // instructions as specified
      const HandAngles bend = s->instructed_angles(FtmPhase::pose_bend_90);
      EXPECT_NEAR(bend[index_of(HandDof::index_pip_flexion)], deg_to_rad(90.0), 1e-12);
      EXPECT_NEAR(bend[index_of(HandDof::middle_pip_flexion)], deg_to_rad(90.0), 1e-12);
      const HandAngles flat = s->instructed_angles(FtmPhase::pose_flat);
      for (double x : flat) EXPECT_EQ(x, 0.0);
    }
  }
  const double mean = sum / n;
  std::printf("[ftm_sim] calibration poses: mean |held - instructed| %.2f deg, worst %.2f deg (tracked DOFs, 5 seeds)\n",
              rad_to_deg(mean), rad_to_deg(worst));
  EXPECT_GT(mean, deg_to_rad(1.5));
  EXPECT_LT(mean, deg_to_rad(6.0));
  EXPECT_LT(worst, deg_to_rad(15.0));
  // Without the pose error only the wobble is left.
  FtmWearerOptions o;
  o.task_s = 1.0;
  o.calibration.enable_pose_error = false;
  auto s = fws_make(o);
  for (const auto& span : s->phases()) {
    if (span.phase == FtmPhase::figure_eight || span.phase == FtmPhase::task) continue;
    const HandAngles inst = s->instructed_angles(span.phase);
    for (TimeNs t = span.hold_begin_ns; t < span.end_ns; t += 100 * kNsPerMillisecond) {
      const HandAngles a = s->truth_at(t).angles;
      for (HandDof d : ftm::kFtmTrackedDofs) {
        EXPECT_LE(std::abs(a[index_of(d)] - inst[index_of(d)]), o.calibration.wobble_amplitude_rad + 1e-9);
      }
    }
  }
}

TEST(FtmWearerSimulator, MagneticObjectsRaiseDisturbedOnlyWhileNear) {
  auto o = fws_short(40.0);
  o.magnetic.objects = FtmMagneticOptions::figure_4_14_objects(2 * kNsPerSecond);
  auto s = fws_make(o);
  ASSERT_TRUE(s);
  for (const auto& obj : o.magnetic.objects) {
    const TimeNs t0 = obj.t_start_ns, t_end = t0 + obj.approach_ns + obj.hold_ns + obj.retreat_ns;
    double peak[4] = {0, 0, 0, 0};
    int flagged_in_hold = 0, held = 0;
    for (TimeNs t = t0 - kNsPerSecond; t < t_end + kNsPerSecond; t += 20 * kNsPerMillisecond) {
      const auto tr = s->truth_at(t);
      const bool inside = t > t0 && t < t_end;
      const bool in_hold = t >= t0 + obj.approach_ns && t <= t0 + obj.approach_ns + obj.hold_ns;
      for (std::size_t i = 0; i < 4; ++i) {
        if (!inside) {
          EXPECT_FALSE(tr.mag_disturbed[i]) << to_string(obj.kind) << " imu " << i << " t " << t;
        }
        peak[i] = std::max(peak[i], tr.mag_disturbance_uT[i]);
      }
      if (in_hold) {
        ++held;
        flagged_in_hold += tr.mag_disturbed[0] ? 1 : 0;
      }
    }
    std::printf("[ftm_sim] %s at %.0f mm above the dorsum IMU: peak disturbance %.1f / %.1f / %.1f / %.1f uT "
                "(dorsum, thumb MC, index PP, middle PP)\n",
                std::string(to_string(obj.kind)).c_str(), obj.near_distance_m * 1e3, peak[0], peak[1], peak[2], peak[3]);
    EXPECT_EQ(flagged_in_hold, held) << to_string(obj.kind);
  }
  // The compass readings see it too: the dorsum's raw field norm moves.
  std::vector<FtmEvent> ev = fws_run(*s, 3 * kNsPerSecond + 4 * kNsPerSecond / 2);
  double n_before = 0, n_hold = 0;
  for (const auto& e : ev) {
    if (e.kind != FtmEvent::Kind::imu || e.index != 0 || !e.imu.mag_fresh) continue;
    if (e.imu.time_ns < 2 * kNsPerSecond) n_before = e.imu.mag_uT.norm();
    if (e.imu.time_ns > 4 * kNsPerSecond + 500 * kNsPerMillisecond) n_hold = e.imu.mag_uT.norm();
  }
  EXPECT_GT(std::abs(n_hold - n_before), 50.0);
}

TEST(FtmWearerSimulator, FingertipDevicesFollowContactAndTheEmulatorsCurrent) {
  auto o = fws_short(18.0);
  o.protocol = sim::MotionProtocol::pinch_grasp;
  auto s = fws_make(o);
  ASSERT_TRUE(s);
  double peak[4] = {0, 0, 0, 0};
  int contact_samples = 0, full_current = 0, disturbed = 0;
  for (TimeNs t = 0; t < s->end_ns(); t += 10 * kNsPerMillisecond) {
    const auto tr = s->truth_at(t);
    for (std::size_t i = 0; i < 4; ++i) {
      peak[i] = std::max(peak[i], tr.mag_disturbance_uT[i]);
      disturbed += tr.mag_disturbed[i] ? 1 : 0;
    }
    if (tr.contact[1] >= 1.0) {
      ++contact_samples;
      full_current += std::abs(tr.fingertip_current_A[1] - o.magnetic.device.full_current_A) < 1e-12 ? 1 : 0;
    } else if (tr.contact[1] <= 0.0) {
      EXPECT_EQ(tr.fingertip_current_A[1], 0.0);
    }
  }
  std::printf("[ftm_sim] fingertip devices (10 mm rule), pinch-grasp: peak disturbance %.4f / %.4f / %.4f / %.4f uT "
              "(dorsum, thumb MC, index PP, middle PP); disturbed samples %d\n",
              peak[0], peak[1], peak[2], peak[3], disturbed);
  EXPECT_GT(contact_samples, 100);
  EXPECT_EQ(full_current, contact_samples);
  EXPECT_GT(peak[2], 0.0);
  EXPECT_LT(peak[2], 0.2);  // the preset's own caution: ~0.02 µT at the proximal IMUs
  EXPECT_EQ(disturbed, 0);
  // A disturbance scenario: devices with one 2 mm NdFeB cube's moment
  // (8e-3 A·m², the preset's own comparison), 400x the 10 mm rule's. The
  // field is linear in the moment, so the same instants scale by exactly 400.
  {
    auto big = o;
    big.magnetic.device.moment_static_Am2 *= 400.0;
    big.magnetic.device.moment_per_current_Am2_per_A *= 400.0;
    auto b = fws_make(big);
    double big_peak[4] = {0, 0, 0, 0};
    int big_disturbed[4] = {0, 0, 0, 0}, samples = 0;
    for (TimeNs t = 0; t < b->end_ns(); t += 10 * kNsPerMillisecond) {
      const auto tb = b->truth_at(t), ts = s->truth_at(t);
      ++samples;
      for (std::size_t i = 0; i < 4; ++i) {
        big_peak[i] = std::max(big_peak[i], tb.mag_disturbance_uT[i]);
        big_disturbed[i] += tb.mag_disturbed[i] ? 1 : 0;
        EXPECT_NEAR(tb.mag_disturbance_uT[i], 400.0 * ts.mag_disturbance_uT[i], 1e-9 + 1e-9 * tb.mag_disturbance_uT[i]);
      }
    }
    std::printf("[ftm_sim] fingertip devices x400 (2 mm NdFeB cube): peak %.2f / %.2f / %.2f / %.2f uT, disturbed "
                "%.1f / %.1f / %.1f / %.1f %% of samples\n",
                big_peak[0], big_peak[1], big_peak[2], big_peak[3], 100.0 * big_disturbed[0] / samples,
                100.0 * big_disturbed[1] / samples, 100.0 * big_disturbed[2] / samples, 100.0 * big_disturbed[3] / samples);
  }
  // The haptics emulator's current replaces the contact model from then on.
  s->set_fingertip_current(Finger::index, 2 * kNsPerSecond, 0.2);
  EXPECT_DOUBLE_EQ(s->truth_at(2 * kNsPerSecond + 1).fingertip_current_A[1], 0.2);
  EXPECT_DOUBLE_EQ(s->truth_at(15 * kNsPerSecond).fingertip_current_A[1], 0.2);
  EXPECT_EQ(s->truth_at(kNsPerSecond).fingertip_current_A[1], 0.0);
}

TEST(FtmWearerSimulator, WristTrackerDropsOut) {
  auto o = fws_short(40.0);
  auto s = fws_make(o);
  ASSERT_TRUE(s);
  std::vector<FtmEvent> ev;
  s->advance(s->end_ns(), ev);
  int total = 0, lost = 0, episodes = 0;
  bool prev_valid = true;
  for (const auto& e : ev) {
    if (e.kind != FtmEvent::Kind::wrist) continue;
    ++total;
    if (!e.wrist.valid) {
      ++lost;
      if (prev_valid) ++episodes;
    }
    prev_valid = e.wrist.valid;
  }
  std::printf("[ftm_sim] wrist tracker: %d of %d samples lost (%.1f %%) in %d dropouts over 40 s\n", lost, total,
              100.0 * lost / total, episodes);
  EXPECT_GT(episodes, 2);
  EXPECT_LT(lost, total / 10);
  o.wrist.enable_dropouts = false;
  auto q = fws_make(o);
  std::vector<FtmEvent> ev2;
  q->advance(q->end_ns(), ev2);
  for (const auto& e : ev2) {
    if (e.kind == FtmEvent::Kind::wrist) {
      ASSERT_TRUE(e.wrist.valid);
    }
  }
  // Only the wrist stream changed.
  EXPECT_TRUE(fws_same(fws_flatten(ev, 0), fws_flatten(ev2, 0)));
  EXPECT_TRUE(fws_same(fws_flatten(ev, 1), fws_flatten(ev2, 1)));
}

TEST(FtmWearerSimulator, EachSwitchChangesOnlyItsOwnEffect) {
  // 5 s: the hand holds its first posture for 3 s, then moves (lag and
  // latency only show in motion).
  auto base = fws_short(5.0);
  base.protocol = sim::MotionProtocol::pinch_grasp;
  auto run = [](const FtmWearerOptions& o) {
    auto s = fws_make(o);
    return fws_run(*s, s->end_ns());
  };
  const auto ref = run(base);
  constexpr int kImu = 0, kBend = 1, kWrist = 2;
  struct Case {
    const char* name;
    void (*apply)(FtmWearerOptions&);
    int changes;  // the one kind that must change
  };
  const Case cases[] = {
      {"bend.enable_noise", [](FtmWearerOptions& o) { o.bend.enable_noise = false; }, kBend},
      {"bend.enable_lowpass", [](FtmWearerOptions& o) { o.bend.enable_lowpass = false; }, kBend},
      {"bend.enable_nonlinearity", [](FtmWearerOptions& o) { o.bend.enable_nonlinearity = false; }, kBend},
      {"bend.enable_donning_spread", [](FtmWearerOptions& o) { o.bend.enable_donning_spread = false; }, kBend},
      {"wrist.enable_jitter", [](FtmWearerOptions& o) { o.wrist.enable_jitter = false; }, kWrist},
      {"wrist.enable_latency", [](FtmWearerOptions& o) { o.wrist.enable_latency = false; }, kWrist},
      {"imu.enable_white_noise", [](FtmWearerOptions& o) { o.imu.enable_white_noise = false; }, kImu},
  };
  for (const auto& c : cases) {
    auto o = base;
    c.apply(o);
    const auto ev = run(o);
    for (int kind : {kImu, kBend, kWrist}) {
      const bool same = fws_same(fws_flatten(ref, kind), fws_flatten(ev, kind));
      EXPECT_EQ(same, kind != c.changes) << c.name << " kind " << kind;
    }
  }
  // Magnetic switches: only the compass changes (accelerometer and gyro stay).
  {
    auto o = fws_short(20.0);
    o.magnetic.objects = FtmMagneticOptions::figure_4_14_objects(1 * kNsPerSecond);
    auto s1 = fws_make(o);
    const auto e1 = fws_run(*s1, 5 * kNsPerSecond);
    o.magnetic.enable_objects = false;
    auto s2 = fws_make(o);
    const auto e2 = fws_run(*s2, 5 * kNsPerSecond);
    EXPECT_TRUE(fws_same(fws_inertial(e1), fws_inertial(e2)));
    EXPECT_TRUE(fws_same(fws_flatten(e1, kBend), fws_flatten(e2, kBend)));
    EXPECT_FALSE(fws_same(fws_flatten(e1, kImu), fws_flatten(e2, kImu)));
  }
  // Fingertip devices and their contact current: the truth's disturbance
  // changes, the inertial, bend and wrist streams do not (at the IMUs the
  // 10 mm-rule devices are below one compass LSB, so the raw compass may not move).
  {
    auto o = fws_short(8.0);
    o.protocol = sim::MotionProtocol::pinch_grasp;
    auto s1 = fws_make(o);
    auto o2 = o;
    o2.magnetic.enable_fingertip_devices = false;
    auto s2 = fws_make(o2);
    auto o3 = o;
    o3.magnetic.enable_contact_current = false;
    auto s3 = fws_make(o3);
    const auto e1 = fws_run(*s1, s1->end_ns()), e2 = fws_run(*s2, s2->end_ns()), e3 = fws_run(*s3, s3->end_ns());
    for (const auto* e : {&e2, &e3}) {
      EXPECT_TRUE(fws_same(fws_inertial(e1), fws_inertial(*e)));
      EXPECT_TRUE(fws_same(fws_flatten(e1, kBend), fws_flatten(*e, kBend)));
      EXPECT_TRUE(fws_same(fws_flatten(e1, kWrist), fws_flatten(*e, kWrist)));
    }
    const TimeNs t_contact = 4 * kNsPerSecond + 500 * kNsPerMillisecond;  // the pinch is held
    ASSERT_GT(s1->truth_at(t_contact).contact[1], 0.99);
    EXPECT_GT(s1->truth_at(t_contact).mag_disturbance_uT[2], 0.0);
    EXPECT_EQ(s2->truth_at(t_contact).mag_disturbance_uT[2], 0.0);
    EXPECT_GT(s1->truth_at(t_contact).fingertip_current_A[1], 0.0);
    EXPECT_EQ(s3->truth_at(t_contact).fingertip_current_A[1], 0.0);
    EXPECT_NE(s1->truth_at(t_contact).mag_disturbance_uT[2], s3->truth_at(t_contact).mag_disturbance_uT[2]);
  }
  // The contact artefact shows only while a fingertip holds the object.
  {
    auto o = fws_short(12.0);
    o.protocol = sim::MotionProtocol::pinch_grasp;
    o.bend.enable_noise = false;
    auto s1 = fws_make(o);
    o.bend.enable_contact_artefact = false;
    auto s2 = fws_make(o);
    double in_contact = 0.0, outside = 0.0;
    for (TimeNs t = 0; t < s1->end_ns(); t += 5 * kNsPerMillisecond) {
      const double d = s1->bend_capacitance_truth_pF(ftm::FtmBend::index_pip, t) -
                       s2->bend_capacitance_truth_pF(ftm::FtmBend::index_pip, t);
      (s1->truth_at(t).contact[1] > 0.0 ? in_contact : outside) = std::max(
          s1->truth_at(t).contact[1] > 0.0 ? in_contact : outside, std::abs(d));
    }
    EXPECT_NEAR(in_contact, o.bend.contact_artefact_pF, 1e-9);
    EXPECT_EQ(outside, 0.0);
  }
  // Synergy residuals: the distal joints change; the IMU-carrying segments
  // and the bend sensors' joints do not (devices off: their dipoles ride on the tips).
  {
    auto o = fws_short(4.0);
    o.magnetic.enable_fingertip_devices = false;
    auto s1 = fws_make(o);
    o.synergy.enable_residuals = false;
    auto s2 = fws_make(o);
    const auto e1 = fws_run(*s1, s1->end_ns()), e2 = fws_run(*s2, s2->end_ns());
    for (int kind : {kImu, kBend, kWrist}) EXPECT_TRUE(fws_same(fws_flatten(e1, kind), fws_flatten(e2, kind))) << kind;
    EXPECT_NE(s1->angles_at(2 * kNsPerSecond)[index_of(HandDof::index_dip_flexion)],
              s2->angles_at(2 * kNsPerSecond)[index_of(HandDof::index_dip_flexion)]);
  }
}

TEST(FtmWearerSimulator, SubjectsAndHandsAreHonoured) {
  FtmWearerOptions o = fws_short(1.0);
  o.subject.subject_index = 14;
  auto s = fws_make(o);
  ASSERT_TRUE(s);
  auto subj = sim::sim_subject(14);
  ASSERT_TRUE(subj.ok());
  EXPECT_NEAR(s->model().shape().hand_length_m, subj->hand_length_m, 1e-12);
  o.hand = Handedness::left;
  auto l = fws_make(o);
  ASSERT_TRUE(l);
  EXPECT_EQ(l->truth_at(0).pose.hand, Handedness::left);
  EXPECT_FALSE(l->describe().empty());
}

}  // namespace ftm_wearer_sim_test
}  // namespace proprio::ftm_sim
