// proprio xr-probe: the OpenXR probe (proprio::engine, xr_probe.hpp) with its
// report printed once a second, and its outcome as the exit status.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>

#include "commands.hpp"
#include "proprio/core/log.hpp"
#include "xr_loader_paths.hpp"
#ifdef PROPRIO_HAVE_ENGINE
#include "proprio/engine/xr_probe.hpp"
#endif

namespace proprio::cli {

namespace {

// Exit statuses, also listed in --help.
constexpr int kExitOk = 0;
constexpr int kExitError = 1;
constexpr int kExitNoHandTracking = 2;
constexpr int kExitNeverActive = 3;  // --haptics: a finger failed its press

struct ProbeArgs {
  double seconds = 5.0;
  std::string space = "view";
  std::string hand = "both";
  std::string session = "auto";  // auto | headless | vulkan
  bool enable_layer = false;
  bool data_source = false;
  bool haptics = false;
};

#ifdef PROPRIO_HAVE_ENGINE
using engine::XrProbeSessionKind;

double percent(std::uint64_t part, std::uint64_t whole) {
  return whole ? 100.0 * static_cast<double>(part) / static_cast<double>(whole) : 0.0;
}

// Prints one event of the probe's report.
struct ProbePrinter {
  const ProbeArgs& args;

  void operator()(const engine::XrProbeDataSourceNotOffered&) const {
    std::printf("(--data-source: XR_EXT_hand_tracking_data_source is not offered; continuing without it)\n");
  }
  void operator()(const engine::XrProbeRuntime& r) const {
    std::printf("Runtime: %s %u.%u.%u\n", r.name.c_str(), r.version_major, r.version_minor, r.version_patch);
  }
  void operator()(const engine::XrProbeSystem& s) const {
    std::printf("System: %s (vendor %u)\n", s.name.c_str(), s.vendor_id);
    if (!args.haptics) std::printf("supportsHandTracking: %s\n", s.supports_hand_tracking ? "true" : "false");
    if (s.data_source_enabled) std::printf("XR_EXT_hand_tracking_data_source: enabled\n");
  }
  void operator()(const engine::XrProbeHeadlessRefused& h) const {
    std::printf(
        "The runtime refuses frames in headless sessions (%s), as Monado does: starting again with a "
        "Vulkan graphics binding, as hello_xr -g Vulkan2 does.\n",
        h.refused_call.c_str());
    std::fflush(stdout);
  }
  void operator()(const engine::XrProbeSessionStarted& s) const {
    const char* kind = s.kind == XrProbeSessionKind::headless ? "headless (XR_MND_headless)"
                                                              : "Vulkan graphics binding (XR_KHR_vulkan_enable2)";
    const std::string device = s.device.empty() ? "" : " on " + s.device;
    if (args.haptics) {
      std::printf("Session: %s%s; checking the fingertip devices (XR_PROPRIO_fingertip_haptics).\n\n", kind,
                  device.c_str());
    } else {
      std::printf("Session: %s%s; locating %s hand joints in %s space.\n\n", kind, device.c_str(), args.hand.c_str(),
                  args.space.c_str());
    }
    std::fflush(stdout);
  }
  void operator()(const engine::XrProbeZeroDisplayTime&) const {
    std::printf("(the runtime's predictedDisplayTime is 0: locating at the current time)\n");
  }
  void operator()(const engine::XrProbeSecond& second) const {
    for (const auto& h : second.hands) {
      const std::string name(engine::to_string(h.hand));
      std::printf("t=%5.1f s %-5s %s", second.t_s, name.c_str(), h.active ? "active  " : "INACTIVE");
      if (h.active) {
        const Vec3 wrist_mm = h.wrist_m * 1e3, tip_mm = h.index_tip_m * 1e3;
        const Quat& q = h.palm_orientation;
        std::printf(" wrist (%7.1f %7.1f %7.1f) mm  index tip (%7.1f %7.1f %7.1f) mm\n", wrist_mm.x(), wrist_mm.y(),
                    wrist_mm.z(), tip_mm.x(), tip_mm.y(), tip_mm.z());
        std::printf("                 palm q(xyzw) (%6.3f %6.3f %6.3f %6.3f), faces (%5.2f %5.2f %5.2f)", q.x(), q.y(),
                    q.z(), q.w(), h.palm_faces.x(), h.palm_faces.y(), h.palm_faces.z());
        if (h.index_tip_speed_m_s) std::printf(", index tip speed %.3f m/s", *h.index_tip_speed_m_s);
        if (h.data_source_controller)
          std::printf(", source %s", *h.data_source_controller ? "controller" : "unobstructed");
        std::printf("\n                ");
      }
      std::printf(" joints fully tracked %5.1f%%, locate %6.1f Hz, distinct data %6.1f Hz\n",
                  percent(h.window.fully_tracked_joints, h.window.joints),
                  static_cast<double>(h.window.locates) / second.window_s,
                  static_cast<double>(h.window.distinct) / second.window_s);
    }
    std::fflush(stdout);
  }
  void operator()(const engine::XrProbeHapticsDevices& d) const {
    std::printf("Fingertip devices:\n");
    for (const auto& f : d.fingers) {
      std::printf("  %-5s %-6s %-32s %s, %u DoF, max normal %.2f N, max shear %.2f N\n",
                  std::string(engine::to_string(f.hand)).c_str(), f.finger.c_str(), f.device.c_str(),
                  f.connected ? "connected" : "NOT CONNECTED", f.force_dofs, f.max_normal_n, f.max_shear_n);
    }
    for (engine::XrProbeHand hand : {engine::XrProbeHand::left, engine::XrProbeHand::right}) {
      std::string names;
      for (const auto& [h, finger] : d.absent) {
        if (h == hand) names += (names.empty() ? "" : ", ") + finger;
      }
      if (!names.empty()) std::printf("  %-5s no device: %s\n", std::string(engine::to_string(hand)).c_str(), names.c_str());
    }
    std::printf("Waiting for the session to be FOCUSED and the devices' gates to ramp in...\n");
    std::fflush(stdout);
  }
  void operator()(const engine::XrProbeHapticsReady& r) const {
    std::printf("FOCUSED after %.2f s, gates %s after %.2f s more.\n", r.waited_for_focus_s,
                r.all_gates_active ? "active" : "NOT ALL ACTIVE", r.waited_for_gates_s);
    std::printf("Pressing each with %.2f N (+Y, fingertip frame) for 0.3 s, then releasing:\n",
                engine::xr_probe_haptics_press_n());
    std::fflush(stdout);
  }
  void operator()(const engine::XrProbeSummary& s) const {
    if (args.haptics) return;  // the presses are the summary
    if (s.interrupted) std::printf("\nInterrupted.\n");
    std::printf("\nSummary over %.1f s, %llu frames, %s session:\n", s.run_s, static_cast<unsigned long long>(s.frames),
                s.kind == XrProbeSessionKind::headless ? "headless" : "Vulkan");
    for (const auto& [hand, t] : s.hands) {
      const std::string name(engine::to_string(hand));
      std::printf("  %-5s active in %llu of %llu locates, joints fully tracked %.1f%%, distinct data %.1f Hz\n",
                  name.c_str(), static_cast<unsigned long long>(t.active), static_cast<unsigned long long>(t.locates),
                  percent(t.fully_tracked_joints, t.joints),
                  s.run_s > 0 ? static_cast<double>(t.distinct) / s.run_s : 0.0);
    }
    for (const auto& [hand, l] : s.latency) print_latency(std::string(engine::to_string(hand)), l);
    std::fflush(stdout);
  }
  // p50/p99/max and a text histogram (the bins up to the p99.9 one, grouped to at most 16 rows).
  static void print_latency(const std::string& hand, const engine::XrProbeLatency& l) {
    using engine::XrProbeLatency;
    std::printf("\n  %s hand: data age behind %llu served poses (XR_PROPRIO_hand_tracking_latency)\n", hand.c_str(),
                static_cast<unsigned long long>(l.poses));
    if (l.poses == 0) {
      std::printf("    none served: no latency to report\n");
      return;
    }
    const struct {
      const char* label;
      const std::vector<std::uint64_t>& bins;
      double max_ms;
    } rows[] = {{"sensor sample -> pose servable", l.sample_to_ready, l.max_sample_to_ready_ms},
                {"sensor sample -> xrLocateHandJointsEXT", l.age_at_locate, l.max_age_at_locate_ms}};
    for (const auto& r : rows) {
      std::printf("    %-40s p50 <= %.1f ms, p99 <= %.1f ms, max %.2f ms\n", r.label,
                  XrProbeLatency::quantile_ms(r.bins, l.bin_ms, 0.5), XrProbeLatency::quantile_ms(r.bins, l.bin_ms, 0.99),
                  r.max_ms);
    }
    const auto& bins = l.age_at_locate;
    const double upto_ms = XrProbeLatency::quantile_ms(bins, l.bin_ms, 0.999);
    const std::size_t last = std::min(bins.size(), static_cast<std::size_t>(std::ceil(upto_ms / l.bin_ms)));
    const std::size_t group = std::max<std::size_t>(1, (last + 15) / 16);
    std::uint64_t biggest = 1, total = 0;
    for (std::size_t i = 0; i < last; i += group) {
      std::uint64_t c = 0;
      for (std::size_t j = i; j < std::min(last, i + group); ++j) c += bins[j];
      biggest = std::max(biggest, c);
    }
    for (auto c : bins) total += c;
    std::printf("    sensor sample -> xrLocateHandJointsEXT, histogram:\n");
    for (std::size_t i = 0; i < last; i += group) {
      std::uint64_t c = 0;
      for (std::size_t j = i; j < std::min(last, i + group); ++j) c += bins[j];
      const int width = static_cast<int>(std::lround(40.0 * static_cast<double>(c) / static_cast<double>(biggest)));
      std::printf("    %5.1f-%5.1f ms %6.2f%% %s\n", static_cast<double>(i) * l.bin_ms,
                  static_cast<double>(std::min(last, i + group)) * l.bin_ms,
                  100.0 * static_cast<double>(c) / static_cast<double>(total), std::string(static_cast<std::size_t>(width), '#').c_str());
    }
  }
};

int run_haptics_check(const engine::XrProbeOptions& options, const ProbeArgs& a) {
  const ProbePrinter printer{a};
  auto result =
      engine::run_xr_probe_haptics(options, [&](const engine::XrProbeEvent& e) { std::visit(printer, e); });
  if (!result) {
    if (!result.error().message.empty()) logger().error("{}", result.error().message);
    return result.error().code == Errc::unsupported ? kExitNoHandTracking : kExitError;
  }
  int failed = 0;
  for (const auto& f : *result) {
    const auto after = [](const std::optional<double>& s) {
      return s ? fmt::format("after {:.0f} ms", *s * 1e3) : std::string("NOT within 0.2 s");
    };
    std::printf("  %-5s %-6s commanded %.2f N, measured %.2f N, released %s (measured below 0.01 N %s): %s\n",
                std::string(engine::to_string(f.hand)).c_str(), f.finger.c_str(), f.peak_commanded_n,
                f.peak_measured_n, after(f.released_after_s).c_str(), after(f.measured_released_after_s).c_str(),
                f.passed() ? "ok" : "FAILED");
    failed += !f.passed();
  }
  if (failed) {
    std::printf("%d of %zu fingertip devices FAILED: check the layer's log, the device's cable and its model "
                "('proprio haptics devices', docs/xr-proprio-fingertip-haptics.md).\n", failed, result->size());
    return kExitNeverActive;
  }
  std::printf("All %zu fingertip devices pressed and released.\n", result->size());
  return kExitOk;
}

int run_xr_probe(const ProbeArgs& a) {
  engine::XrProbeOptions options;
  options.duration_s = a.seconds;
  options.space = a.space == "local"   ? engine::XrProbeSpace::local
                  : a.space == "stage" ? engine::XrProbeSpace::stage
                                       : engine::XrProbeSpace::view;
  options.hands = a.hand == "left"    ? engine::XrProbeHands::left
                  : a.hand == "right" ? engine::XrProbeHands::right
                                      : engine::XrProbeHands::both;
  options.session = a.session == "headless" ? engine::XrProbeSession::headless
                    : a.session == "vulkan" ? engine::XrProbeSession::vulkan
                                            : engine::XrProbeSession::automatic;
  if (a.enable_layer) options.api_layer = xr::kLayerName;
  options.data_source = a.data_source;
  options.stop = &g_sigint_stop;

  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  if (a.haptics) {
    const int rc = run_haptics_check(options, a);
    std::signal(SIGINT, previous);
    return rc;
  }
  const ProbePrinter printer{a};
  auto result = engine::run_xr_probe(options, [&](const engine::XrProbeEvent& e) { std::visit(printer, e); });
  std::signal(SIGINT, previous);
  if (!result) {
    // An empty message: stopped before the session started, nothing to add.
    if (!result.error().message.empty()) logger().error("{}", result.error().message);
    return result.error().code == engine::kXrProbeNoHandTracking ? kExitNoHandTracking : kExitError;
  }
  if (!result->any_active()) {
    std::printf(
        "No hand was ever active. If Proprio's layer is meant to serve hands, check 'proprio layer status' "
        "and the app's log for the layer's messages.\n");
    return kExitNeverActive;
  }
  return kExitOk;
}
#else
int run_xr_probe(const ProbeArgs&) {
  logger().error("this build of proprio has no engine (proprio::engine), which runs xr-probe's OpenXR session");
  return kExitError;
}
#endif

}  // namespace

void add_xr_probe_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ProbeArgs>();
  CLI::App* cmd = add_command(app, "xr-probe");
  cmd->add_option("--seconds", args->seconds, "How long to run, s")->check(CLI::Range(0.0, 24.0 * 3600.0))->capture_default_str();
  cmd->add_option("--space", args->space, "Reference space to locate the joints in")
      ->check(CLI::IsMember({"view", "local", "stage"}))
      ->capture_default_str();
  cmd->add_option("--hand", args->hand, "Which hand trackers to create")
      ->check(CLI::IsMember({"left", "right", "both"}))
      ->capture_default_str();
  cmd->add_option("--session", args->session,
                  "auto: headless when offered, else (or when the runtime refuses headless frames) a Vulkan graphics "
                  "binding; headless or vulkan: only that kind")
      ->check(CLI::IsMember({"auto", "headless", "vulkan"}))
      ->capture_default_str();
  cmd->add_flag("--enable-layer", args->enable_layer,
                "Enable XR_APILAYER_PROPRIO_hand_tracking from the app side (enabledApiLayerNames), as an app "
                "could, for an explicit install without XR_ENABLE_API_LAYERS");
  cmd->add_flag("--data-source", args->data_source,
                "Also enable XR_EXT_hand_tracking_data_source when offered, and report each hand's data source "
                "(Debian's 1.0.20 core_validation layer rejects this extension's structs)");
  cmd->add_flag("--haptics", args->haptics,
                "Check the fingertip devices behind XR_PROPRIO_fingertip_haptics instead of the hands: list both "
                "hands' devices, wait for the session to be FOCUSED, press each with 0.5 N (+Y in the fingertip "
                "frame) for 0.3 s and report the peak force the layer commanded and the device measured, and whether "
                "each fell below 0.01 N within 0.2 s (exit 3 if a device failed, 2 without the extension or devices, "
                "1 on any other error such as no focus)");
  cmd->callback([args, &exit_code] { exit_code = run_xr_probe(*args); });
}

}  // namespace proprio::cli
