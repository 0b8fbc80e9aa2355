// proprio rig example|plan|emulate|live: the modular rig device (issue 31,
// docs/rig-device.md). `rig plan` picks where a kit's joints and splitters go
// on a glTF character and writes the plan, assembly instructions and
// pictures; `rig emulate` runs a plan's device on the emulated bus (faults
// included) and prints what the host sees; `rig live` poses the character
// from the device (emulated or on USB) in the engine, recorded if asked.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/render/character.hpp"
#include "proprio/rig_characters/examples.hpp"
#include "proprio/rig_device/kit.hpp"
#include "proprio/rig_live/rig_live.hpp"
#include "proprio/rig_plan/assembly.hpp"
#include "proprio/rig_plan/joint_ranges.hpp"
#include "proprio/rig_plan/plan_io.hpp"
#include "proprio/rig_plan/rig_reduction.hpp"
#include "rig_common.hpp"
#include "run_args.hpp"
#include "svg_plot.hpp"

namespace proprio::cli {
// Named, not anonymous: the CLI is a unity build.
namespace rig_cmd {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------
// rig example

struct ExampleArgs {
  std::string name;
  std::string out;
  bool force = false;
};

int run_example(const ExampleArgs& a) {
  auto c = rig_characters::make_example_character(a.name);
  if (!c) return report_error(c.error());
  if (!a.force && fs::exists(a.out))
    return report_error(make_error(Errc::invalid_argument, a.out + " exists; pass --force to replace it"));
  if (auto st = check_output_path(a.out, "the character file"); !st) return report_error(st.error());
  if (auto st = render::save_character_gltf(*c, a.out); !st) return report_error(st.error());
  std::printf("%s: %zu bones, %zu sample poses, %zu vertices -> %s\n", c->name.c_str(), c->skeleton.size(),
              c->sample_poses.size(), c->mesh.vertices.size(), a.out.c_str());
  return 0;
}

// ---------------------------------------------------------------------------
// rig plan

struct PlanArgs {
  std::string character;
  std::string out;
  std::string kit;
  int joints = -1;
  bool no_splitters = false;
  bool exact_rest = false;
  bool force = false;
};

int run_plan(const PlanArgs& a) {
  auto loaded = load_rig_character(a.character);
  if (!loaded) return report_error(loaded.error());
  const rig_plan::RigInput& input = loaded->input;
  rig_device::Kit kit = rig_device::default_kit();
  if (!a.kit.empty()) {
    auto k = rig_device::load_kit(a.kit);
    if (!k) return report_error(k.error());
    kit = std::move(*k);
  }
  const fs::path out(a.out);
  const char* names[] = {"plan.json", "assembly.txt", "assembly.svg", "error_curve.svg"};
  if (fs::exists(out) && !fs::is_directory(out))
    return report_error(make_error(Errc::invalid_argument, a.out + " is not a folder"));
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) return report_error(make_error(Errc::io_error, "cannot create " + a.out + ": " + ec.message()));
  auto lock = FolderLock::acquire(out, "the plan folder");
  if (!lock) return report_error(lock.error());
  if (!a.force) {
    for (const char* n : names)
      if (fs::exists(out / n))
        return report_error(make_error(Errc::invalid_argument, (out / n).string() +
                                                                   " exists; pass --force to replace the plan"));
  }
  rig_plan::ReductionOptions ro;
  ro.max_joints = a.joints;
  ro.use_splitters = !a.no_splitters;
  ro.center_joint_ranges = !a.exact_rest;
  if (auto st = ro.validate(); !st) return report_error(st.error());
  std::printf("%s: %zu bones, %zu sample poses\n%s\n%s\n", input.name.c_str(), input.skeleton.size(),
              input.samples.size(), kit.describe().c_str(), ro.describe().c_str());
  std::fflush(stdout);
  const auto t0 = std::chrono::steady_clock::now();
  std::string last_phase;
  auto plan = rig_plan::reduce_rig(input, kit, ro, [&](const rig_plan::ReductionProgress& p) {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::fprintf(stderr, "  [%5.1f s] pass %d, %s: %d of %d joints placed, pose error %.4g\n", s, p.iteration,
                 p.phase.c_str(), p.joints_placed, p.joints_available, p.error);
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!plan) return report_error(plan.error());
  plan->character = input.name;

  if (auto st = rig_plan::save_plan(out / "plan.json", *plan, input.skeleton.size()); !st) return report_error(st.error());
  auto text = rig_plan::assembly_text(input, *plan);
  if (!text) return report_error(text.error());
  if (auto st = write_file_atomic(out / "assembly.txt", *text, "the assembly instructions"); !st)
    return report_error(st.error());
  auto svg = rig_plan::assembly_svg(input, *plan);
  if (!svg) return report_error(svg.error());
  if (auto st = write_file_atomic(out / "assembly.svg", *svg, "the assembly picture"); !st) return report_error(st.error());

  // Fig. 3.7: the pose error against the number of joints the greedy phase placed.
  PlotPanel panel{"pose error (eq. 3.1) as the greedy phase adds joints", "% of the rigid error", {}};
  PlotSeries curve{"first joint pass", {0.0}, {100.0}};
  for (std::size_t j = 0; j < plan->error_after_joint.size(); ++j) {
    curve.x.push_back(static_cast<double>(j + 1));
    curve.y.push_back(plan->error_rigid > 0 ? 100.0 * plan->error_after_joint[j] / plan->error_rigid : 0.0);
  }
  panel.series.push_back(curve);
  if (auto st = write_svg_plot(out / "error_curve.svg", input.name + ": pose error against joints", "joints", {panel});
      !st)
    return report_error(st.error());

  std::printf("%s\n", text->c_str());
  auto reduction_at = [&](std::size_t joints) -> std::string {
    if (plan->error_rigid <= 0) return "n/a (the samples do not move the rig)";
    if (plan->error_after_joint.size() < joints) return "n/a (fewer joints placed)";
    return fmt::format("{:.1f} %", 100.0 * (1.0 - plan->error_after_joint[joints - 1] / plan->error_rigid));
  };
  std::printf("pose error: rigid %.4g; error reduction with 5 joints %s, with 10 joints %s; final device (%d joints, "
              "%d splitters) %.4g (%.1f %% less than rigid)\n",
              plan->error_rigid, reduction_at(5).c_str(), reduction_at(10).c_str(), plan->joint_count(),
              plan->splitter_count(), plan->error_final,
              plan->error_rigid > 0 ? 100.0 * (1.0 - plan->error_final / plan->error_rigid) : 0.0);
  const auto ranges = rig_plan::joint_range_report(*plan);
  if (ranges.joints_past_stop > 0)
    std::printf("joints that cannot reach every sample pose (their bones follow as far as the stop allows):\n%s",
                ranges.describe(*plan, &input.skeleton).c_str());
  else
    std::printf("every joint reaches every sample pose within its %.0f deg stop\n", ranges.limit_rad * 180.0 / M_PI);
  std::printf("planned in %.2f s\nwrote %s/{plan.json, assembly.txt, assembly.svg, error_curve.svg}\n", seconds,
              a.out.c_str());
  return 0;
}

// ---------------------------------------------------------------------------
// rig emulate / rig live: shared bus fault flags.

struct FaultArgs {
  double loss = 0.01;
  double corrupt = 0.001;
  double power_loss_every_s = 10.0;
  double skew_ppm = 50.0;
  bool exact_angles = false;
  std::uint64_t seed = 1;
  double seconds_per_pose = 3.0;

  void add(CLI::App* cmd) {
    cmd->add_option("--loss", loss, "emulated bus: probability that a message is lost on each hop")
        ->check(CLI::Range(0.0, 0.5))
        ->capture_default_str();
    cmd->add_option("--corrupt", corrupt, "emulated bus: probability that a message is corrupted on each hop")
        ->check(CLI::Range(0.0, 0.5))
        ->capture_default_str();
    cmd->add_option("--power-loss-every", power_loss_every_s,
                    "emulated bus: seconds between link power losses (a random link; 0: none)")
        ->check(CLI::Range(0.0, 3600.0))
        ->capture_default_str();
    cmd->add_option("--skew-ppm", skew_ppm, "emulated bus: components' clocks run off by up to this")
        ->check(CLI::Range(0.0, 10000.0))
        ->capture_default_str();
    cmd->add_flag("--exact-angles", exact_angles, "emulated joints send the animator's angles (no Hall-sensor model)");
    cmd->add_option("--seconds-per-pose", seconds_per_pose, "the scripted animator's pace through the sample poses")
        ->check(CLI::Range(0.2, 600.0))
        ->capture_default_str();
    cmd->add_option("--seed", seed, "the emulated device's and bus's seed")->capture_default_str();
  }

  rig_live::RigLiveOptions live_options() const {
    rig_live::RigLiveOptions o;
    o.faults.loss_probability = loss;
    o.faults.corrupt_probability = corrupt;
    o.faults.clock_skew_max_ppm = skew_ppm;
    o.faults.power_loss_interval_ns = static_cast<DurationNs>(power_loss_every_s * 1e9);
    o.emulated.hall_sensors = !exact_angles;
    o.emulated.seed = seed;
    o.emulated.animator.seconds_per_pose = seconds_per_pose;
    o.bus_seed = seed;
    return o;
  }
};

struct EmulateArgs {
  std::string plan, character;
  double seconds = 10.0;
  FaultArgs faults;
};

// One line per attached component, indented by depth.
std::string topology_lines(const rig_bus::BusSnapshot& s, const std::map<std::uint32_t, std::string>& names) {
  std::map<std::uint32_t, std::vector<const rig_bus::BusComponentView*>> kids;
  for (const auto& c : s.components)
    if (c.attached && c.id != s.base_id) kids[c.parent_id].push_back(&c);
  std::string out;
  std::function<void(std::uint32_t, int)> walk = [&](std::uint32_t id, int depth) {
    auto it = kids.find(id);
    if (it == kids.end() || depth > 64) return;
    auto list = it->second;
    std::sort(list.begin(), list.end(), [](auto* x, auto* y) { return x->parent_outlet < y->parent_outlet; });
    for (const auto* c : list) {
      const auto n = names.find(c->id);
      out += fmt::format("{:{}}outlet {}: {} {:08x}{}", "", 2 * depth, static_cast<int>(c->parent_outlet),
                         c->type_known ? printable(c->kind_name, 16) : "?", c->id,
                         n != names.end() ? " = " + n->second : std::string(" (not in the plan)"));
      if (c->have_angles)
        out += fmt::format("  twist {:+6.1f} bend {:+6.1f} {:+6.1f} twist {:+6.1f} deg ({:.0f} ms old)",
                           c->angles.twist_in_rad * 180 / M_PI, c->angles.bend_x_rad * 180 / M_PI,
                           c->angles.bend_y_rad * 180 / M_PI, c->angles.twist_out_rad * 180 / M_PI,
                           static_cast<double>(c->angles_age_ns) * 1e-6);
      out += "\n";
      walk(c->id, depth + 1);
    }
  };
  out += fmt::format("base {:08x}\n", s.base_id);
  walk(s.base_id, 1);
  return out;
}

int run_emulate(const EmulateArgs& a) {
  auto loaded = load_rig_character(a.character);
  if (!loaded) return report_error(loaded.error());
  auto plan = rig_plan::load_plan(a.plan, loaded->input.skeleton.size());
  if (!plan) return report_error(plan.error());
  if (auto st = check_plan_matches(*plan, loaded->input); !st) return report_error(st.error());
  rig_live::RigLiveOptions lo = a.faults.live_options();
  auto tree = rig_live::bus_tree_for_plan(*plan, lo.emulated.seed);
  if (!tree) return report_error(tree.error());
  auto device = rig_live::EmulatedPlanDevice::create(*plan, *tree, lo.emulated);
  if (!device) return report_error(device.error());
  rig_bus::BusEmulatorOptions eo;
  eo.seed = lo.bus_seed;
  eo.faults = lo.faults;
  auto link = rig_live::EmulatedBusLink::create(tree->tree, eo, rig_live::angles_callback(*device));
  if (!link) return report_error(link.error());
  std::map<std::uint32_t, std::string> names;
  for (std::size_t m = 0; m < plan->modules.size(); ++m)
    names[tree->module_id[m]] = rig_plan::module_label(*plan, static_cast<int>(m));
  std::printf("%s\n%s\n%s\n", lo.describe().c_str(), eo.describe().c_str(),
              "the host reads the base through the real driver on the fake USB cable; it never sees the truth");
  std::signal(SIGINT, on_sigint_stop);
  if (auto st = (*link)->start(); !st) return report_error(st.error());
  const auto t0 = std::chrono::steady_clock::now();
  std::set<rig_bus::BusTopologyTracker::Edge> last_host;
  int mismatched_checks = 0, checks = 0;
  std::size_t events_shown = 0;
  for (int tick = 1; !g_sigint_stop.load(); ++tick) {
    std::this_thread::sleep_until(t0 + std::chrono::milliseconds(500 * tick));
    const double t = 0.5 * tick;
    const auto snap = (*link)->device().snapshot();
    const auto events = (*link)->truth_events();
    for (; events_shown < events.size(); ++events_shown) {
      const auto& e = events[events_shown];
      const auto n = names.find(e.component_id);
      std::printf("[%5.1f s] truth: %s at %08x%s%s\n", static_cast<double>(e.at_ns) * 1e-9,
                  e.kind == rig_bus::BusTruthEventKind::power_loss ? "link power lost"
                  : e.kind == rig_bus::BusTruthEventKind::unplug   ? "unplugged"
                  : e.kind == rig_bus::BusTruthEventKind::plug     ? "plugged in"
                                                                   : "re-parented",
                  e.component_id, n != names.end() ? (" (" + n->second + ")").c_str() : "",
                  e.duration_ns > 0 ? fmt::format(" for {:.0f} ms", static_cast<double>(e.duration_ns) * 1e-6).c_str()
                                    : "");
    }
    std::set<rig_bus::BusTopologyTracker::Edge> host;
    for (const auto& c : snap.components)
      if (c.attached) host.insert({c.id, c.id == snap.base_id ? 0u : c.parent_id, c.id == snap.base_id ? rig_bus::kNoOutlet : c.parent_outlet});
    if (host != last_host) {
      std::printf("[%5.1f s] host: %zu components attached\n%s", t, snap.attached, topology_lines(snap, names).c_str());
      last_host = host;
    }
    // Is the host's table the truth (after the first 2 s of start-up)?
    if (t >= 2.0) {
      const auto truth = (*link)->truth_edges();
      ++checks;
      if (std::set<rig_bus::BusTopologyTracker::Edge>(truth.begin(), truth.end()) != host) ++mismatched_checks;
    }
    std::fflush(stdout);
    if (a.seconds > 0 && t >= a.seconds) break;
  }
  const auto es = (*link)->emulator_stats();
  const auto ds = (*link)->device().stats();
  (*link)->stop();
  std::printf("emulator: %llu messages made, %llu hops, %llu lost, %llu corrupted (%llu caught by CRC), %llu power "
              "losses, %llu boots, %llu reports to the host\n",
              static_cast<unsigned long long>(es.created[1] + es.created[2] + es.created[3]),
              static_cast<unsigned long long>(es.hops), static_cast<unsigned long long>(es.lost),
              static_cast<unsigned long long>(es.corrupted), static_cast<unsigned long long>(es.crc_dropped),
              static_cast<unsigned long long>(es.power_losses), static_cast<unsigned long long>(es.boots),
              static_cast<unsigned long long>(es.reports_sent));
  std::printf("host: %llu reports (%llu not decoded), %llu messages, %llu detaches, %llu attaches, %llu re-parents\n",
              static_cast<unsigned long long>(ds.host.reports), static_cast<unsigned long long>(ds.host.decode_errors),
              static_cast<unsigned long long>(ds.host.messages), static_cast<unsigned long long>(ds.host.tracker.detaches),
              static_cast<unsigned long long>(ds.host.tracker.attaches),
              static_cast<unsigned long long>(ds.host.tracker.parent_changes));
  std::printf("the host's topology matched the truth at %d of %d half-second checks after start-up\n",
              checks - mismatched_checks, checks);
  if (ds.host.reports == 0) return report_error(make_error(Errc::unavailable, "no report reached the host"));
  return 0;
}

// ---------------------------------------------------------------------------
// rig live

struct LiveArgs {
  std::string plan, character;
  std::string device = "emulate";
  std::string hid_path;
  double seconds = -1.0;
  std::string record;
  bool no_pose_space = false;
  bool no_truth = false;
  FaultArgs faults;
  RunArgs run;
};

// Rotation vectors of a pose's local rotations, 3 per node (a recording's joint_angles stream).
void pose_angles(const SkeletonPose& pose, std::vector<double>& out) {
  out.clear();
  for (const auto& q : pose.q_parent_node) {
    const Vec3 r = so3_log(q);
    out.insert(out.end(), {r.x(), r.y(), r.z()});
  }
}

int run_live(LiveArgs d) {
  RunArgs& a = d.run;
  a.mono = true;
  if (!a.xr && !a.window) a.headless = true;
  if (d.seconds < 0.0) d.seconds = a.headless ? 10.0 : 0.0;
  if (a.headless) a.frames = std::max(1, static_cast<int>(std::lround(d.seconds * a.fps)));
  auto options = app_options_from(a);
  if (!options) return report_error(options.error());

  auto loaded = load_rig_character(d.character);
  if (!loaded) return report_error(loaded.error());
  const render::Character& character = loaded->character;
  auto plan = rig_plan::load_plan(d.plan, loaded->input.skeleton.size());
  if (!plan) return report_error(plan.error());
  if (auto st = check_plan_matches(*plan, loaded->input); !st) return report_error(st.error());

  rig_live::RigLiveOptions lo = d.faults.live_options();
  lo.device = d.device;
  lo.hid_path = d.hid_path;
  lo.retarget.pose_space = !d.no_pose_space;
  auto source = rig_live::RigLiveSource::create(loaded->input, *plan, lo);
  if (!source) return report_error(source.error());
  rig_live::RigLiveSource& live = **source;
  std::printf("%s\n", lo.describe().c_str());

  // The recording: the device's joints (per plan joint: live flag and four
  // angles), the rig pose (and the truth when emulated), events.
  std::optional<RecordingWriter> writer;
  StreamId joints_stream = 0, pose_stream = 0, truth_stream = 0, events_stream = 0;
  if (!d.record.empty()) {
    if (fs::exists(d.record))
      return report_error(make_error(Errc::invalid_argument, d.record + " exists; choose another --record file"));
    RecordingWriterOptions wo;
    auto w = RecordingWriter::create(d.record, wo);
    if (!w) return report_error(w.error());
    writer.emplace(std::move(*w));
    std::string node_names;
    for (const auto& n : loaded->input.skeleton.names) node_names += (node_names.empty() ? "\"" : ", \"") + n + "\"";
    std::string joint_nodes;
    for (const auto& m : plan->modules)
      if (m.type == rig_plan::DeviceModule::Type::joint)
        joint_nodes += (joint_nodes.empty() ? "\"" : ", \"") + loaded->input.skeleton.names[m.rig_node] + "\"";
    auto j = writer->add_stream(StreamKind::joint_angles, "rig/device_joints",
                                "{\"layout\": \"per plan joint: live (1) or missing (0), twist_in, bend_x, bend_y, "
                                "twist_out (rad)\", \"joints_drive\": [" + joint_nodes + "]}");
    auto p = writer->add_stream(StreamKind::joint_angles, "rig/pose",
                                "{\"layout\": \"per node: its local rotation as a rotation vector (rad)\", "
                                "\"nodes\": [" + node_names + "]}");
    auto e = writer->add_stream(StreamKind::event, "events", "{\"tool\": \"proprio rig live\"}");
    if (!j || !p || !e) return report_error((!j ? j.error() : !p ? p.error() : e.error()));
    joints_stream = *j;
    pose_stream = *p;
    events_stream = *e;
    if (d.device == "emulate") {
      auto t = writer->add_stream(StreamKind::joint_angles, "rig/truth",
                                  "{\"layout\": \"as rig/pose: the scripted animator's pose (emulated device)\"}");
      if (!t) return report_error(t.error());
      truth_stream = *t;
    }
  }

  auto scene = engine::Scene::preset("empty");
  if (!scene) return report_error(scene.error());
  engine::AppInputs in;
  std::vector<std::uint32_t> triangles(character.mesh.indices.begin(), character.mesh.indices.end());
  const std::size_t nv = character.mesh.vertices.size();
  in.surfaces.push_back({character.name + " (device)", triangles, nv, {0.9f, 0.55f, 0.25f, 1.0f}});
  const bool show_truth = d.device == "emulate" && !d.no_truth;
  if (show_truth) in.surfaces.push_back({character.name + " (animator's truth)", triangles, nv, {0.45f, 0.6f, 0.8f, 1.0f}});

  // The character stands in front of the viewer, its width or height at rest
  // (whichever is larger; depth does not show) scaled to 0.7 m, its feet on
  // a common floor.
  Eigen::Vector3d lo_m = Eigen::Vector3d::Constant(1e30), hi_m = Eigen::Vector3d::Constant(-1e30);
  for (const auto& v : character.mesh.vertices) {
    const Eigen::Vector3d p(v.position.x, v.position.y, v.position.z);
    lo_m = lo_m.cwiseMin(p);
    hi_m = hi_m.cwiseMax(p);
  }
  const double scale = 0.7 / std::max({0.05, hi_m.x() - lo_m.x(), hi_m.y() - lo_m.y()});
  const Vec3 p_stage_char(-0.5 * (lo_m.x() + hi_m.x()), -lo_m.y(), -0.5 * (lo_m.z() + hi_m.z()));
  const double side_gap_m = 0.55 * scale * (hi_m.x() - lo_m.x()) + 0.05;
  std::optional<Pose> T_world_stage;
  std::vector<Pose> T_world_node;
  std::vector<glm::mat4> skin;
  std::vector<render::Vertex> skinned;
  rig_live::RigLiveFrame frame;
  std::vector<double> node_error_mm, age_ms, live_fraction;
  std::string last_problems = "(start)";
  std::vector<double> angles_out;
  const auto wall_start = std::chrono::steady_clock::now();
  Status failure;
  in.on_frame = [&](engine::FrameContext& c) {
    if (options->output == engine::OutputMode::headless)
      std::this_thread::sleep_until(wall_start + std::chrono::duration<double>(c.frame / options->frame_rate_hz));
    const double t_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    c.show_hands = false;
    c.show_scene = false;
    if (d.seconds > 0.0 && t_s >= d.seconds) c.stop = true;
    if (auto st = live.update(frame); !st) {
      failure = st;
      c.stop = true;
      return;
    }
    if (!T_world_stage) T_world_stage = c.T_world_head * Pose{Quat::Identity(), Vec3(0.0, -0.38, -0.9)};
    auto place = [&](const SkeletonPose& pose, double side, std::vector<Vec3>& out) {
      forward_kinematics(character.skeleton, pose, T_world_node);
      render::skin_character(character, T_world_node, skin, skinned);
      out.resize(skinned.size());
      const Vec3 offset(side * side_gap_m, 0.0, 0.0);
      for (std::size_t i = 0; i < skinned.size(); ++i) {
        const Vec3 p(skinned[i].position.x, skinned[i].position.y, skinned[i].position.z);
        out[i] = *T_world_stage * (offset + scale * (p + p_stage_char));
      }
    };
    c.surfaces.resize(show_truth ? 2 : 1);
    place(frame.pose, show_truth ? -1.0 : 0.0, c.surfaces[0]);
    double err_mm = std::nan("");
    if (frame.truth) {
      if (show_truth) place(*frame.truth, 1.0, c.surfaces[1]);
      // Node position error against the truth, in the character's own metres.
      std::vector<Pose> T_live, T_true;
      forward_kinematics(character.skeleton, frame.pose, T_live);
      forward_kinematics(character.skeleton, *frame.truth, T_true);
      double sum = 0.0;
      for (std::size_t i = 0; i < T_live.size(); ++i) sum += (T_live[i].p - T_true[i].p).norm();
      err_mm = 1e3 * sum / static_cast<double>(T_live.size());
      if (frame.joints_live > 0) node_error_mm.push_back(err_mm);
    }
    if (std::isfinite(frame.newest_reading_age_ms)) age_ms.push_back(frame.newest_reading_age_ms);
    live_fraction.push_back(frame.joints_planned > 0 ? static_cast<double>(frame.joints_live) / frame.joints_planned : 0);
    c.prompt = frame.joints_live == 0
                   ? fmt::format("waiting for the device: {} components on the bus", frame.components_attached)
                   : fmt::format("{}/{} joints live{}", frame.joints_live, frame.joints_planned,
                                 std::isfinite(err_mm) ? fmt::format("  node error {:.0f} mm", err_mm) : "");
    if (frame.binding_problems != last_problems) {
      last_problems = frame.binding_problems;
      const std::string text = last_problems.empty() ? "the device matches the plan" : "device differs from the plan: " + last_problems;
      std::printf("[%5.1f s] %s\n", t_s, text.c_str());
      if (writer) (void)writer->write(events_stream, Event{text}, frame.time_ns);
    }
    if (writer) {
      JointAngles ja;
      for (std::size_t m = 0; m < plan->modules.size(); ++m) {
        if (plan->modules[m].type != rig_plan::DeviceModule::Type::joint) continue;
        if (frame.q_in_out[m]) {
          const auto ang = rig_device::joint_angles_for(*frame.q_in_out[m], 0.0);
          ja.angles_rad.insert(ja.angles_rad.end(), {1.0, ang.twist_in_rad, ang.bend_x_rad, ang.bend_y_rad, ang.twist_out_rad});
        } else {
          ja.angles_rad.insert(ja.angles_rad.end(), {0.0, 0.0, 0.0, 0.0, 0.0});
        }
      }
      Status st = writer->write(joints_stream, ja, frame.time_ns);
      pose_angles(frame.pose, ja.angles_rad);
      if (st) st = writer->write(pose_stream, ja, frame.time_ns);
      if (st && frame.truth && truth_stream) {
        pose_angles(*frame.truth, ja.angles_rad);
        st = writer->write(truth_stream, ja, frame.time_ns);
      }
      if (!st) {
        failure = st;
        c.stop = true;
      }
    }
  };

  auto app = engine::App::create(std::move(*scene), std::move(in), *options);
  if (!app) return report_error(app.error());
  if (auto st = live.start(); !st) return report_error(st.error());
  auto report = run_app_until_done(**app);
  live.stop();
  if (writer) {
    if (auto st = writer->close(); !st && failure) failure = st;
  }
  if (!report) return report_error(report.error());
  if (!failure) return report_error(failure.error());
  std::printf("%s\n", report->describe().c_str());
  auto summary = [](std::vector<double> v, const char* what, const char* unit) {
    if (v.empty()) {
      std::printf("  %s: no frame had one\n", what);
      return;
    }
    std::sort(v.begin(), v.end());
    double sum = 0.0;
    for (double x : v) sum += x;
    std::printf("  %s over %zu frames: mean %.2f %s, median %.2f, p95 %.2f, max %.2f\n", what, v.size(),
                sum / static_cast<double>(v.size()), unit, v[v.size() / 2],
                v[std::min(v.size() - 1, v.size() * 95 / 100)], v.back());
  };
  summary(age_ms, "age of the newest joint reading at the frame", "ms");
  summary(live_fraction, "fraction of the plan's joints live", "");
  if (d.device == "emulate") summary(node_error_mm, "mean node position error against the animator (latency included)", "mm");
  const auto ds = live.device_stats();
  std::printf("  bus: %llu reports, %llu messages, %llu detaches, %llu attaches\n",
              static_cast<unsigned long long>(ds.host.reports), static_cast<unsigned long long>(ds.host.messages),
              static_cast<unsigned long long>(ds.host.tracker.detaches),
              static_cast<unsigned long long>(ds.host.tracker.attaches));
  if (auto es = live.emulator_stats())
    std::printf("  emulated bus: %llu messages lost, %llu corrupted, %llu link power losses\n",
                static_cast<unsigned long long>(es->lost), static_cast<unsigned long long>(es->corrupted),
                static_cast<unsigned long long>(es->power_losses));
  if (!report->images.empty())
    std::printf("Frames written to %s/ (frame_0000.png ... frame_%04d.png): the character posed by the device "
                "(orange)%s\n",
                a.out.c_str(), report->frames - 1, show_truth ? ", the animator's truth (blue) right" : "");
  if (writer) std::printf("recorded to %s\n", d.record.c_str());
  const bool any_live = std::any_of(live_fraction.begin(), live_fraction.end(), [](double f) { return f > 0; });
  if (!any_live)
    return report_error(make_error(Errc::unavailable, "no joint of the plan was ever live: is the device plugged in "
                                                      "and assembled as the plan says?"));
  return 0;
}

}  // namespace rig_cmd

void add_rig_commands(CLI::App& app, int& exit_code) {
  using namespace rig_cmd;
  {
    auto a = std::make_shared<ExampleArgs>();
    CLI::App* cmd = add_command(app, "rig example");
    cmd->add_option("name", a->name, "humanoid, quadruped or creature")
        ->required()
        ->check(CLI::IsMember(rig_characters::example_character_names()));
    cmd->add_option("--out", a->out, "the glTF file to write (.gltf)")->required();
    cmd->add_flag("--force", a->force, "replace an existing file");
    cmd->callback([a, &exit_code] { exit_code = run_example(*a); });
  }
  {
    auto a = std::make_shared<PlanArgs>();
    CLI::App* cmd = add_command(app, "rig plan");
    cmd->add_option("character", a->character, "a skinned glTF character with sample poses as animation keyframes "
                                               "(or example:NAME)")
        ->required();
    cmd->add_option("--out", a->out, "the folder for plan.json, assembly.txt, assembly.svg, error_curve.svg")
        ->required();
    cmd->add_option("--kit", a->kit, "the kit (TOML; default: the thesis's 18 joints and 7 splitters)");
    cmd->add_option("--joints", a->joints, "use at most this many of the kit's joints")->check(CLI::Range(1, 256));
    cmd->add_flag("--no-splitters", a->no_splitters, "joints only, on one chain");
    cmd->add_flag("--exact-rest", a->exact_rest, "joints' rest settings copy the rig at rest, even past their stops "
                                                  "(default: centred in their range where the stops need it)");
    cmd->add_flag("--force", a->force, "replace a plan already in --out");
    cmd->callback([a, &exit_code] { exit_code = run_plan(*a); });
  }
  {
    auto a = std::make_shared<EmulateArgs>();
    CLI::App* cmd = add_command(app, "rig emulate");
    cmd->add_option("--plan", a->plan, "plan.json from 'proprio rig plan'")->required();
    cmd->add_option("--character", a->character, "the character the plan is for (.gltf, or example:NAME)")->required();
    cmd->add_option("--seconds", a->seconds, "how long to run (0: until Ctrl-C)")
        ->check(CLI::Range(0.0, 86400.0))
        ->capture_default_str();
    a->faults.add(cmd);
    cmd->callback([a, &exit_code] { exit_code = run_emulate(*a); });
  }
  {
    auto d = std::make_shared<LiveArgs>();
    d->run.out = "rig-live-frames";
    d->run.size = "960x540";
    d->run.fps = 10.0;
    CLI::App* cmd = add_command(app, "rig live");
    cmd->add_option("--plan", d->plan, "plan.json from 'proprio rig plan'")->required();
    cmd->add_option("--character", d->character, "the character the plan is for (.gltf, or example:NAME)")->required();
    cmd->add_option("--device", d->device, "emulate (the plan's device on the fake USB cable, with bus faults) or usb")
        ->check(CLI::IsMember({"emulate", "usb"}))
        ->capture_default_str();
    cmd->add_option("--hid-path", d->hid_path, "--device usb: the base's hidraw node (default: the first rig base)");
    cmd->add_option("--seconds", d->seconds, "how long to run (headless default 10; window/XR: until closed)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--record", d->record, "record the session (.prec): device joints, rig pose, truth, events");
    cmd->add_flag("--no-pose-space", d->no_pose_space, "undriven bones stay at rest (no pose-space interpolation)");
    cmd->add_flag("--no-truth", d->no_truth, "emulated device: do not draw the animator's pose beside it");
    d->faults.add(cmd);
    add_live_view_options(cmd, d->run);
    cmd->callback([d, &exit_code] { exit_code = run_live(*d); });
  }
}

}  // namespace proprio::cli
