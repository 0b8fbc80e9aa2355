// proprio haptics sim|mjcf|devices|test and proprio bench haptics.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "proprio/core/data_dir.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/log.hpp"
#include "proprio/haptics/contact_sim.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/servo_loop.hpp"
#include "proprio/haptics/touch_script.hpp"
#include "svg_plot.hpp"

namespace proprio::cli {
namespace {

using namespace proprio::haptics;

struct SceneChoice {
  HapticScene scene;
  Vec3 p_touch_in_world;  // where the scripted index finger lands
  // How deep a fingertip sphere is inside the touched surface (< 0: above it).
  std::function<double(const Vec3&, double)> depth;
};

Result<SceneChoice> make_scene(const std::string& name) {
  if (name == "half-cylinder") {
    SceneChoice c{HapticScene::half_cylinder_study(), Vec3::Zero(), {}};
    const SceneObject& cyl = *c.scene.find("half_cylinder");
    c.p_touch_in_world = cyl.T_world_object.p + Vec3(0, cyl.radius_m, 0);
    const Pose T = cyl.T_world_object;
    const double R = cyl.radius_m;
    c.depth = [T, R](const Vec3& p, double r) {
      const Vec3 q = T.inverse() * p;
      return R + r - std::hypot(q.x(), q.y());
    };
    return c;
  }
  if (name == "peg-in-hole") {
    SceneChoice c{HapticScene::peg_in_hole(), Vec3::Zero(), {}};
    const SceneObject& peg = *c.scene.find("peg");
    c.p_touch_in_world = peg.T_world_object.p + Vec3(0, peg.half_length_m, 0);
    const double top = c.p_touch_in_world.y();
    c.depth = [top](const Vec3& p, double r) { return top - (p.y() - r); };
    return c;
  }
  if (name == "table") {
    SceneChoice c{HapticScene{}, Vec3(0, 1.0, -0.55), {}};
    c.scene.objects.push_back(
        SceneObject::box("table", Vec3(0.4, 0.02, 0.4), Pose{Quat::Identity(), Vec3(0, 0.98, -0.55)}));
    c.depth = [](const Vec3& p, double r) { return 1.0 - (p.y() - r); };
    return c;
  }
  return make_error(Errc::invalid_argument,
                    "unknown scene '" + name + "': choose half-cylinder, peg-in-hole or table");
}

HandModel cli_hand(double length_m, double width_m) {
  auto shape = HandShape::from_measurements(length_m, width_m);
  return HandModel(shape ? *shape : HandShape{});
}

// ---------------------------------------------------------------------------
// haptics sim

struct SimArgs {
  std::string scene = "half-cylinder";
  std::string device = data_path("haptics/band_2dof.toml");
  double seconds = 8.0;
  double press_depth_m = TouchScriptOptions{}.press_depth_m;
  double hand_length_m = 0.19, hand_width_m = 0.09;
  std::string plot, csv;
  bool json = false;
};

int run_sim(const SimArgs& a) {
  auto scene = make_scene(a.scene);
  if (!scene) return report_error(scene.error());
  auto device = load_device_model(a.device);
  if (!device) return report_error(device.error());
  std::shared_ptr<const FingertipDeviceModel> model(std::move(*device));
  // Refused outputs (an input file, a device) fail before the simulation runs.
  if (!a.csv.empty()) {
    if (auto st = check_output_path(a.csv, "CSV output"); !st) return report_error(st.error());
  }
  if (!a.plot.empty()) {
    if (auto st = check_output_path(a.plot, "plot"); !st) return report_error(st.error());
  }
  const HandModel hand = cli_hand(a.hand_length_m, a.hand_width_m);
  auto sim = ContactSimulation::create(hand, Handedness::right, scene->scene);
  if (!sim) return report_error(sim.error());
  TouchScriptOptions to;
  to.p_surface_in_world = scene->p_touch_in_world;
  to.press_depth_m = a.press_depth_m;
  const TouchScript script(sim->hand_model(), Handedness::right, to);
  Pose T;
  HandAngles angles;
  script.at(0.0, T, angles);
  sim->reset_hand(T, angles);

  auto emulated = EmulatedFingertip::create(model);
  if (!emulated) return report_error(emulated.error());
  std::shared_ptr<EmulatedFingertip> sink = std::move(*emulated);
  std::vector<ServoChannel> channels(1);
  channels[0].finger = Finger::index;
  channels[0].model = model;
  channels[0].sink = sink;
  ServoLoopOptions so;
  auto loop = ServoLoop::create(std::move(*sim), std::move(channels), so);
  if (!loop) return report_error(loop.error());
  ServoLoop& servo = **loop;
  std::printf("Scene %s; device %s\n%s\n", a.scene.c_str(), std::string(model->kind()).c_str(),
              servo.simulation().describe_model().c_str());

  // Simulated time at 1 kHz, as fast as the machine goes.
  const auto steps = static_cast<int>(a.seconds * 1000.0);
  // Legends stay short: the plot's legend column is 170 px wide.
  PlotSeries contact_f{"contact |F| (MuJoCo)", {}, {}}, tip_n{"F along pad normal", {}, {}};
  PlotSeries pad_n{"pad pressure (felt)", {}, {}}, cmd_f{"commanded |F|", {}, {}};
  PlotSeries meas_n{"device sensors, normal", {}, {}};
  PlotSeries tracked_depth{"tracked fingertip", {}, {}}, proxy_depth{"proxy (penetration)", {}, {}};
  std::ofstream csv;
  if (!a.csv.empty()) {
    csv.open(a.csv);
    if (!csv) return report_error(make_error(Errc::io_error, "cannot write " + a.csv));
    csv << "t_s,contact_force_n,contact_normal_sum_n,tip_frame_normal_n,tip_frame_shear_x_n,tip_frame_shear_z_n,"
           "pad_normal_n,pad_shear_x_n,pad_shear_z_n,commanded_normal_n,commanded_shear_x_n,commanded_shear_z_n,"
           "device_normal_n,tracked_depth_m,proxy_depth_m\n";
  }
  struct Peaks {
    double contact_force = 0, contact_normal_sum = 0, pad_normal = 0, pad_shear = 0;
    double commanded_force = 0, commanded_normal = 0, commanded_shear = 0, device_normal = 0;
    double tracked_depth = 0, proxy_depth = 0;
  } peak;
  const TimeNs t0 = kNsPerSecond;
  servo.engage(t0);
  const auto wall_start = std::chrono::steady_clock::now();
  for (int i = 0; i < steps; ++i) {
    const double t = i * 1e-3;
    const TimeNs now = t0 + static_cast<TimeNs>(i) * kNsPerMillisecond;
    script.at(t, T, angles);
    servo.submit_tracked_hand(now, T, angles);
    servo.tick(now);
    const ServoSnapshot* snap = servo.latest();
    constexpr auto kIndex = static_cast<std::size_t>(Finger::index);
    const FingertipForce c = snap->hands[0].contact[kIndex];
    const FingertipForce pad = snap->hands[0].on_pad[kIndex];
    const double contact_force = c.in_tip_frame().norm();
    const auto& ch = snap->channels[0];
    const double commanded_force = ch.commanded.in_tip_frame().norm();
    const HandPose tracked = hand.forward(Handedness::right, angles, T, now);
    const double r = tracked.radius_m[index_of(HandJoint::index_tip)];
    const double tracked_below = scene->depth(tracked.joint(HandJoint::index_tip).p, r);
    const double proxy_below = servo.simulation().fingertip(Finger::index).max_penetration_m;
    peak.contact_force = std::max(peak.contact_force, contact_force);
    peak.contact_normal_sum = std::max(peak.contact_normal_sum, snap->hands[0].contact_normal_n[kIndex]);
    peak.pad_normal = std::max(peak.pad_normal, pad.normal_n);
    peak.pad_shear = std::max(peak.pad_shear, pad.shear_magnitude_n());
    peak.commanded_force = std::max(peak.commanded_force, commanded_force);
    peak.commanded_normal = std::max(peak.commanded_normal, ch.commanded.normal_n);
    peak.commanded_shear = std::max(peak.commanded_shear, ch.commanded.shear_magnitude_n());
    peak.device_normal = std::max(peak.device_normal, ch.measured.normal_n);
    peak.tracked_depth = std::max(peak.tracked_depth, tracked_below);
    peak.proxy_depth = std::max(peak.proxy_depth, proxy_below);
    if (i % 5 == 0) {
      contact_f.x.push_back(t), contact_f.y.push_back(contact_force);
      tip_n.x.push_back(t), tip_n.y.push_back(c.normal_n);
      pad_n.x.push_back(t), pad_n.y.push_back(pad.normal_n);
      cmd_f.x.push_back(t), cmd_f.y.push_back(commanded_force);
      meas_n.x.push_back(t), meas_n.y.push_back(ch.measured.normal_n);
      tracked_depth.x.push_back(t), tracked_depth.y.push_back(tracked_below * 1e3);
      proxy_depth.x.push_back(t), proxy_depth.y.push_back(proxy_below * 1e3);
    }
    if (csv) {
      csv << t << ',' << contact_force << ',' << snap->hands[0].contact_normal_n[kIndex] << ',' << c.normal_n << ','
          << c.shear_x_n << ',' << c.shear_z_n << ',' << pad.normal_n << ',' << pad.shear_x_n << ',' << pad.shear_z_n
          << ',' << ch.commanded.normal_n << ',' << ch.commanded.shear_x_n << ',' << ch.commanded.shear_z_n << ','
          << ch.measured.normal_n << ',' << tracked_below << ',' << proxy_below << '\n';
    }
  }
  servo.disengage_and_zero(t0 + static_cast<TimeNs>(steps) * kNsPerMillisecond);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  if (csv && !csv.flush()) return report_error(make_error(Errc::io_error, "writing " + a.csv + " failed"));

  const DeviceLimits& limits = model->limits();
  if (!a.plot.empty()) {
    std::vector<PlotPanel> panels = {
        {"Index fingertip force", "N", {contact_f, tip_n, pad_n, cmd_f, meas_n}},
        {"Index fingertip depth inside the surface (the proxy stays on it)", "mm", {tracked_depth, proxy_depth}},
    };
    if (auto s = write_svg_plot(a.plot, "proprio haptics sim: " + a.scene + ", " + std::string(model->kind()), "time (s)",
                                panels);
        !s) {
      return report_error(s.error());
    }
  }
  const auto stats = servo.simulation().stats();
  if (a.json) {
    nlohmann::json j;
    j["scene"] = a.scene;
    j["device"] = model->kind();
    j["seconds"] = a.seconds;
    j["peak_contact_force_n"] = peak.contact_force;
    j["peak_contact_normal_sum_n"] = peak.contact_normal_sum;
    j["peak_pad_normal_n"] = peak.pad_normal;
    j["peak_pad_shear_n"] = peak.pad_shear;
    j["peak_commanded_force_n"] = peak.commanded_force;
    j["peak_commanded_normal_n"] = peak.commanded_normal;
    j["peak_commanded_shear_n"] = peak.commanded_shear;
    j["peak_device_normal_n"] = peak.device_normal;
    j["device_max_normal_n"] = limits.max_normal_n;
    j["device_max_shear_n"] = limits.max_shear_n;
    j["max_tracked_depth_m"] = peak.tracked_depth;
    j["max_proxy_depth_m"] = peak.proxy_depth;
    j["instability_resets"] = stats.instability_resets;
    j["wall_s"] = wall_s;
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf(
        "%.1f s simulated in %.2f s wall (%.1fx real time)\n"
        "Index fingertip, all contacts on its distal phalanx:\n"
        "  peak contact force %.2f N (magnitude of the net force; %.2f N summed along the contact normals)\n"
        "  felt on the pad (sent to the device before its limits): peak %.2f N pressure, %.2f N shear\n"
        "  peak commanded force %.2f N (%.2f N normal, %.2f N shear) after the safety gate; device limits %.2f N "
        "normal, %.2f N shear\n"
        "  device sensors: peak normal %.2f N\n"
        "  the tracked fingertip went %.1f mm into the surface, the proxy %.1f mm (contact softness)\n"
        "Device: %s\n",
        a.seconds, wall_s, a.seconds / std::max(wall_s, 1e-9), peak.contact_force, peak.contact_normal_sum,
        peak.pad_normal, peak.pad_shear, peak.commanded_force, peak.commanded_normal, peak.commanded_shear,
        limits.max_normal_n, limits.max_shear_n, peak.device_normal, peak.tracked_depth * 1e3,
        peak.proxy_depth * 1e3, sink->describe().c_str());
    if (!a.plot.empty()) std::printf("Plot: %s\n", a.plot.c_str());
  }
  if (stats.instability_resets != 0) {
    std::fprintf(stderr, "error: MuJoCo went unstable %llu times; the forces above include the resets\n",
                 static_cast<unsigned long long>(stats.instability_resets));
  }
  return stats.instability_resets == 0 ? 0 : 1;
}

// ---------------------------------------------------------------------------
// bench haptics

struct BenchArgs {
  double seconds = 5.0;
  bool json = false;
  bool realtime = true;
};

struct Quantiles {
  double p50 = 0, p99 = 0, max = 0;
};
Quantiles quantiles(std::vector<double> v) {
  Quantiles q;
  if (v.empty()) return q;
  std::sort(v.begin(), v.end());
  q.p50 = v[v.size() / 2];
  q.p99 = v[std::min(v.size() - 1, v.size() * 99 / 100)];
  q.max = v.back();
  return q;
}

int run_bench(const BenchArgs& a) {
  const HandModel hand = cli_hand(0.19, 0.09);
  auto scene = make_scene("peg-in-hole");
  auto device = load_device_model(data_path("haptics/platform_3dof.toml"));
  if (!device) return report_error(device.error());
  std::shared_ptr<const FingertipDeviceModel> model(std::move(*device));

  // 1. MuJoCo steps with the index finger pressing on the standing peg.
  auto sim = ContactSimulation::create(hand, Handedness::right, scene->scene);
  if (!sim) return report_error(sim.error());
  TouchScriptOptions to;
  to.p_surface_in_world = scene->p_touch_in_world;
  to.period_s = 1e9;  // hold the approach pose; lowered below
  const TouchScript script(sim->hand_model(), Handedness::right, to);
  Pose T;
  HandAngles angles;
  script.at(0.0, T, angles);
  sim->reset_hand(T, angles);
  T.p.y() -= to.approach_height_m + 0.01;
  sim->set_target(T, angles);
  for (int i = 0; i < 500; ++i) sim->step();
  std::vector<double> step_us;
  const int n = 5000;
  step_us.reserve(n);
  for (int i = 0; i < n; ++i) {
    const auto s = std::chrono::steady_clock::now();
    sim->step();
    step_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - s).count());
  }
  const Quantiles step = quantiles(step_us);
  const int contacts = sim->stats().last_contact_count;

  // 2. The servo loop on its own thread for `seconds`, three channels.
  std::vector<ServoChannel> channels;
  for (Finger f : {Finger::thumb, Finger::index, Finger::middle}) {
    ServoChannel c;
    c.finger = f;
    c.model = model;
    c.sink = std::make_shared<RecordingSink>();
    channels.push_back(std::move(c));
  }
  ServoLoopOptions so;
  so.realtime_priority = a.realtime;
  auto loop = ServoLoop::create(std::move(*sim), std::move(channels), so);
  if (!loop) return report_error(loop.error());
  if (auto s = (*loop)->start(); !s) return report_error(s.error());
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(a.seconds);
  while (std::chrono::steady_clock::now() < end) {
    (*loop)->submit_tracked_hand(MonotonicClock::instance().now_ns(), T, angles);
    std::this_thread::sleep_for(std::chrono::milliseconds(11));  // a 90 Hz tracker
  }
  (*loop)->stop();
  const ServoTiming timing = (*loop)->timing();
  const unsigned cores = std::thread::hardware_concurrency();

  // 3. Both hands in one world, thumb and index of each pinching the peg,
  //    six emulated devices (thumb, index, middle per hand). Ticked here on
  //    simulated time, one tick per millisecond: the hands close on the peg
  //    over 0.5 s and settle for 1 s, then each timed tick (the tick alone) is
  //    checked to leave the four pinching pads pressed.
  const HandModel both_hand = cli_hand(0.19, 0.10);
  const ProxyHandSpec two[] = {{both_hand, Handedness::left}, {both_hand, Handedness::right}};
  auto world = ContactSimulation::create(two, scene->scene);
  if (!world) return report_error(world.error());
  auto pinch = pinch_peg_with_both_hands(both_hand, scene->scene);
  if (!pinch) return report_error(pinch.error());
  for (std::size_t h = 0; h < 2; ++h) world->reset_hand((*pinch)[h].T_world_wrist_start, (*pinch)[h].open, h);
  std::vector<ServoChannel> six;
  for (std::size_t h = 0; h < 2; ++h) {
    for (Finger f : {Finger::thumb, Finger::index, Finger::middle}) {
      auto sink = EmulatedFingertip::create(model);
      if (!sink) return report_error(sink.error());
      six.push_back({f, model, std::shared_ptr<FingertipSink>(std::move(*sink)), h});
    }
  }
  ServoLoopOptions manual = so;
  manual.realtime_priority = false;
  auto both = ServoLoop::create(std::move(*world), std::move(six), manual);
  if (!both) return report_error(both.error());
  TimeNs now = MonotonicClock::instance().now_ns();
  (*both)->engage(now);
  const auto submit = [&](double closing) {
    for (std::size_t h = 0; h < 2; ++h) {
      const CylinderPinch& p = (*pinch)[h];
      HandAngles angles_h;
      for (std::size_t d = 0; d < kHandDofCount; ++d) angles_h[d] = p.open[d] + closing * (p.closed[d] - p.open[d]);
      const Pose T_h{p.T_world_wrist.q,
                     p.T_world_wrist_start.p + closing * (p.T_world_wrist.p - p.T_world_wrist_start.p)};
      (*both)->submit_tracked_hand(now, T_h, angles_h, h);
    }
  };
  for (int i = 0; i < 1500; ++i) {
    submit(std::min(1.0, i / 500.0));
    (*both)->tick(now += kNsPerMillisecond);
  }
  const int both_n = 5000;
  std::vector<double> both_us;
  both_us.reserve(both_n);
  const ContactSimulation& both_sim = (*both)->simulation();
  double least_pad_n = 1e9;
  int tips_without_contact = 0;
  for (int i = 0; i < both_n; ++i) {
    submit(1.0);  // the tracked hands, outside the timed tick
    now += kNsPerMillisecond;
    const auto t0 = std::chrono::steady_clock::now();
    (*both)->tick(now);
    both_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    for (std::size_t h = 0; h < 2; ++h) {
      for (Finger f : {Finger::thumb, Finger::index}) {
        const FingertipContact& c = both_sim.fingertip(f, h);
        least_pad_n = std::min(least_pad_n, c.on_pad.normal_n);
        tips_without_contact += c.contact_count == 0;
      }
    }
  }
  if (!(least_pad_n > 0.05)) {
    std::fprintf(stderr,
                 "proprio bench haptics: the two-hand case did not run as specified: a pinching fingertip (thumb "
                 "or index) left the peg (least pad force %.3f N over the timed ticks); no timing is reported "
                 "for it\n",
                 least_pad_n);
    return 1;
  }
  const Quantiles both_tick = quantiles(both_us);

  if (a.json) {
    nlohmann::json j;
    j["mujoco_step_us"] = {{"p50", step.p50}, {"p99", step.p99}, {"max", step.max}, {"contacts", contacts}};
    j["servo_tick_us"] = {{"p50", timing.tick_p50_us}, {"p99", timing.tick_p99_us}, {"max", timing.tick_max_us}};
    j["servo_jitter_us"] = {{"p50", timing.jitter_p50_us}, {"p99", timing.jitter_p99_us}, {"max", timing.jitter_max_us}};
    j["servo_ticks"] = timing.ticks;
    j["servo_overruns"] = timing.overruns;
    j["realtime_priority"] = timing.realtime;
    j["cores"] = cores;
    j["two_hands_servo_tick_us"] = {{"p50", both_tick.p50},
                                    {"p99", both_tick.p99},
                                    {"max", both_tick.max},
                                    {"devices", 6},
                                    {"fingertips_pressing_the_peg", 4},
                                    {"pinching", "thumb and index of each hand"},
                                    {"least_pad_force_n", least_pad_n},
                                    {"fingertip_ticks_without_a_contact", tips_without_contact},
                                    {"ticks", both_n}};
    j["targets"] = {{"mujoco_step_us", 250},
                    {"servo_tick_us", 400},
                    {"jitter_p99_us", 200},
                    {"two_hands_servo_tick_us", {{"p50", 150}, {"p99", 400}}}};
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf(
        "MuJoCo step, hand + peg-in-hole scene, index pressing the peg (%d contacts), %d steps:\n"
        "  p50 %.0f us, p99 %.0f us, max %.0f us (target <= 250 us)\n"
        "Servo loop, %.1f s on its own thread (%s), 3 devices (platform_3dof), %u cores:\n"
        "  tick p50 %.0f us, p99 %.0f us, max %.0f us (target <= 400 us)\n"
        "  wake-up jitter p50 %.0f us, p99 %.0f us, max %.0f us (target p99 <= 200 us on an idle machine)\n"
        "  %llu ticks, %llu overruns\n"
        "One servo tick, both hands in one world, thumb and index of each pinching the peg (4 of 4 pressed in\n"
        "every tick, least pad force %.2f N), 6 emulated devices (platform_3dof), %d ticks timed on this thread:\n"
        "  p50 %.0f us, p99 %.0f us, max %.0f us (target p50 <= 150 us, p99 <= 400 us)\n"
        "Percentiles of the servo loop come from 10 us bins (upper edges).\n",
        contacts, n, step.p50, step.p99, step.max, a.seconds,
        timing.realtime ? "SCHED_FIFO" : "normal priority: run as root or grant rtprio for less jitter", cores,
        timing.tick_p50_us, timing.tick_p99_us, timing.tick_max_us, timing.jitter_p50_us, timing.jitter_p99_us,
        timing.jitter_max_us, static_cast<unsigned long long>(timing.ticks),
        static_cast<unsigned long long>(timing.overruns), least_pad_n, both_n, both_tick.p50, both_tick.p99,
        both_tick.max);
  }
  return 0;
}

}  // namespace

void add_haptics_commands(CLI::App& app, int& exit_code) {
  auto* h = add_command(app, "haptics");

  auto sim_args = std::make_shared<SimArgs>();
  auto* s = h->add_subcommand(
      "sim",
      "Simulate a scripted index finger touching a scene (approach, press, slide, lift) through the proxy hand,\n"
      "the safety gate and an emulated fingertip device (motor dynamics), and report the forces.");
  s->add_option("--scene", sim_args->scene, "half-cylinder (the perception study's), peg-in-hole or table")
      ->capture_default_str();
  s->add_option("--device", sim_args->device, "device model TOML (config/haptics/*.toml)")->capture_default_str();
  s->add_option("--seconds", sim_args->seconds, "simulated seconds (one touch every 4 s)")
      ->check(CLI::Range(0.1, 600.0))
      ->capture_default_str();
  s->add_option("--press-depth", sim_args->press_depth_m, "how far below the surface the tracked fingertip goes (m)")
      ->check(CLI::Range(0.0, 0.1))
      ->capture_default_str();
  s->add_option("--plot", sim_args->plot, "write an SVG plot of forces and depths");
  s->add_option("--csv", sim_args->csv, "write every tick as CSV");
  s->add_flag("--json", sim_args->json, "print the summary as JSON");
  s->callback([sim_args, &exit_code] { exit_code = run_sim(*sim_args); });

  auto mjcf_scene = std::make_shared<std::string>("peg-in-hole");
  auto* m = h->add_subcommand("mjcf", "Print the MuJoCo model (proxy hand + scene) the simulation compiles");
  m->add_option("--scene", *mjcf_scene, "half-cylinder, peg-in-hole or table")->capture_default_str();
  m->callback([mjcf_scene, &exit_code] {
    auto scene = make_scene(*mjcf_scene);
    if (!scene) {
      exit_code = report_error(scene.error());
      return;
    }
    auto xml = generate_mjcf(cli_hand(0.19, 0.09), Handedness::right, scene->scene, ContactSimOptions{});
    if (!xml) {
      exit_code = report_error(xml.error());
      return;
    }
    std::fputs(xml->c_str(), stdout);
    exit_code = 0;
  });

  add_haptics_device_commands(*h, exit_code);

  auto bench_args = std::make_shared<BenchArgs>();
  auto* b = add_command(app, "bench haptics");
  b->add_option("--seconds", bench_args->seconds, "how long the servo loop runs")
      ->check(CLI::Range(0.5, 600.0))
      ->capture_default_str();
  b->add_flag("!--no-realtime", bench_args->realtime, "do not ask for SCHED_FIFO");
  b->add_flag("--json", bench_args->json, "print the figures as JSON");
  b->callback([bench_args, &exit_code] { exit_code = run_bench(*bench_args); });
}

}  // namespace proprio::cli
