// proprio run SCENE: the engine (scene + hands + haptics + renderer) to an
// HMD through OpenXR, a desktop window, or PNG frames headless.
#include <csignal>
#include <filesystem>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "commands.hpp"
#include "run_args.hpp"
#include "proprio/core/data_dir.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/replay_source.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/engine/scripted_hands.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/haptics/hid_channels.hpp"
#include "proprio/hand_sources/hand_sources.hpp"
#include "proprio/sim/sim_hand_source.hpp"

namespace proprio::cli {
namespace {

using engine::OutputMode;

Result<Finger> finger_from_arg(const std::string& s) {
  if (auto f = proprio::parse_finger(s)) return *f;
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

// --ftm-calibration feeds only --hands ftm; --tracker only the simulated
// peg-in-hole study (a real participant's glove is --hands ftm). An empty
// value given on purpose would read as "not given": refused too.
Status check_ftm_options(const RunArgs& a, bool calibration_given, bool tracker_given) {
  if (calibration_given && a.ftm_calibration.empty()) {
    return make_error(Errc::invalid_argument, "--ftm-calibration '': give the FTM calibration file (from 'proprio "
                                              "calibrate ftm')");
  }
  if (calibration_given && a.hands.front() != "ftm") {
    return make_error(Errc::invalid_argument, "--ftm-calibration applies only to --hands ftm [sim|device], not "
                                              "--hands " + a.hands.front());
  }
  if (tracker_given && a.tracker.empty()) {
    return make_error(Errc::invalid_argument,
                      "--tracker '': choose ideal (the commanded hand) or ftm (the simulated FTM glove)");
  }
  if (tracker_given && (a.scene != "peg-in-hole" || a.participant.empty())) {
    return make_error(Errc::invalid_argument, "--tracker applies only to 'proprio run peg-in-hole --participant "
                                              "sim'; a live hand's glove is --hands (e.g. --hands ftm sim)");
  }
  return {};
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

void add_live_view_options(CLI::App* cmd, RunArgs& a) {
  auto* xr = cmd->add_flag("--xr", a.xr, "OpenXR session (stereo to the HMD)");
  auto* window = cmd->add_flag("--window", a.window, "desktop window with a mouse/keyboard camera");
  auto* headless = cmd->add_flag("--headless", a.headless, "frames to PNG files in --out (the default)");
  xr->excludes(window)->excludes(headless);
  window->excludes(headless);
  cmd->add_option("--out", a.out, "headless: the frames' folder")->capture_default_str();
  cmd->add_option("--size", a.size, "image size WIDTHxHEIGHT (per eye)")->capture_default_str();
  cmd->add_option("--fps", a.fps, "headless: frames per second of wall time")
      ->check(CLI::Range(0.5, 240.0))
      ->capture_default_str();
  cmd->add_flag("--software", a.software, "force Mesa's lavapipe (CPU) renderer");
  cmd->add_flag("--no-hud", a.no_hud, "no engine status line");
}

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
  if (auto look = engine::parse_hand_look(a.hand_look)) {
    o.hand_look = *look;
  } else if (const auto ext = std::filesystem::path(a.hand_look).extension(); ext == ".gltf" || ext == ".glb") {
    o.hand_look = engine::HandLook::skinned;
    o.hand_gltf = a.hand_look;
  } else {
    return make_error(Errc::invalid_argument,
                      "--hand-look '" + a.hand_look + "': choose joints, skinned or a glTF hand (.gltf, .glb)");
  }
  return o;
}

Result<engine::AppInputs> app_inputs_from(const RunArgs& a, const engine::Scene& scene,
                                          const engine::AppOptions& o) {
  engine::AppInputs in;
  auto shape = HandShape::from_measurements(0.19, 0.09);
  if (!shape) return shape.error();
  in.hand_model = std::make_shared<const HandModel>(*shape);
  const std::string& kind = a.hands.front();
  // Headless runs step simulated time unless told otherwise; live sources
  // (window, XR) run on the monotonic clock, as do VIST and the glove, whose
  // trackers run on their own threads in real time.
  const bool real_time_source = kind == "vist" || kind == "glove" || kind == "ftm";
  const bool simulated = o.output == OutputMode::headless && !a.realtime && !real_time_source;
  if (simulated) in.simulated_clock = std::make_shared<ManualClock>(kNsPerSecond);
  const Clock& clock = simulated ? static_cast<const Clock&>(*in.simulated_clock) : MonotonicClock::instance();

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
  } else if (real_time_source) {
    // The OpenXR layer's sources, configured as a [[source]] table would be.
    openxr_layer::SourceConfig sc;
    sc.hands = {o.hand};
    sc.space = openxr_layer::ReferenceSpace::local;
    const std::string arg = a.hands.size() > 1 ? a.hands[1] : std::string();
    if (kind == "vist") {
      if (arg.empty()) {
        return make_error(Errc::invalid_argument, "--hands vist needs a VIST session recording (proprio sim-vist, or "
                                                  "one recorded live): --hands vist FILE.prec");
      }
      sc.type = openxr_layer::SourceType::vist;
      sc.path = arg;
    } else if (kind == "ftm") {
      sc.type = openxr_layer::SourceType::ftm;
      sc.input = arg.empty() ? "sim" : arg;
      if (sc.input != "sim" && sc.input != "device") {
        return make_error(Errc::invalid_argument, "--hands ftm '" + arg + "': choose sim (a simulated wearer, "
                                                  "calibrated from its own figure-eight and poses) or device (an FTM "
                                                  "board on USB, with --ftm-calibration)");
      }
      if (sc.input == "device" && a.ftm_calibration.empty()) {
        return make_error(Errc::invalid_argument, "--hands ftm device needs the wearer's calibration: "
                                                  "--ftm-calibration FILE (from 'proprio calibrate ftm')");
      }
      sc.calibration = a.ftm_calibration;
      sc.subject = a.sim_subject;
      sc.seed = a.seed;
    } else {
      sc.type = openxr_layer::SourceType::glove;
      sc.input = arg.empty() ? "sim" : arg;
      if (sc.input != "sim" && sc.input != "device") {
        return make_error(Errc::invalid_argument, "--hands glove '" + arg + "': choose sim (a simulated wearer) or "
                                                  "device (the read-out board on USB, with --glove-calibration)");
      }
      if (sc.input == "device" && a.glove_calibration.empty()) {
        return make_error(Errc::invalid_argument, "--hands glove device needs the wearer's calibration: "
                                                  "--glove-calibration FILE (from 'proprio calibrate glove')");
      }
      sc.calibration = a.glove_calibration;
      sc.subject = a.sim_subject;
      sc.seed = a.seed;
    }
    auto src = hand_sources::start_hand_source(sc, 50 * kNsPerMillisecond);
    // The source's message may not name the file (a calibration for the other hand).
    if (!src && kind == "ftm" && !sc.calibration.empty()) {
      return src.error().with_context("--hands ftm " + sc.input + " --hand " + a.hand + " --ftm-calibration " +
                                      sc.calibration);
    }
    if (!src) return src.error();
    std::shared_ptr<HandSource> source = std::move(*src);
    in.hands = a.no_recentre ? source
                             : std::make_shared<engine::RecentredHandSource>(source,
                                                                             engine::recentred_wrist_target(scene));
  } else if (kind == "xr" || kind == "none") {
    // xr: the runtime's XR_EXT_hand_tracking (in --xr sessions); none: no hand.
  } else {
    return make_error(Errc::invalid_argument, "--hands '" + kind +
                                                  "': choose touch, sim, replay FILE, vist FILE, glove [sim|device], ftm [sim|device], "
                                                  "xr or none");
  }

  if (a.haptics == "sim") {
    auto model = haptics::load_device_model(a.device);
    if (!model) return model.error();
    std::shared_ptr<const haptics::FingertipDeviceModel> shared(std::move(*model));
    for (const auto& f : a.fingers) {
      auto finger = finger_from_arg(f);
      if (!finger) return finger.error();
      auto sink = haptics::EmulatedFingertip::create(shared);
      if (!sink) return sink.error();
      in.haptic_channels.push_back({*finger, shared, std::shared_ptr<haptics::EmulatedFingertip>(std::move(*sink))});
    }
  } else if (a.haptics == "hid") {
    auto channels = open_hid_haptics(a);
    if (!channels) return channels.error();
    in.haptic_channels = std::move(*channels);
  } else if (a.haptics != "none") {
    return make_error(Errc::invalid_argument, "--haptics '" + a.haptics + "': choose sim, hid or none");
  }
  return in;
}

Result<std::vector<haptics::ServoChannel>> open_hid_haptics(const RunArgs& a) {
  haptics::HidChannelOptions ho;
  ho.fingers.clear();
  for (const auto& f : a.fingers) {
    auto finger = finger_from_arg(f);
    if (!finger) return finger.error();
    ho.fingers.push_back(*finger);
  }
  for (const auto& b : a.hid_devices) {
    auto binding = haptics::parse_hid_binding(b);
    if (!binding) return binding.error().with_context("--hid-device");
    ho.bindings.push_back(*binding);
  }
  ho.hand = *parse_handedness(a.hand);
  if (a.device_given) ho.model_file = a.device;
  ho.model_dir = data_path("haptics");
  auto listed = devices::enumerate_fingertip_devices();
  if (!listed) return listed.error();
  auto channels = haptics::open_hid_channels(ho, *listed);
  if (!channels) return channels.error();
  std::vector<haptics::ServoChannel> out;
  for (auto& c : *channels) {
    std::printf("haptics: %s\n", c.describe().c_str());
    out.push_back(std::move(c.channel));
  }
  return out;
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
  CLI::App* cmd = add_command(app, "run");
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
                  "hand), replay FILE.prec, vist FILE.prec (a VIST session through the tracker), glove [sim|device] "
                  "(the stretch glove: a simulated wearer, or the read-out board on USB), ftm [sim|device] (the FTM glove, "
                  "likewise), xr (the runtime's "
                  "XR_EXT_hand_tracking) or none. vist, glove and ftm run in real time, also headless")
      ->expected(1, 2)
      ->capture_default_str();
  cmd->add_flag("--no-recentre", a->no_recentre,
                "--hands vist/glove: keep the source's own coordinates (by default the first wrist pose is moved "
                "above the scene's focus, and the hand keeps that offset)");
  cmd->add_option("--glove-calibration", a->glove_calibration,
                  "--hands glove device: the wearer's min-max calibration (proprio calibrate glove)");
  auto* ftm_calibration_option = cmd->add_option("--ftm-calibration", a->ftm_calibration,
                                                 "--hands ftm: the FTM glove's calibration (proprio calibrate ftm); "
                                                 "needed for a board (device), optional for a simulated wearer (sim)");
  cmd->add_option("--haptics", a->haptics,
                  "sim (emulated fingertip devices), hid (fingertip devices on USB, one per --fingers) or none")
      ->check(CLI::IsMember({"sim", "hid", "none"}))
      ->capture_default_str();
  auto* device_option = cmd->add_option("--device", a->device,
                                        "fingertip device model (config/haptics/*.toml); hid: default by the kind "
                                        "each device reports")
                            ->capture_default_str();
  cmd->add_option("--hid-device", a->hid_devices,
                  "--haptics hid: FINGER=SERIAL or FINGER=/dev/hidrawN (repeatable); unbound fingers take a device "
                  "assigned to them, else the next free one (proprio haptics devices lists them)");
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
  cmd->add_option("--hand-look", a->hand_look,
                  "how hands are drawn: joints (spheres and bones with axis triads), skinned (a hand mesh generated "
                  "from the hand model), or a glTF hand whose skin joints carry OpenXR joint names")
      ->capture_default_str();
  cmd->add_option("--sim-subject", a->sim_subject, "--hands sim / glove sim: simulated subject")->capture_default_str();
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
  auto* tracker_option = cmd->add_option(
      "--tracker", a->tracker, "peg-in-hole --participant sim: ideal (the commanded hand) or ftm (a simulated FTM glove)");
  cmd->add_flag("--resume", a->resume, "continue the crashed session in --out at its next trial");
  cmd->add_flag("--force", a->force, "overwrite session data already in --out");
  cmd->add_option("--calibration", a->calibration,
                  "perception-threshold: the HMD calibration to apply (written by 'run hmd-calibration')");
  cmd->callback([a, &exit_code, out_option, seed_option, device_option, ftm_calibration_option, tracker_option] {
    // A value that would be silently ignored is refused: a user who names
    // their calibration or a tracker must get it, or be told why not.
    if (auto st = check_ftm_options(*a, ftm_calibration_option->count() > 0, tracker_option->count() > 0); !st) {
      exit_code = report_error(st.error());
      return;
    }
    a->out_given = out_option->count() > 0;
    a->device_given = device_option->count() > 0;
    a->seed_given = seed_option->count() > 0;
    exit_code = run(*a);
  });
}

}  // namespace proprio::cli
