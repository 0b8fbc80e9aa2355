// proprio calibrate wrist: the wearer's wrist in a tracked device's grip frame
// (proprio::engine, wrist_calibration.hpp), guided on stdout, saved per user
// for the OpenXR layer's wrist_calibration key (docs/wrist-calibration.md).
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/log.hpp"
#include "proprio/engine/wrist_calibration.hpp"
#include "proprio/openxr_layer/layer_config.hpp"

namespace proprio::cli {

namespace calibrate_wrist {

namespace fs = std::filesystem;
using engine::WristDevice;
using engine::WristReference;

struct Args {
  std::string hand;
  std::string device;
  std::string reference = "pose";
  std::string role;
  std::string out;
  std::string session = "auto";
  double seconds = 2.0;
  double timeout_s = 30.0;
  double wrist_below_device_m = 0.03;
  double wrist_behind_grip_m = 0.08;
  double max_angular_speed_deg_s = 10.0;
  double max_position_spread_m = 0.01;
  double max_rotation_spread_deg = 5.0;
  bool non_interactive = false;
  bool force = false;
};

constexpr double kCountdownS = 5.0;

// $XDG_CONFIG_HOME/proprio/wrist/<hand>_<device>.toml, else ~/.config/...: per user.
Result<fs::path> default_out(const engine::WristCalibrationOptions& o) {
  const std::string name = std::string(to_string(o.hand)) + "_" + std::string(engine::to_string(o.device)) + ".toml";
  if (const char* x = std::getenv("XDG_CONFIG_HOME"); x && *x) return fs::path(x) / "proprio" / "wrist" / name;
  if (const char* h = std::getenv("HOME"); h && *h) return fs::path(h) / ".config" / "proprio" / "wrist" / name;
  return make_error(Errc::not_found,
                    "neither XDG_CONFIG_HOME nor HOME is set, so there is no per-user folder: pass --out");
}

std::string toml_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

void print_instructions(const engine::WristCalibrationOptions& o, bool interactive) {
  const std::string hand(to_string(o.hand));
  const std::string device = o.device == WristDevice::tracker
                                 ? "the VIVE tracker with role " + o.role() + " (on the " + hand + " wrist)"
                                 : "the " + hand + " controller";
  std::printf("Calibrating the %s wrist against %s.\n", hand.c_str(), device.c_str());
  if (o.reference == WristReference::runtime_hand) {
    std::printf(
        "Reference: the runtime's own hand tracking (XR_EXT_hand_tracking, Proprio's layer off in this process).\n"
        "Keep the %s hand %s in the headset's view, fingers open and relaxed, and hold it still for %.1f s.\n",
        hand.c_str(), o.device == WristDevice::tracker ? "(wearing the tracker)" : "(holding the controller)",
        o.seconds);
  } else if (o.device == WristDevice::tracker) {
    std::printf(
        "Wear the tracker where you will use it. When the countdown ends, hold the %s hand FLAT, PALM DOWN, fingers\n"
        "together and pointing STRAIGHT AHEAD (level, the way the headset looks), arm relaxed (rest the elbow if\n"
        "you can), and hold still for %.1f s. Look ahead, level, meanwhile.\n",
        hand.c_str(), o.seconds);
  } else {
    std::printf(
        "When the countdown ends, hold the controller as you use it, with the FOREARM LEVEL and pointing STRAIGHT\n"
        "AHEAD (the way the headset looks), THUMB UP (the back of the hand facing %s), and hold still for %.1f s.\n"
        "Look ahead, level, meanwhile.\n",
        o.hand == Handedness::right ? "right" : "left", o.seconds);
  }
  if (!interactive) std::printf("(--non-interactive: measuring at once)\n");
  std::fflush(stdout);
}

struct Printer {
  bool in_countdown = false;
  void end_countdown() {
    if (in_countdown) std::printf("\n");
    in_countdown = false;
  }
  void operator()(const engine::XrProbeRuntime& r) {
    std::printf("Runtime: %s %u.%u.%u\n", r.name.c_str(), r.version_major, r.version_minor, r.version_patch);
  }
  void operator()(const engine::XrProbeHeadlessRefused& h) {
    std::printf(
        "The runtime refuses frames in headless sessions (%s): starting again with a Vulkan graphics "
        "binding.\n",
        h.refused_call.c_str());
  }
  void operator()(const engine::XrProbeSessionStarted& s) {
    std::printf("Session: %s%s\n",
                s.kind == engine::XrProbeSessionKind::headless ? "headless (XR_MND_headless)"
                                                               : "Vulkan graphics binding (XR_KHR_vulkan_enable2)",
                s.device.empty() ? "" : (" on " + s.device).c_str());
  }
  void operator()(const engine::XrProbeZeroDisplayTime&) {
    std::printf("(the runtime's predictedDisplayTime is 0: locating at the current time)\n");
  }
  void operator()(const engine::WristCalibrationCountdown& c) {
    std::printf(in_countdown ? " %d..." : "Get into the pose: %d...", c.seconds_left);
    in_countdown = true;
  }
  void operator()(const engine::WristCalibrationMeasuring&) {
    end_countdown();
    std::printf("Hold still now.\n");
  }
  void operator()(const engine::WristCalibrationWaiting& w) {
    end_countdown();
    std::printf("  waiting: %s\n", w.what.c_str());
  }
  void operator()(const engine::WristCalibrationHolding& h) {
    std::printf("  still for %.1f of %.1f s\n", h.held_s, h.needed_s);
  }
  void operator()(const engine::WristCalibrationMoved& m) {
    end_countdown();
    std::printf("  moved: %s; hold still, starting again\n", m.why.c_str());
  }
};

int run(const Args& a) {
  engine::WristCalibrationOptions o;
  o.hand = a.hand == "left" ? Handedness::left : Handedness::right;
  o.device = a.device == "tracker" ? WristDevice::tracker : WristDevice::controller;
  o.reference = a.reference == "runtime-hand" ? WristReference::runtime_hand : WristReference::pose;
  o.tracker_role = a.role;
  o.seconds = a.seconds;
  o.timeout_s = a.timeout_s;
  o.countdown_s = a.non_interactive ? 0.0 : kCountdownS;
  o.wrist_below_device_m = a.wrist_below_device_m;
  o.wrist_behind_grip_m = a.wrist_behind_grip_m;
  o.still.max_angular_speed_deg_s = a.max_angular_speed_deg_s;
  o.still.max_position_spread_m = a.max_position_spread_m;
  o.still.max_rotation_spread_deg = a.max_rotation_spread_deg;
  o.session = a.session == "headless" ? engine::XrProbeSession::headless
              : a.session == "vulkan" ? engine::XrProbeSession::vulkan
                                      : engine::XrProbeSession::automatic;
  if (o.device == WristDevice::controller && !a.role.empty()) {
    return logger().error("--role applies only to --device tracker"), 1;
  }
  if (a.timeout_s < a.seconds) {
    return logger().error("--timeout ({} s) must be at least --seconds ({} s)", a.timeout_s, a.seconds), 1;
  }
  if (auto s = o.validate(); !s) return report_error(s.error());

  // Where it goes, checked before anyone holds a pose for it.
  fs::path out = a.out;
  if (out.empty()) {
    auto d = default_out(o);
    if (!d) return report_error(d.error());
    out = *d;
  }
  if (auto s = check_output_path(out, "wrist calibration"); !s) return report_error(s.error());
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_regular_file(out, ec)) {
    return logger().error("cannot write the wrist calibration to '{}': it exists and is not a regular file",
                          out.string()),
           1;
  }
  if (!a.force && fs::exists(out, ec)) {
    return logger().error("'{}' exists; pass --force to overwrite it (a calibration is worth keeping)", out.string()),
           1;
  }
  if (out.has_parent_path() && !fs::is_directory(out.parent_path(), ec)) {
    fs::create_directories(out.parent_path(), ec);
    if (ec) {
      return logger().error("cannot create the folder for '{}': {}", out.string(), ec.message()), 1;
    }
  }

  print_instructions(o, !a.non_interactive);
  g_sigint_stop.store(false);
  std::signal(SIGINT, on_sigint_stop);
  o.stop = &g_sigint_stop;
  Printer printer;
  auto result = engine::run_wrist_calibration(o, [&](const engine::WristCalibrationEvent& e) {
    std::visit(printer, e);
    std::fflush(stdout);
  });
  std::signal(SIGINT, SIG_DFL);
  printer.end_countdown();
  if (!result) return report_error(result.error());

  const Pose& T = result->T_device_wrist;
  const Vec3 r_deg = so3_log(T.q) * (180.0 / M_PI);
  std::printf("\nDone: %zu poses over %.2f s; peak %.1f deg/s, within %.1f mm and %.1f deg of the mean.\n",
              result->samples, result->window_s, result->stillness.peak_angular_speed_deg_s,
              result->stillness.position_spread_m * 1e3, result->stillness.rotation_spread_deg);
  std::printf(
      "T_device_wrist (the wrist in the device's grip frame): position [%.4f, %.4f, %.4f] m, rotation "
      "[%.2f, %.2f, %.2f] deg (rotation vector)\n",
      T.p.x(), T.p.y(), T.p.z(), r_deg.x(), r_deg.y(), r_deg.z());
  std::printf("Measured: %s.\n", result->measured.c_str());
  std::printf("Assumed:  %s.\n", result->assumed.empty() ? "nothing" : result->assumed.c_str());

  const std::string hand(to_string(o.hand));
  std::string comment = hand + " hand, " + std::string(engine::to_string(o.device)) +
                        (o.device == WristDevice::tracker ? " role " + o.role() : std::string()) + ", reference " +
                        std::string(engine::to_string(o.reference)) + "; " +
                        (result->assumed.empty() ? std::string("fully measured") : "assumed " + result->assumed);
  const std::string text = openxr_layer::format_wrist_calibration(T, comment);
  if (auto s = write_file_atomic(out, text, "wrist calibration", a.force); !s) return report_error(s.error());
  if (auto back = openxr_layer::load_wrist_calibration(out); !back) {
    return logger().error("wrote {}, but it does not load back: {}", out.string(), back.error().message), 1;
  }
  std::printf("Wrote %s\n", out.string().c_str());

  std::printf(
      "\nLayer config (docs/openxr-layer.md): in the [[source]] that serves the %s hand. The offset is this "
      "hand's, so that [[source]] should serve only it:\n",
      hand.c_str());
  std::printf("  hands = [\"%s\"]\n", hand.c_str());
  std::printf("  wrist = \"%s\"\n", std::string(engine::to_string(o.device)).c_str());
  std::printf("  wrist_calibration = %s\n", toml_string(fs::absolute(out, ec).string()).c_str());
  if (o.device == WristDevice::tracker) std::printf("  tracker_role_%s = \"%s\"\n", hand.c_str(), o.role().c_str());
  return 0;
}

}  // namespace calibrate_wrist

void add_calibrate_wrist_command(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<calibrate_wrist::Args>();
  CLI::App* cmd = add_command(app, "calibrate wrist");
  cmd->add_option("--hand", a->hand, "Which wrist")->check(CLI::IsMember({"left", "right"}))->required();
  cmd->add_option("--device", a->device,
                  "What is tracked: a VIVE-style wrist tracker (XR_HTCX_vive_tracker_interaction) or the hand's "
                  "controller (grip pose)")
      ->check(CLI::IsMember({"tracker", "controller"}))
      ->required();
  std::vector<std::string> roles;
  for (auto r : engine::vive_tracker_roles()) roles.emplace_back(r);
  cmd->add_option("--role", a->role, "--device tracker: the tracker's role (default: <hand>_wrist)")
      ->check(CLI::IsMember(roles));
  cmd->add_option("--reference", a->reference,
                  "pose: the hand held in a known pose (rotation measured, position assumed); runtime-hand: the "
                  "runtime's own optical hand tracking (fully measured)")
      ->check(CLI::IsMember({"pose", "runtime-hand"}))
      ->capture_default_str();
  cmd->add_option("--seconds", a->seconds, "The still window that is averaged, s")
      ->check(CLI::Range(0.5, 30.0))
      ->capture_default_str();
  cmd->add_option("--timeout", a->timeout_s, "Give up when no still window came within this long, s")
      ->check(CLI::Range(0.5, 3600.0))
      ->capture_default_str();
  cmd->add_flag("--non-interactive", a->non_interactive, "Start measuring at once, no countdown (scripts, tests)");
  cmd->add_option("--wrist-below-device-m", a->wrist_below_device_m,
                  "--reference pose, tracker: the wrist joint centre this far below the tracker origin (world -Y), m")
      ->check(CLI::Range(-0.2, 0.2))
      ->capture_default_str();
  cmd->add_option("--wrist-behind-grip-m", a->wrist_behind_grip_m,
                  "--reference pose, controller: the wrist joint centre this far behind the grip point along the "
                  "forearm, m")
      ->check(CLI::Range(0.0, 0.3))
      ->capture_default_str();
  cmd->add_option("--max-angular-speed-deg-s", a->max_angular_speed_deg_s,
                  "Held still: peak rotation rate (orientations 0.1 s apart), deg/s")
      ->check(CLI::Range(0.1, 360.0))
      ->capture_default_str();
  cmd->add_option("--max-position-spread-m", a->max_position_spread_m,
                  "Held still: largest distance of a position from the window's mean, m")
      ->check(CLI::Range(0.0005, 0.5))
      ->capture_default_str();
  cmd->add_option("--max-rotation-spread-deg", a->max_rotation_spread_deg,
                  "Held still: largest angle of an orientation from the window's mean, deg")
      ->check(CLI::Range(0.1, 90.0))
      ->capture_default_str();
  cmd->add_option("--session", a->session,
                  "auto: headless when offered, else (or when headless frames are refused) Vulkan")
      ->check(CLI::IsMember({"auto", "headless", "vulkan"}))
      ->capture_default_str();
  cmd->add_option("--out", a->out,
                  "Calibration file to write (default: $XDG_CONFIG_HOME/proprio/wrist/<hand>_<device>.toml)");
  cmd->add_flag("--force", a->force, "Overwrite --out");
  cmd->callback([a, &exit_code] { exit_code = calibrate_wrist::run(*a); });
}

}  // namespace proprio::cli
