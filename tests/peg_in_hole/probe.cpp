// Runs one simulated trial and prints a trace (development aid):
//   peg_probe SETTING TRIAL SECONDS
// Env: EVERY=N print every N ticks (250); HF=1 the hand's force on the peg;
// FW=1 each fingertip's force (world and pad frame); PADS=1 each pad's normal
// against the direction to the peg's axis; TIPS=1 tip positions; ABD=rad the
// planned finger spread; STIFF=N·m/rad the finger coupling; GRIP=N the grip
// target; WRIST=1 the proxy wrist against the submitted one; THUMBROLL=deg
// the thumb's pronation; FAM=s spring familiarisation first (20); SPRING=1
// the trial itself on the spring; REPEAT=N N trials in a row by one user. "RELEASE why" lines say why the user let go.
// PSEED=<participant_seed from a study JSON> SETTINGS=1,4,2,...: that study
// participant again, exactly (its 180 + 180 s familiarisation unless FAM is
// set, then its trials in order);
// TRACE=k traces its k-th trial (EVERY=N adds forces and the peg every N ms).
// PAIRED=N TRIALS=T SETS=1,2,3,4 PBASE=b: N participants, each familiarised
// once, then T trials in each setting from a copy of that participant (the
// settings differ by nothing else); WHY=1 counts breaks and drops by phase.
// TRACKER=ftm (PAIRED only): a fresh simulated FTM glove per arm (the study's
// glove seed); ABLATE=none,truth,truth_wrist,... (DIAGNOSTIC,
// FtmGloveAblation; "ideal" = no glove) makes each variant an arm; FAMFTM=1
// familiarises through a glove as the study does.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>
#include "proprio/peg_in_hole/study_runner.hpp"
using namespace proprio;
using namespace proprio::peg_in_hole;

// A study participant as the study runner makes one, familiarised as
// published (180 + 180 s) unless FAM is set.
static SimulatedUser familiarised_participant(const PegInHoleConfig& c, const HandModel& hand,
                                              const std::shared_ptr<const haptics::FingertipDeviceModel>& dev,
                                              std::uint64_t pseed, SimulatedFtmGlove* glove = nullptr) {
  SimulatedUser pu(c, hand, mix_seed(pseed, 0x55534552));
  const double fam_s = getenv("FAM") ? atof(getenv("FAM")) : 180.0;
  for (WorldPhase phase : {WorldPhase::spring, WorldPhase::ground}) {
    pu.set_grasp_only(phase == WorldPhase::spring);
    SimulatedTrialOptions fo;
    fo.phase = phase;
    fo.time_limit_s = fam_s;
    fo.ftm_glove = glove;
    (void)run_simulated_trial(c, trial_layout(c, pseed, -1), Setting{true, true}, pu, hand, dev, fo);
    pu.set_grasp_only(false);
  }
  return pu;
}

// "a,b,c" -> {"a", "b", "c"}.
static std::vector<std::string> names_list(const char* text) {
  std::vector<std::string> out;
  std::string cur;
  for (const char* q = text; q && *q; ++q) {
    if (*q == ',') {
      if (!cur.empty()) out.push_back(cur);
      cur.clear();
    } else {
      cur += *q;
    }
  }
  if (!cur.empty()) out.push_back(cur);
  return out;
}

// "1,4,2" -> {1, 4, 2}, settings outside 1-4 dropped.
static std::vector<int> settings_list(const char* text) {
  std::vector<int> out;
  for (const char* q = text; q && *q;) {
    const int k = atoi(q);
    if (k >= 1 && k <= 4) out.push_back(k);
    while (*q && *q != ',') ++q;
    if (*q == ',') ++q;
  }
  return out;
}

int main(int argc, char** argv) {
  const int setting = argc > 1 ? std::atoi(argv[1]) : 1;
  const int trial = argc > 2 ? std::atoi(argv[2]) : 0;
  const double limit = argc > 3 ? std::atof(argv[3]) : 30;
  PegInHoleConfig c;
  if (getenv("STIFF")) c.devices.finger_joint_stiffness_nm_per_rad = atof(getenv("STIFF"));
  if (getenv("GRIP")) c.sim_user.grip_target_n = atof(getenv("GRIP"));
  if (getenv("ABD")) { c.sim_user.index_abduction_rad = atof(getenv("ABD")); c.sim_user.middle_abduction_rad = -atof(getenv("ABD")); }
  auto dev = load_device_model(c);
  if (!dev) { std::printf("%s\n", dev.error().message.c_str()); return 1; }
  if (getenv("THUMBROLL")) c.sim_user.thumb_pronation_deg = atof(getenv("THUMBROLL"));
  auto shape = simulated_participant_hand(c.sim_user);
  HandModel hand(*shape);
  const std::uint64_t user_seed = getenv("USER_SEED") ? std::strtoull(getenv("USER_SEED"), nullptr, 10) : 7;
  const std::uint64_t layout_seed = getenv("LAYOUT_SEED") ? std::strtoull(getenv("LAYOUT_SEED"), nullptr, 10) : 11;
  SimulatedUser user(c, hand, user_seed);
  const double fam = getenv("FAM") ? atof(getenv("FAM")) : 20.0;
  for (WorldPhase phase : {WorldPhase::spring, WorldPhase::ground}) {
    if (fam <= 0) break;
    user.set_grasp_only(phase == WorldPhase::spring);
    SimulatedTrialOptions fo;
    fo.phase = phase;
    fo.time_limit_s = fam;
    auto r = run_simulated_trial(c, trial_layout(c, layout_seed, -1), Setting{true, true}, user, hand, *dev, fo);
    user.set_grasp_only(false);
    std::printf("familiarisation %.0f s: %d breaks, felt gain %.2f\n", fam, r ? r->breaks : -1, user.felt_gain());
  }
  if (const char* ps = getenv("PSEED")) {
    // PSEED=<participant_seed from a study's JSON sidecar> SETTINGS=1,4,2,...:
    // that participant again (published familiarisation unless FAM is set),
    // its trials in order, with why the hand let go in trial TRACE (1-based).
    const std::uint64_t pseed = std::strtoull(ps, nullptr, 10);
    SimulatedUser pu = familiarised_participant(c, hand, *dev, pseed);
    const int trace = getenv("TRACE") ? atoi(getenv("TRACE")) : 0;
    int k = -1;
    for (const int setting_k : settings_list(getenv("SETTINGS"))) {
      ++k;
      if (k + 1 == trace) {
        auto tw = PegWorld::create(c, trial_layout(c, pseed, k), setting_from_number(setting_k), hand, *dev);
        if (!tw) return 1;
        PegWorld& w2 = **tw;
        const auto& L = trial_layout(c, pseed, k);
        pu.begin(0, Pose{Quat(Eigen::AngleAxisd(-0.3, Vec3::UnitX())), L.p_peg_start_in_world + Vec3(0.0, c.peg.length_m + 0.12, 0.25)});
        std::string last_phase;
        for (int t = 0; t < 120000; ++t) {
          const Percept pp = perceive(w2);
          const HandCommand cmd = pu.act(pp);
          w2.submit_hand(cmd.T_world_wrist, cmd.angles);
          const PegEvent ev = w2.step();
          const std::string ph(pu.phase_name());
          if (ph != last_phase) {
            std::printf("%7.3f %-8s s=%.3f ff=%.3f%s%s\n", 1e-9 * w2.now_ns(), ph.c_str(), pu.closure(), pu.feedforward_closure(),
                        ph == "release" ? " why " : "", ph == "release" ? std::string(pu.release_reason()).c_str() : "");
            last_phase = ph;
          }
          if (ev.kind != PegEvent::Kind::none) std::printf("%7.3f EVENT %d\n", 1e-9 * w2.now_ns(), static_cast<int>(ev.kind));
          if (getenv("EVERY") && t % atoi(getenv("EVERY")) == 0) {
            const auto& sn = w2.snapshot();
            const Vec3 ax = peg_axis(w2.peg_pose());
            std::printf("        %-7s s=%.3f grip %.2f tips T%.2f I%.2f M%.2f ax(%.2f %.2f %.2f) peg(%.3f %.3f %.3f)\n", ph.c_str(),
                        pu.closure(), w2.filtered_grasp_force_n(), sn.hands[0].contact[0].normal_n, sn.hands[0].contact[1].normal_n,
                        sn.hands[0].contact[2].normal_n, ax.x(), ax.y(), ax.z(), w2.peg_pose().p.x(), w2.peg_pose().p.y(),
                        w2.peg_pose().p.z());
          }
          if (ev.kind == PegEvent::Kind::inserted) break;
        }
        return 0;
      }
      SimulatedTrialOptions to;
      to.time_limit_s = 120;
      auto r = run_simulated_trial(c, trial_layout(c, pseed, k), setting_from_number(setting_k), pu, hand, *dev, to);
      if (!r) return 1;
      std::printf("trial %d (setting %d): %s %.1f s, %d breaks, %d drops; grip target %.2f, felt gain %.2f, feed-forward %.3f\n",
                  k + 1, setting_k, r->completed ? "inserted" : "timed out", r->completion_time_s, r->breaks, r->drops,
                  pu.grip_target_n(), pu.felt_gain(), pu.feedforward_closure());
    }
    return 0;
  }
  if (const char* pn = getenv("PAIRED")) {
    // PAIRED=N TRIALS=T SETS=1,2,3,4 PBASE=b: N participants (seeds b..b+N-1),
    // each familiarised once, then T trials in every setting, each setting
    // from a copy of the same familiarised user on the same layouts, so the
    // settings differ only by the setting.
    // TRACKER=ftm: each arm wears a fresh simulated FTM glove (the study's
    // glove seed for that participant). ABLATE=none,truth_wrist,...
    // (DIAGNOSTIC, FtmGloveAblation; "ideal" = no glove): every listed
    // variant is an arm of its own, per setting, from the same copy.
    // FAMFTM=1 familiarises through a glove too, as the study does.
    const int n = atoi(pn), trials = getenv("TRIALS") ? atoi(getenv("TRIALS")) : 5;
    const std::uint64_t base = getenv("PBASE") ? std::strtoull(getenv("PBASE"), nullptr, 10) : 100;
    const std::vector<int> sets = settings_list(getenv("SETS") ? getenv("SETS") : "1,2,3,4");
    const bool ftm = getenv("TRACKER") && std::string(getenv("TRACKER")) == "ftm";
    std::vector<std::string> variants = {"ideal"};
    if (ftm) variants = names_list(getenv("ABLATE") ? getenv("ABLATE") : "none");
    struct Arm {
      int setting;
      std::string variant;
      double sum_t = 0.0, sum_norm = 0.0, err_deg = 0.0, wrist_mm = 0.0, wrist_deg = 0.0;
      int breaks = 0, drops = 0, timeouts = 0, done = 0, runs = 0;
      std::map<std::string, int> tally;
    };
    std::vector<Arm> arms;
    for (int st : sets) {
      for (const std::string& v : variants) {
        if (v != "ideal" && !parse_ftm_glove_ablation(v)) {
          std::printf("%s\n", parse_ftm_glove_ablation(v).error().message.c_str());
          return 1;
        }
        Arm arm;
        arm.setting = st;
        arm.variant = v;
        arms.push_back(std::move(arm));
      }
    }
    const auto make_glove = [&](std::uint64_t pseed, FtmGloveAblation a) {
      SimulatedFtmGloveOptions go;
      go.seed = mix_seed(pseed, 0x46544d);  // as the study runner seeds it
      go.device_leads = c.ftm_device_leads;
      go.ablate = a;
      return SimulatedFtmGlove::create(*shape, go);
    };
    for (int i = 0; i < n; ++i) {
      const std::uint64_t pseed = base + static_cast<std::uint64_t>(i);
      std::unique_ptr<SimulatedFtmGlove> fam_glove;
      if (getenv("FAMFTM")) {
        auto g = make_glove(pseed, FtmGloveAblation::none);
        if (!g) { std::printf("%s\n", g.error().message.c_str()); return 1; }
        fam_glove = std::move(*g);
      }
      const SimulatedUser pu = familiarised_participant(c, hand, *dev, pseed, fam_glove.get());
      std::vector<double> mean_t(arms.size(), 0.0);
      for (std::size_t ai = 0; ai < arms.size(); ++ai) {
        Arm& arm = arms[ai];
        SimulatedUser u = pu;
        std::unique_ptr<SimulatedFtmGlove> glove;
        if (arm.variant != "ideal") {
          auto g = make_glove(pseed, *parse_ftm_glove_ablation(arm.variant));
          if (!g) { std::printf("%s\n", g.error().message.c_str()); return 1; }
          glove = std::move(*g);
          if (getenv("DESCRIBE")) std::printf("%s\n", glove->describe().c_str());
        }
        std::printf("p%llu S%d %-20s:", static_cast<unsigned long long>(pseed), arm.setting, arm.variant.c_str());
        for (int k = 0; k < trials; ++k) {
          SimulatedTrialOptions to;
          to.time_limit_s = 120;
          to.ftm_glove = glove.get();
          if (getenv("WHY")) {
            to.on_event = [&arm](PegEvent::Kind kind, std::string_view phase) {
              if (kind == PegEvent::Kind::broke) ++arm.tally["b:" + std::string(phase)];
              if (kind == PegEvent::Kind::dropped) ++arm.tally["d:" + std::string(phase)];
            };
          }
          auto r = run_simulated_trial(c, trial_layout(c, pseed, k), setting_from_number(arm.setting), u, hand, *dev, to);
          if (!r) { std::printf("%s\n", r.error().message.c_str()); return 1; }
          std::printf(" %5.1f/%db%dd", r->completion_time_s, r->breaks, r->drops);
          if (r->ftm) {
            const auto& rv = r->ftm->mean_wrist_rotation_error_in_wrist_deg;
            std::printf("(%.1f°,%.1fmm,%.1f°[%.0f %.0f %.0f])", r->ftm->mean_angle_error_deg, r->ftm->mean_wrist_error_mm,
                        r->ftm->mean_wrist_angle_error_deg, rv[0], rv[1], rv[2]);
            arm.err_deg += r->ftm->mean_angle_error_deg;
            arm.wrist_mm += r->ftm->mean_wrist_error_mm;
            arm.wrist_deg += r->ftm->mean_wrist_angle_error_deg;
          }
          std::fflush(stdout);
          mean_t[ai] += r->completion_time_s / trials;
          arm.drops += r->drops;
          arm.breaks += r->breaks;
          arm.timeouts += r->completed ? 0 : 1;
          arm.done += r->completed ? 1 : 0;
          ++arm.runs;
        }
        std::printf("  mean %.1f\n", mean_t[ai]);
        std::fflush(stdout);
      }
      double all = 0.0;
      for (double m : mean_t) all += m / static_cast<double>(arms.size());
      for (std::size_t ai = 0; ai < arms.size(); ++ai) {
        arms[ai].sum_t += mean_t[ai] / n;
        arms[ai].sum_norm += mean_t[ai] / all / n;
      }
    }
    for (const Arm& arm : arms) {
      std::printf("S%d %-20s: n %d, completed %d, mean %.1f s, normalised %.2f, breaks %d, drops %d, timeouts %d",
                  arm.setting, arm.variant.c_str(), arm.runs, arm.done, arm.sum_t, arm.sum_norm, arm.breaks, arm.drops,
                  arm.timeouts);
      if (arm.variant != "ideal" && arm.runs > 0) {
        std::printf(", tracker err %.1f°, wrist %.1f mm %.1f°", arm.err_deg / arm.runs, arm.wrist_mm / arm.runs,
                    arm.wrist_deg / arm.runs);
      }
      for (const auto& [k, v] : arm.tally) std::printf(" %s=%d", k.c_str(), v);
      std::printf("\n");
    }
    return 0;
  }
  if (const char* rep = getenv("REPEAT")) {  // REPEAT=N: N trials in a row, one participant
    for (int k = 0; k < atoi(rep); ++k) {
      SimulatedTrialOptions to;
      to.time_limit_s = limit;
      auto r = run_simulated_trial(c, trial_layout(c, layout_seed, trial + k), setting_from_number(setting), user, hand, *dev, to);
      if (!r) return 1;
      std::printf("trial %d: %s %.1f s, %d breaks, %d regrasps; grip target %.2f, felt gain %.2f, feed-forward %.3f\n",
                  trial + k, r->completed ? "inserted" : "timed out", r->completion_time_s, r->breaks, r->regrasps,
                  user.grip_target_n(), user.felt_gain(), user.feedforward_closure());
    }
    return 0;
  }
  auto layout = trial_layout(c, layout_seed, trial);
  const bool spring = getenv("SPRING") != nullptr;
  if (spring) layout = trial_layout(c, layout_seed, -1);
  user.set_grasp_only(spring);
  auto w = PegWorld::create(c, layout, setting_from_number(setting), hand, *dev, spring ? WorldPhase::spring : WorldPhase::trial);
  if (!w) { std::printf("%s\n", w.error().message.c_str()); return 1; }
  PegWorld& world = **w;
  const Quat q(Eigen::AngleAxisd(-0.3, Vec3::UnitX()));
  user.begin(0, Pose{q, layout.p_peg_start_in_world + Vec3(0.0, c.peg.length_m + 0.12, 0.25)});
  std::string last;
  for (int t = 0; t < limit * 1000; ++t) {
    const Percept p = perceive(world);
    const auto& s = world.snapshot();
    auto cmd = user.act(p);
    world.submit_hand(cmd.T_world_wrist, cmd.angles);
    auto ev = world.step();
    std::string ph(user.phase_name());
    if (ph == "release" && last != "release") std::printf("RELEASE %s at %.2f\n", std::string(user.release_reason()).c_str(), 1e-9 * world.now_ns());
    if (ph != last || t % (getenv("EVERY") ? atoi(getenv("EVERY")) : 250) == 0 || ev.kind != PegEvent::Kind::none) {
      const auto& pp = world.peg_pose();
      Vec3 ax = peg_axis(pp);
      auto ins = world.insertion();
      std::printf("%6.3f s=%.2f %-8s ev%d peg(%.3f %.3f %.3f) ax(%.2f %.2f %.2f) wrist(%.3f %.3f %.3f) tips T%.2f I%.2f M%.2f felt %.2f %.2f %.2f filt %.2f ins d=%.3f r=%.4f\n",
        1e-9*world.now_ns(), user.closure(), ph.c_str(), (int)ev.kind, pp.p.x(), pp.p.y(), pp.p.z(), ax.x(), ax.y(), ax.z(),
        cmd.T_world_wrist.p.x(), cmd.T_world_wrist.p.y(), cmd.T_world_wrist.p.z(),
        s.hands[0].contact[0].normal_n, s.hands[0].contact[1].normal_n, s.hands[0].contact[2].normal_n,
        p.felt_normal_n[0], p.felt_normal_n[1], p.felt_normal_n[2], world.filtered_grasp_force_n(), ins.depth_m, ins.radial_offset_m);
      last = ph;
      if (getenv("HF")) { Vec3 hf = world.servo().simulation().hand_force_on_object("peg"); std::printf("      hand->peg (%.2f %.2f %.2f) tip raw T%.2f I%.2f M%.2f cnt %d %d %d\n", hf.x(), hf.y(), hf.z(),
        world.servo().simulation().fingertip(Finger::thumb).raw.normal_n, world.servo().simulation().fingertip(Finger::index).raw.normal_n, world.servo().simulation().fingertip(Finger::middle).raw.normal_n,
        world.servo().simulation().fingertip(Finger::thumb).contact_count, world.servo().simulation().fingertip(Finger::index).contact_count, world.servo().simulation().fingertip(Finger::middle).contact_count); }
      if (getenv("WRIST")) { const Pose& pw = s.hands[0].proxy.joint(HandJoint::wrist); const Vec3 dp = pw.p - cmd.T_world_wrist.p;
        const double ang = 2.0 * std::acos(std::min(1.0, std::abs(pw.q.dot(cmd.T_world_wrist.q))));
        std::printf("      proxy wrist off (%.4f %.4f %.4f) m, %.2f deg\n", dp.x(), dp.y(), dp.z(), ang * 57.2958); }
      if (getenv("FW")) for (int f = 0; f < 3; ++f) { const auto& tip = world.servo().simulation().fingertip(static_cast<Finger>(f));
        std::printf("      f%d world(%.2f %.2f %.2f) raw n %.2f sx %.2f sz %.2f contact normal %.2f\n", f, tip.f_in_world.x(), tip.f_in_world.y(), tip.f_in_world.z(), tip.raw.normal_n, tip.raw.shear_x_n, tip.raw.shear_z_n, tip.contact_normal_n); }
      if (getenv("PADS")) for (int f = 0; f < 3; ++f) {
        const Pose& tip = s.hands[0].proxy.joint(tip_of(static_cast<Finger>(f)));
        Vec3 n = tip.q * Vec3(0, -1, 0); Vec3 d = pp.p - tip.p; d -= d.dot(ax) * ax; d.normalize();
        std::printf("      pad%d normal(%.2f %.2f %.2f) toward-axis dot %.2f\n", f, n.x(), n.y(), n.z(), n.dot(d));
      }
      if (getenv("TIPS")) for (int f = 0; f < 3; ++f) {
        Vec3 d = p.p_proxy_tip_in_world[f] - pp.p; Vec3 dr = d - d.dot(ax) * ax;
        std::printf("      tip%d rel(%.3f %.3f %.3f) radial %.4f axial %.4f\n", f, d.x(), d.y(), d.z(), dr.norm(), d.dot(ax));
      }
    }
    if (ev.kind == PegEvent::Kind::inserted) { std::printf("INSERTED at %.2f s\n", world.elapsed_s()); break; }
  }
}
