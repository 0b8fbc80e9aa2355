// proprio run array-demo --model DIR_OR_ONNX: a stretch sensor array worn by
// a simulated wearer, read live through the emulated board over the fake HID
// cable and reconstructed (stretch_array_eval::ArrayLiveSource), drawn by the
// engine as a deforming surface beside the simulator's true sheet, with a line
// giving the frame rate, latency and mean vertex error.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "commands.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/stretch_array_eval/array_live.hpp"
#include "proprio/stretch_array_recon/recon_mesh.hpp"
#include "run_args.hpp"

namespace proprio::cli {
// Named, not anonymous: the CLI is a unity build.
namespace array_demo {

namespace sae = stretch_array_eval;

struct DemoArgs {
  std::string model;
  std::string motion = "elbow";
  std::string layout;
  double seconds = -1.0;  // headless default 8; window/XR: until closed
  double rest_s = 1.0;
  std::uint64_t seed = 1;
  bool stereo = false;
  bool flat_rest = false;
  std::string board = "sim";  // sim | usb
  std::string hid_path;
  RunArgs run;  // output, size, fps, camera, renderer
};

// The renderer draws both faces of every triangle (no culling) and lights
// the back face by its own side, so each triangle once: a reversed copy
// would fight the first in the depth buffer and cancel the vertex normals.
std::vector<std::uint32_t> triangle_indices(const stretch_array_recon::ReconMesh& mesh) {
  std::vector<std::uint32_t> t;
  t.reserve(mesh.triangles.size() * 3);
  for (const auto& tri : mesh.triangles) t.insert(t.end(), {tri[0], tri[1], tri[2]});
  return t;
}

std::string hud_line(const sae::ArrayLiveSnapshot& snap) {
  const auto& s = snap.stats;
  if (s.link != "streaming" && s.link != "stopped") return fmt::format("board {}: waiting for it", s.link);
  if (s.calibrating) return fmt::format("hold still: taking C0 ({} rest frames)", s.rest_frames);
  if (!snap.frame) return "reconstructing...";
  const auto& f = *snap.frame;
  // Short: the prompt is drawn large and must fit a 640-pixel view.
  return fmt::format("{:.0f} fps  {:.0f} ms  error {:.1f} mm", s.frame_rate_hz, 1e3 * f.latency_s,
                     std::isfinite(f.mean_error_m) ? 1e3 * f.mean_error_m : std::numeric_limits<double>::quiet_NaN());
}

int run_demo(DemoArgs d) {
  RunArgs& a = d.run;
  a.mono = !d.stereo;
  if (!a.xr && !a.window) a.headless = true;  // the demo renders frames unless asked for a window or an HMD
  if (d.seconds < 0.0) d.seconds = a.headless ? 8.0 : 0.0;
  if (a.headless) a.frames = std::max(1, static_cast<int>(std::lround(d.seconds * a.fps)));
  auto options = app_options_from(a);
  if (!options) return report_error(options.error());

  sae::ArrayLiveOptions lo;
  lo.model = d.model;
  lo.motion = d.motion;
  lo.layout_file = d.layout;
  lo.rest_s = d.rest_s;
  lo.seed = d.seed;
  lo.wrapped_rest_shape = !d.flat_rest;
  auto source = d.board == "usb" ? sae::ArrayLiveSource::create_usb(lo, {}, d.hid_path)
                                 : sae::ArrayLiveSource::create_simulated(lo);
  if (!source) return report_error(source.error());
  if (d.board == "usb") {
    // No file holds an array's per-row calibration yet: the rows keep what
    // the board's own open-pads subtraction leaves, and there is no truth.
    std::printf("board on USB%s: no per-row parasitic calibration (rows as the board subtracts them); C0 over the "
                "first %.1f s: hold the sleeve still\n",
                d.hid_path.empty() ? "" : (" " + d.hid_path).c_str(), d.rest_s);
  }
  sae::ArrayLiveSource& live = **source;
  std::printf("%s\n", lo.describe().c_str());

  auto scene = engine::Scene::preset("empty");
  if (!scene) return report_error(scene.error());
  engine::AppInputs in;
  const auto triangles = triangle_indices(live.mesh());
  in.surfaces.push_back({"reconstructed sheet", triangles, live.vertex_count(), {0.9f, 0.55f, 0.25f, 1.0f}});
  in.surfaces.push_back({"true sheet (simulator)", triangles, live.vertex_count(), {0.45f, 0.6f, 0.8f, 1.0f}});

  // Where the sheets are drawn, fixed at the first reconstructed frame: in
  // front of the viewer and a little below the text, each sheet turned so
  // that its principal axes (of the true sheet then) line up with the view's
  // (the normal towards the viewer), the reconstruction left, the truth right.
  struct Placement {
    Vec3 p_centre_sim;
    Mat3 R_world_sim;
    Vec3 p_anchor_world, right_world;
    double half_gap_m = 0.0;
  };
  std::optional<Placement> placement;
  const auto wall_start = std::chrono::steady_clock::now();
  std::uint64_t last_index = std::numeric_limits<std::uint64_t>::max();
  std::vector<double> latency_ms, recon_ms, error_mm;
  sae::ArrayLiveSnapshot last;
  in.on_frame = [&](engine::FrameContext& c) {
    // Headless frames are rendered as fast as the renderer goes; the board is
    // live, so each frame waits for its wall-clock instant.
    if (options->output == engine::OutputMode::headless) {
      std::this_thread::sleep_until(wall_start + std::chrono::duration<double>(c.frame / options->frame_rate_hz));
    }
    const double t_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    c.show_hands = false;
    c.show_scene = false;
    const sae::ArrayLiveSnapshot snap = live.latest();
    last = snap;
    c.prompt = hud_line(snap);
    if (d.seconds > 0.0 && t_s >= d.seconds) c.stop = true;
    if (!snap.frame) return;
    const auto& f = *snap.frame;
    if (f.index != last_index) {
      last_index = f.index;
      latency_ms.push_back(1e3 * f.latency_s);
      recon_ms.push_back(f.reconstruct_ms);
      if (std::isfinite(f.mean_error_m)) error_mm.push_back(1e3 * f.mean_error_m);
    }
    if (!placement) {
      const auto& anchor = f.truth_m.empty() ? f.vertices_m : f.truth_m;
      Placement p;
      p.p_centre_sim = Vec3::Zero();
      for (const auto& v : anchor) p.p_centre_sim += v;
      p.p_centre_sim /= static_cast<double>(anchor.size());
      Mat3 cov = Mat3::Zero();
      for (const auto& v : anchor) cov += (v - p.p_centre_sim) * (v - p.p_centre_sim).transpose();
      const Eigen::SelfAdjointEigenSolver<Mat3> eig(cov);  // ascending: the normal first
      Mat3 B;
      B.row(0) = eig.eigenvectors().col(2).transpose();
      B.row(1) = eig.eigenvectors().col(1).transpose();
      B.row(2) = B.row(0).cross(B.row(1));
      const Mat3 R_world_head = c.T_world_head.q.toRotationMatrix();
      p.R_world_sim = R_world_head * B;
      p.p_anchor_world = c.T_world_head * Vec3(0.0, -0.07, -0.45);
      p.right_world = R_world_head.col(0);
      double extent = 0.0;
      for (const auto& v : anchor) extent = std::max(extent, std::abs(B.row(0).dot(v - p.p_centre_sim)));
      p.half_gap_m = 1.15 * extent;
      placement = p;
    }
    auto place = [&](const std::vector<Eigen::Vector3d>& v_sim, double side) {
      const Placement& p = *placement;
      std::vector<Vec3> out(v_sim.size());
      const Vec3 at = p.p_anchor_world + side * p.half_gap_m * p.right_world;
      for (std::size_t i = 0; i < v_sim.size(); ++i) out[i] = at + p.R_world_sim * (v_sim[i] - p.p_centre_sim);
      return out;
    };
    c.surfaces.resize(2);
    c.surfaces[0] = place(f.vertices_m, -1.0);
    if (!f.truth_m.empty()) c.surfaces[1] = place(f.truth_m, 1.0);
  };

  auto app = engine::App::create(std::move(*scene), std::move(in), *options);
  if (!app) return report_error(app.error());
  if (auto st = live.start(); !st) return report_error(st.error());
  auto report = run_app_until_done(**app);
  live.stop();
  if (!report) return report_error(report.error());
  std::printf("%s\n", report->describe().c_str());
  const auto final_stats = live.latest().stats;
  std::printf("array: %s\n", final_stats.describe().c_str());
  auto summary = [](std::vector<double> v, const char* what, const char* unit) {
    if (v.empty()) return;
    std::sort(v.begin(), v.end());
    double sum = 0.0;
    for (double x : v) sum += x;
    std::printf("  %s over the %zu frames shown: mean %.2f %s, median %.2f, p95 %.2f, max %.2f\n", what, v.size(),
                sum / static_cast<double>(v.size()), unit, v[v.size() / 2], v[std::min(v.size() - 1, v.size() * 95 / 100)],
                v.back());
  };
  summary(latency_ms, "latency (newest measurement -> vertices)", "ms");
  summary(recon_ms, "reconstruction (regressor + ARAP)", "ms");
  summary(error_mm, "mean vertex error against the simulator", "mm");
  if (!report->images.empty()) {
    std::printf("Frames written to %s/ (frame_0000.png ... frame_%04d.png): reconstructed sheet (orange) left, "
                "the simulator's sheet (blue) right\n",
                a.out.c_str(), report->frames - 1);
  }
  if (final_stats.frames == 0) {
    return report_error(make_error(Errc::unavailable, "no frame was reconstructed: " + final_stats.describe()));
  }
  return 0;
}

}  // namespace array_demo

void add_run_array_demo_command(CLI::App& app, int& exit_code) {
  auto d = std::make_shared<array_demo::DemoArgs>();
  d->run.out = "array-demo-frames";
  d->run.size = "960x540";
  d->run.fps = 10.0;
  CLI::App* cmd = add_command(app, "run array-demo");
  cmd->add_option("--model", d->model, "the regressor: an .onnx file, or the folder `proprio train array` wrote (OUT "
                                       "or OUT/dnn)")
      ->required();
  cmd->add_option("--motion", d->motion, "the wearer: balloon, biceps, elbow, wrist or forearm")
      ->check(CLI::IsMember({"balloon", "biceps", "elbow", "wrist", "forearm"}))
      ->capture_default_str();
  cmd->add_option("--layout", d->layout, "the array's layout file (default: prototype_92; biceps: biceps_144)");
  cmd->add_option("--seconds", d->seconds, "how long to run (headless default 8; window/XR: until closed)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--rest-seconds", d->rest_s, "the wearer holds still this long first: C0 is taken there")
      ->capture_default_str();
  cmd->add_flag("--flat-rest", d->flat_rest, "ARAP deforms the flat sheet instead of the rest mesh wrapped on the "
                                            "body's nominal cylinder (as bench array)");
  cmd->add_option("--board", d->board, "sim (a simulated wearer and the emulated board over the fake cable) or usb "
                                       "(a stretch board on USB: no truth, no per-row calibration yet)")
      ->check(CLI::IsMember({"sim", "usb"}))
      ->capture_default_str();
  cmd->add_option("--hid-path", d->hid_path, "--board usb: the board's hidraw node (default: the first stretch board)");
  cmd->add_option("--seed", d->seed, "the wearer's and the board's seed")->capture_default_str();
  add_live_view_options(cmd, d->run);
  cmd->add_flag("--stereo", d->stereo, "headless: a stereo pair instead of one eye");
  cmd->add_option("--camera", d->run.camera, "headless camera: head (standing viewer) or orbit")
      ->check(CLI::IsMember({"head", "orbit"}))
      ->capture_default_str();
  cmd->callback([d, &exit_code] {
    exit_code = array_demo::run_demo(*d);
    // `run`'s own callback (a scene) runs after a subcommand's; this ends the
    // parse with the demo's exit status instead.
    if (exit_code == 0) throw CLI::Success();
    throw CLI::RuntimeError(exit_code);
  });
}

}  // namespace proprio::cli
