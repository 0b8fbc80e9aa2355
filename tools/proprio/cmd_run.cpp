// proprio run SCENE: the engine (scene + hands + haptics + renderer) to an
// HMD through OpenXR, a desktop window, or PNG frames headless.
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "commands.hpp"
#include "run_args.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/replay_source.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/engine/scripted_hands.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/sim/sim_hand_source.hpp"

namespace proprio::cli {
namespace {

using engine::OutputMode;

Result<Finger> parse_finger(const std::string& s) {
  static const char* names[] = {"thumb", "index", "middle", "ring", "little"};
  for (std::size_t i = 0; i < 5; ++i) {
    if (s == names[i]) return static_cast<Finger>(i);
  }
  return make_error(Errc::invalid_argument, "unknown finger '" + s + "' (thumb, index, middle, ring, little)");
}

int run_scene(const RunArgs& a) {
  auto scene = engine::Scene::load(a.scene);
  if (!scene) return report_error(scene.error());
  auto o = app_options_from(a);
  if (!o) return report_error(o.error());
  auto in = app_inputs_from(a, *scene, *o);
  if (!in) return report_error(in.error());
  std::printf("Scene '%s' (%zu objects); hands: %s; haptics: %s\n", scene->name.c_str(), scene->entities.size(),
              a.hands.front().c_str(), a.haptics.c_str());
  auto app = engine::App::create(std::move(*scene), std::move(*in), *o);
  if (!app) return report_error(app.error());
  auto report = run_app_until_done(**app);
  if (!report) return report_error(report.error());
  std::printf("%s\n", report->describe().c_str());
  if (!report->images.empty()) {
    std::printf("Frames written to %s/ (frame_0000.png ... frame_%04d.png; stereo pairs side by side)\n",
                a.out.c_str(), report->frames - 1);
  }
  return 0;
}

int run(const RunArgs& a) {
  if (!a.participant.empty()) {
#ifdef PROPRIO_HAVE_PERCEPTION_THRESHOLD
    if (a.scene == "perception-threshold") return run_perception_threshold(a);
    if (a.scene == "hmd-calibration") return run_hmd_calibration(a);
#endif
#ifdef PROPRIO_HAVE_PEG_IN_HOLE
    if (a.scene == "peg-in-hole") return run_peg_in_hole(a);
#endif
    return report_error(make_error(Errc::invalid_argument, "--participant runs a study sample built into this proprio (perception-threshold, "
                                                           "hmd-calibration, peg-in-hole), not '" + a.scene + "'"));
  }
  return run_scene(a);
}

}  // namespace

Result<engine::AppOptions> app_options_from(const RunArgs& a) {
  engine::AppOptions o;
  o.output = a.xr ? OutputMode::xr : a.window ? OutputMode::window : a.headless ? OutputMode::headless
                                                                                : OutputMode::automatic;
  unsigned w = 0, h = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &w, &h) != 2) {
    return make_error(Errc::invalid_argument, "--size '" + a.size + "': expected WIDTHxHEIGHT");
  }
  o.width = w;
  o.height = h;
  o.stereo = !a.mono;
  o.frames = a.frames >= 0 ? a.frames : (o.output == OutputMode::headless ? 90 : 0);
  o.frame_rate_hz = a.fps;
  o.out_dir = a.out;
  o.camera = a.camera == "orbit" ? engine::HeadlessCamera::orbit : engine::HeadlessCamera::head;
  o.software_renderer = a.software;
  o.validation = o.validation || a.validation;  // debug builds validate anyway
  o.hud = !a.no_hud;
  o.hand = *parse_handedness(a.hand);
  return o;
}

Result<engine::AppInputs> app_inputs_from(const RunArgs& a, const engine::Scene& scene,
                                          const engine::AppOptions& o) {
  engine::AppInputs in;
  auto shape = HandShape::from_measurements(0.19, 0.09);
  if (!shape) return shape.error();
  in.hand_model = std::make_shared<const HandModel>(*shape);
  // Headless runs step simulated time unless told otherwise; live sources
  // (window, XR) run on the monotonic clock.
  const bool simulated = o.output == OutputMode::headless && !a.realtime;
  if (simulated) in.simulated_clock = std::make_shared<ManualClock>(kNsPerSecond);
  const Clock& clock = simulated ? static_cast<const Clock&>(*in.simulated_clock) : MonotonicClock::instance();

  const std::string& kind = a.hands.front();
  if (kind == "touch") {
    in.hands = std::make_shared<engine::ScriptedTouchSource>(in.hand_model, o.hand, scene, clock.now_ns());
  } else if (kind == "sim") {
    sim::SimHandSourceOptions so;
    so.subject = a.sim_subject;
    so.seed = a.seed;
    so.relative_to_head = false;
    so.rate_hz = simulated ? 0.0 : 90.0;  // simulated time: the frame loop produces each sample
    auto src = sim::SimHandSource::create(so, clock);
    if (!src) return src.error();
    std::shared_ptr<sim::SimHandSource> sim_source = std::move(*src);
    if (simulated) in.before_frame = [sim_source](TimeNs t) { sim_source->produce(t); };
    in.hands = sim_source;
  } else if (kind == "replay") {
    if (a.hands.size() < 2) return make_error(Errc::invalid_argument, "--hands replay needs a file");
    ReplayOptions ro;
    ro.loop = true;
    auto src = ReplayHandSource::open(a.hands[1], ro);
    if (!src) return src.error();
    auto replay = std::make_shared<ReplayHandSource>(std::move(*src));
    replay->set_time_offset_ns(clock.now_ns() - replay->file_time_range().first_ns);
    in.hands = replay;
  } else if (kind == "xr" || kind == "none") {
    // xr: the runtime's XR_EXT_hand_tracking (in --xr sessions); none: no hand.
  } else {
    return make_error(Errc::invalid_argument,
                      "--hands '" + kind + "': choose touch, sim, replay FILE, xr or none (vist and glove feed the "
                      "engine through the OpenXR layer: run the layer with that source and use --xr --hands xr)");
  }

  if (a.haptics == "sim") {
    auto model = haptics::load_device_model(a.device);
    if (!model) return model.error();
    std::shared_ptr<const haptics::FingertipDeviceModel> shared(std::move(*model));
    for (const auto& f : a.fingers) {
      auto finger = parse_finger(f);
      if (!finger) return finger.error();
      auto sink = haptics::EmulatedFingertip::create(shared);
      if (!sink) return sink.error();
      in.haptic_channels.push_back({*finger, shared, std::shared_ptr<haptics::EmulatedFingertip>(std::move(*sink))});
    }
  } else if (a.haptics != "none") {
    return make_error(Errc::invalid_argument, "--haptics '" + a.haptics + "': choose sim or none (real devices: "
                      "proprio haptics devices / haptics test; HID in the engine is not wired yet)");
  }
  return in;
}

Result<engine::AppReport> run_app_until_done(engine::App& app) {
  static engine::App* running = nullptr;
  running = &app;
  std::signal(SIGINT, [](int) {
    if (running) running->request_stop();
    std::signal(SIGINT, SIG_DFL);
  });
  auto report = app.run();
  running = nullptr;
  std::signal(SIGINT, SIG_DFL);
  return report;
}

void add_run_command(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand(
      "run",
      "Run a scene with the engine: tracked hands, the haptics servo loop and the renderer. Output goes to an HMD "
      "through OpenXR when a runtime with XR_KHR_vulkan_enable2 is present, else to a window, else headless to PNG "
      "frames (force one with --xr, --window or --headless). Headless runs step simulated time, so they are "
      "reproducible.");
  cmd->add_option("scene", a->scene, "built-in scene (half-cylinder, peg-in-hole, table, empty) or a scene .toml "
                                     "(docs/engine.md)")
      ->capture_default_str();
  auto* xr = cmd->add_flag("--xr", a->xr, "OpenXR session (stereo to the HMD)");
  auto* window = cmd->add_flag("--window", a->window, "desktop window with a mouse/keyboard camera");
  auto* headless = cmd->add_flag("--headless", a->headless, "render --frames frames to PNG files in --out");
  xr->excludes(window)->excludes(headless);
  window->excludes(headless);
  cmd->add_option("--hands", a->hands,
                  "hand source: touch (a scripted index finger pressing the scene's focus), sim (the procedural "
                  "hand), replay FILE.prec, xr (the runtime's XR_EXT_hand_tracking) or none")
      ->expected(1, 2)
      ->capture_default_str();
  cmd->add_option("--haptics", a->haptics, "sim (emulated fingertip devices) or none")->capture_default_str();
  cmd->add_option("--device", a->device, "fingertip device model (config/haptics/*.toml)")->capture_default_str();
  cmd->add_option("--fingers", a->fingers, "fingers with a device")->delimiter(',')->capture_default_str();
  cmd->add_option("--frames", a->frames, "frames to render (default: 90 headless, until closed otherwise)");
  cmd->add_option("--fps", a->fps, "headless frame rate (simulated time step)")->capture_default_str();
  auto* out_option = cmd->add_option("--out", a->out, "headless: folder for the PNG frames; studies: the session folder")
      ->capture_default_str();
  cmd->add_option("--size", a->size, "per-eye image size (headless, window)")->capture_default_str();
  cmd->add_flag("--mono", a->mono, "headless: one eye instead of a stereo pair");
  cmd->add_option("--camera", a->camera, "headless camera: head (standing viewer) or orbit")
      ->check(CLI::IsMember({"head", "orbit"}))
      ->capture_default_str();
  cmd->add_option("--hand", a->hand, "the hand that drives the haptic proxy")
      ->check(CLI::IsMember({"left", "right"}))
      ->capture_default_str();
  cmd->add_option("--sim-subject", a->sim_subject, "--hands sim: simulated subject")->capture_default_str();
  auto* seed_option = cmd->add_option("--seed", a->seed, "--hands sim: motion seed; studies: the study's seed "
                                                         "(default: the design's)")
                          ->capture_default_str();
  cmd->add_flag("--software", a->software, "force Mesa's lavapipe (CPU) renderer");
  cmd->add_flag("--validation", a->validation, "Vulkan validation layer, on by default in debug builds (fails the run on any validation error)");
  cmd->add_flag("--realtime", a->realtime, "headless: run on the wall clock instead of simulated time");
  cmd->add_flag("--no-hud", a->no_hud, "no text overlay");
  cmd->add_option("--participant", a->participant,
                  "run the scene's study (perception-threshold, hmd-calibration, peg-in-hole): 'sim' for simulated participants, "
                  "or a real participant's id (its number sets the counterbalancing position: P07 is the 7th)");
  cmd->add_option("--participants", a->participants, "--participant sim: how many")->capture_default_str();
  cmd->add_option("--design", a->design, "the study's config file (default: the published protocol)");
  cmd->add_flag("--resume", a->resume, "continue the crashed session in --out at its next trial");
  cmd->add_flag("--force", a->force, "overwrite session data already in --out");
  cmd->add_option("--calibration", a->calibration,
                  "perception-threshold: the HMD calibration to apply (written by 'run hmd-calibration')");
  cmd->callback([a, &exit_code, out_option, seed_option] {
    a->out_given = out_option->count() > 0;
    a->seed_given = seed_option->count() > 0;
    exit_code = run(*a);
  });
}

}  // namespace proprio::cli
