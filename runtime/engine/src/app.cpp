#include "proprio/engine/app.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include "proprio/core/log.hpp"
#include "proprio/render/offscreen_target.hpp"
#include "proprio/render/window_target.hpp"
#include "app_impl.hpp"

namespace proprio::engine {
namespace {

constexpr double kPi = 3.14159265358979323846;

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5))];
}

}  // namespace

std::string_view to_string(OutputMode mode) noexcept {
  switch (mode) {
    case OutputMode::automatic: return "automatic";
    case OutputMode::xr: return "xr";
    case OutputMode::window: return "window";
    case OutputMode::headless: return "headless";
  }
  return "?";
}

std::string_view to_string(HandLook look) noexcept {
  switch (look) {
    case HandLook::joints: return "joints";
    case HandLook::skinned: return "skinned";
  }
  return "?";
}

std::optional<HandLook> parse_hand_look(std::string_view s) noexcept {
  if (s == "joints") return HandLook::joints;
  if (s == "skinned") return HandLook::skinned;
  return std::nullopt;
}

std::string AppOptions::describe() const {
  return fmt::format("app: output {}, {}x{} per eye, {}, {} frames at {} Hz (headless), camera {}, renderer {}, "
                     "validation {}, haptic hand {}, hands drawn as {}{}, out '{}'",
                     to_string(output), width, height, stereo ? "stereo" : "mono", frames, frame_rate_hz,
                     camera == HeadlessCamera::head ? "head" : "orbit", software_renderer ? "lavapipe" : "automatic",
                     validation ? "on" : "off", to_string(hand), to_string(hand_look),
                     hand_gltf.empty() ? std::string() : " from '" + hand_gltf.string() + "'", out_dir.string());
}

Status AppOptions::validate() const {
  if (width < 16 || height < 16 || width > 8192 || height > 8192) {
    return make_error(Errc::invalid_argument, fmt::format("image size {}x{} is out of range (16-8192)", width, height));
  }
  if (frames < 0) return make_error(Errc::invalid_argument, "frames must be >= 0");
  if (!(frame_rate_hz > 0 && frame_rate_hz <= 1000)) {
    return make_error(Errc::invalid_argument, "frame rate must be in (0, 1000] Hz");
  }
  if (!(ipd_m >= 0 && ipd_m < 0.2)) return make_error(Errc::invalid_argument, "ipd must be in [0, 0.2) m");
  if (!hand_gltf.empty() && hand_look != HandLook::skinned) {
    return make_error(Errc::invalid_argument, fmt::format("a glTF hand ('{}') is drawn only with the skinned hand look, "
                                                          "but the hand look is '{}'", hand_gltf.string(),
                                                          to_string(hand_look)));
  }
  return {};
}

std::string AppReport::describe() const {
  std::string s = fmt::format("{} frames ({}) on {}; render {:.1f} ms mean, {:.1f} ms p95, {:.1f} ms max", frames,
                              to_string(output), device, render_ms_mean, render_ms_p95, render_ms_max);
  s += fmt::format("; tracked hand in {} of them", frames_with_hand);
  if (haptics) {
    s += fmt::format("; haptics: peak fingertip force {:.2f} N, {}", peak_fingertip_force_n, servo.describe());
  }
  if (!images.empty()) s += fmt::format("; {} images, the last {}", images.size(), images.back().string());
  return s;
}

Status App::Impl::build_servo() {
  if (inputs.haptic_channels.empty()) return {};
  auto sim = haptics::ContactSimulation::create(*hand_model, options.hand, scene.haptic_scene(), inputs.contact_options);
  if (!sim) return sim.error().with_context("building the contact simulation for scene '" + scene.name + "'");
  // Start the proxy where the tracked hand is, or above the focus.
  Pose T_world_wrist{Quat::Identity(), scene.p_focus_in_world + Vec3(0, 0.25, 0.15)};
  HandAngles angles{};
  if (inputs.hands) {
    const TimeNs now = inputs.simulated_clock ? inputs.simulated_clock->now_ns() : MonotonicClock::instance().now_ns();
    if (auto pose = inputs.hands->pose_at(options.hand, now); pose && pose->active) {
      const auto ik = hand_model->inverse(*pose);
      T_world_wrist = pose->joint(HandJoint::wrist);
      angles = ik.angles;
    }
  }
  sim->reset_hand(T_world_wrist, angles);
  auto loop = haptics::ServoLoop::create(std::move(*sim), inputs.haptic_channels, inputs.servo_options);
  if (!loop) return loop.error();
  servo = std::move(*loop);
  entity_free_object.assign(scene.entities.size(), -1);
  for (std::size_t i = 0; i < scene.entities.size(); ++i) {
    if (scene.entities[i].physics != Physics::free) continue;
    for (std::size_t k = 0; k < servo->simulation().free_object_count(); ++k) {
      if (servo->simulation().free_object_name(k) == scene.entities[i].body.name) entity_free_object[i] = static_cast<int>(k);
    }
  }
  return {};
}

void App::Impl::read_hands(TimeNs t) {
  if (!inputs.hands) return;
  const PoseLookup r = inputs.hands->lookup(options.hand, t, tracked);
  if (is_usable(r)) ++frames_with_hand;
  if (is_usable(r) && servo && servo->running()) servo->submit_tracked_hand(tracked);
  if (!is_usable(r) && r != PoseLookup::stale) tracked.active = false;
}

void App::Impl::step_haptics_to(TimeNs from, TimeNs to) {
  if (!servo) return;
  // On a fixed 1 ms grid from the first frame, so frames that are not a
  // whole number of milliseconds long do not drop ticks.
  if (next_tick_ns == 0) next_tick_ns = from + kNsPerMillisecond;
  for (; next_tick_ns <= to; next_tick_ns += kNsPerMillisecond) {
    if (inputs.hands && is_usable(inputs.hands->lookup(options.hand, next_tick_ns, tracked))) {
      servo->submit_tracked_hand(tracked);
    }
    servo->tick(next_tick_ns);
  }
  // Free bodies move; read them while no thread owns the simulation.
  for (std::size_t i = 0; i < scene.entities.size(); ++i) {
    if (scene.entities[i].physics == Physics::free) {
      if (auto p = servo->simulation().object_pose(scene.entities[i].body.name)) entity_poses[i] = *p;
    }
  }
}

void App::Impl::read_servo_snapshot() {
  if (!servo) return;
  const haptics::ServoSnapshot* snap = servo->latest();
  if (!snap) return;
  proxy = snap->hands[0].proxy;
  // Free bodies move in live runs too: the servo thread publishes their poses.
  for (std::size_t i = 0; i < entity_free_object.size() && i < entity_poses.size(); ++i) {
    const int k = entity_free_object[i];
    if (k >= 0 && static_cast<std::size_t>(k) < snap->object_count) entity_poses[i] = snap->object_poses[static_cast<std::size_t>(k)];
  }
  double force = 0;
  std::string gate = "off";
  for (std::size_t c = 0; c < snap->channel_count; ++c) {
    const auto& ch = snap->channels[c];
    force = std::max(force, ch.commanded.normal_n);
    gate = std::string(haptics::to_string(ch.gate));
  }
  peak_force_n = std::max(peak_force_n, force);
  hud_status = fmt::format("fingertip force {:.2f} N (gate {})", force, gate);
}

void App::Impl::run_frame_hook(TimeNs t, int frame, const Pose& T_world_head, std::vector<std::string> keys) {
  if (!inputs.on_frame) return;
  FrameContext& c = frame_context;
  c.time_ns = t;
  c.frame = frame;
  c.T_world_head = T_world_head;
  c.tracked = &tracked;
  c.proxy = &proxy;
  c.servo = servo ? servo->latest() : nullptr;
  c.keys = std::move(keys);
  c.markers.clear();
  c.prompt.clear();
  inputs.on_frame(c);
  if (c.stop) stop->store(true);
}

void App::Impl::compose(render::DrawList& draws, const SceneDrawer& drawer, double t_s, std::uint32_t width,
                        std::uint32_t height) {
  draws.clear();
  const FrameContext& c = frame_context;
  draws.clear_color = c.show_scene ? glm::vec4(0.08f, 0.09f, 0.11f, 1.0f) : glm::vec4(0, 0, 0, 1);
  if (c.show_scene) drawer.append_scene(draws, entity_poses, c.entities);
  if (c.show_hands) {
    const bool proxy_shown = servo && proxy.active;
    if (proxy_shown) drawer.append_hand(draws, proxy, false);
    if (tracked.active && (!proxy_shown || options.show_tracked_hand)) drawer.append_hand(draws, tracked, proxy_shown);
  }
  for (const auto& m : c.markers) drawer.append_marker(draws, m);
  for (std::size_t i = 0; i < c.surfaces.size(); ++i) drawer.append_surface(draws, i, c.surfaces[i]);
  if (!c.prompt.empty()) {
    // stb_easy_font glyphs are about 6 px wide at scale 1.
    constexpr float scale = 3.0f;
    std::size_t longest = 0, line = 0;
    for (char ch : c.prompt) {
      line = ch == '\n' ? 0 : line + 1;
      longest = std::max(longest, line);
    }
    const float x = std::max(8.0f, 0.5f * static_cast<float>(width) - 3.0f * scale * static_cast<float>(longest));
    draws.hud.push_back({c.prompt, {x, 0.35f * static_cast<float>(height)}, scale, {1, 1, 0.85f, 1}, true});
  }
  if (options.hud) {
    draws.hud.push_back({fmt::format("Proprio  {}  t = {:.2f} s{}{}", scene.name, t_s, hud_status.empty() ? "" : "\n",
                                     hud_status),
                         {16.0f, 16.0f}, 2.0f, {1, 1, 1, 1}, true});
  }
}

Pose App::Impl::head_pose(int frame) const {
  const Vec3& focus = scene.p_focus_in_world;
  if (options.camera == HeadlessCamera::orbit && options.frames > 0) {
    const double a = 2 * kPi * frame / options.frames;
    return render::look_at(focus + Vec3(0.45 * std::sin(a), 0.28, 0.45 * std::cos(a)), focus);
  }
  return render::look_at(focus + Vec3(0.0, 0.28, 0.38), focus);
}

void App::Impl::shutdown_haptics() {
  if (!servo) return;
  servo->stop();  // disengages every gate and sends zero force
  const TimeNs now = inputs.simulated_clock ? inputs.simulated_clock->now_ns() : MonotonicClock::instance().now_ns();
  servo->disengage_and_zero(now);
}

AppReport App::Impl::report(OutputMode mode, const std::string& device, int frames) const {
  AppReport r;
  r.output = mode;
  r.device = device;
  r.frames = frames;
  r.frames_with_hand = frames_with_hand;
  double sum = 0;
  for (double v : render_ms) sum += v;
  r.render_ms_mean = render_ms.empty() ? 0 : sum / static_cast<double>(render_ms.size());
  r.render_ms_p95 = percentile(render_ms, 0.95);
  r.render_ms_max = render_ms.empty() ? 0 : *std::max_element(render_ms.begin(), render_ms.end());
  r.peak_fingertip_force_n = peak_force_n;
  r.haptics = servo != nullptr;
  if (servo) r.servo = servo->timing();
  return r;
}

Result<AppReport> App::Impl::run_headless() {
  const HapticsOffOnExit haptics_off{*this};
  render::ContextOptions co;
  co.device = options.software_renderer ? render::DevicePreference::software : render::DevicePreference::automatic;
  co.validation = options.validation;
  auto ctx = render::VulkanContext::create(co);
  if (!ctx) return ctx.error();
  auto renderer = render::Renderer::create(**ctx);
  if (!renderer) return renderer.error();
  auto drawer = SceneDrawer::create(**renderer, scene, options, *hand_model, inputs.surfaces);
  if (!drawer) return drawer.error();
  const std::uint32_t eyes = options.stereo ? 2 : 1;
  auto target = render::OffscreenTarget::create(**renderer, options.width, options.height, eyes);
  if (!target) return target.error();
  if (!options.out_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(options.out_dir, ec);
    if (ec) return make_error(Errc::io_error, "cannot create '" + options.out_dir.string() + "': " + ec.message());
  }

  const bool simulated = inputs.simulated_clock != nullptr;
  if (servo) {
    const TimeNs now = simulated ? inputs.simulated_clock->now_ns() : MonotonicClock::instance().now_ns();
    if (simulated) {
      servo->engage(now);
    } else if (auto s = servo->start(); !s) {
      return s.error();
    }
  }
  const render::Fov fov = render::symmetric_fov(static_cast<float>(60.0 * kPi / 180.0),
                                                static_cast<float>(options.width) / static_cast<float>(options.height));
  const auto frame_ns = static_cast<DurationNs>(1e9 / options.frame_rate_hz);
  const TimeNs start = simulated ? inputs.simulated_clock->now_ns() : MonotonicClock::instance().now_ns();
  render::DrawList draws;
  render::ImageRGBA8 eye_image, sheet;
  AppReport result;
  int frame = 0;
  TimeNs previous = start;
  for (; frame < options.frames && !stop->load(); ++frame) {
    const TimeNs t = start + frame * frame_ns;
    if (simulated) {
      inputs.simulated_clock->set(t);
    } else {
      std::this_thread::sleep_until(std::chrono::steady_clock::time_point(std::chrono::nanoseconds(t)));
    }
    if (inputs.before_frame) inputs.before_frame(t);
    if (simulated) {
      step_haptics_to(previous, t);
    }
    previous = t;
    read_hands(t);
    read_servo_snapshot();
    const Pose T_world_head = head_pose(frame);
    run_frame_hook(t, frame, T_world_head, {});
    compose(draws, *drawer, static_cast<double>(t - start) * 1e-9, options.width, options.height);
    std::array<render::View, 2> views{};
    if (options.stereo) {
      views = render::stereo_views(T_world_head, static_cast<float>(options.ipd_m), fov);
    } else {
      views[0] = {T_world_head, fov};
    }
    const auto t0 = std::chrono::steady_clock::now();
    if (auto s = (*renderer)->render(draws, std::span(views.data(), eyes), (*target)->views()); !s) {
      return s.error();
    }
    // Timed: rendering and read-back (what a frame costs), not PNG encoding.
    const bool write = !options.out_dir.empty();
    sheet.width = options.width * eyes;
    sheet.height = options.height;
    sheet.pixels.resize(std::size_t{sheet.width} * sheet.height * 4);
    for (std::uint32_t e = 0; e < eyes && write; ++e) {
      if (auto s = (*target)->read(e, eye_image); !s) {
        return s.error();
      }
      for (std::uint32_t y = 0; y < options.height; ++y) {
        std::copy_n(eye_image.at(0, y), std::size_t{options.width} * 4, sheet.at(e * options.width, y));
      }
    }
    if (!write) {
      if (auto s = (*renderer)->wait_idle(); !s) {
        return s.error();
      }
    }
    render_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (write) {
      const auto file = options.out_dir / fmt::format("frame_{:04d}.png", frame);
      if (auto s = render::write_png(sheet, file); !s) {
        return s.error();
      }
      result.images.push_back(file);
    }
  }
  shutdown_haptics();
  auto images = std::move(result.images);
  result = report(OutputMode::headless, (*ctx)->describe(), frame);
  result.images = std::move(images);
  if ((*ctx)->validation_errors() > 0) {
    return make_error(Errc::io_error, fmt::format("{} Vulkan validation errors; first: {}", (*ctx)->validation_errors(),
                                                  (*ctx)->validation_messages().front()));
  }
  return result;
}

Result<AppReport> App::Impl::run_window() {
  const HapticsOffOnExit haptics_off{*this};
  auto window = render::Window::create("Proprio: " + scene.name, static_cast<int>(options.width),
                                       static_cast<int>(options.height));
  if (!window) return window.error();
  render::ContextOptions co;
  co.device = options.software_renderer ? render::DevicePreference::software : render::DevicePreference::automatic;
  co.validation = options.validation;
  co.instance_extensions = (*window)->required_instance_extensions();
  co.swapchain = true;
  auto ctx = render::VulkanContext::create(co);
  if (!ctx) return ctx.error();
  auto renderer = render::Renderer::create(**ctx);
  if (!renderer) return renderer.error();
  auto drawer = SceneDrawer::create(**renderer, scene, options, *hand_model, inputs.surfaces);
  if (!drawer) return drawer.error();
  auto target = render::WindowTarget::create(**renderer, **window);
  if (!target) return target.error();
  if (servo) {
    if (auto s = servo->start(); !s) return s.error();
  }
  // A fly camera starting at the standing viewer's eyes.
  Pose camera = head_pose(0);
  double yaw = 0, pitch = 0;
  {
    const Vec3 f = camera.q * Vec3(0, 0, -1);
    yaw = std::atan2(-f.x(), -f.z());
    pitch = std::asin(std::clamp(f.y(), -1.0, 1.0));
  }
  render::DrawList draws;
  const TimeNs start = MonotonicClock::instance().now_ns();
  auto last = std::chrono::steady_clock::now();
  int frame = 0;
  while (!(*window)->should_close() && !stop->load() && (options.frames == 0 || frame < options.frames)) {
    const auto now_wall = std::chrono::steady_clock::now();
    const double dt = std::chrono::duration<double>(now_wall - last).count();
    last = now_wall;
    const render::WindowInput in = (*window)->poll();
    yaw -= in.look_dx_px * 0.004;
    pitch = std::clamp(pitch - in.look_dy_px * 0.004, -1.5, 1.5);
    camera.q = Quat(Eigen::AngleAxisd(yaw, Vec3::UnitY()) * Eigen::AngleAxisd(pitch, Vec3::UnitX()));
    const double speed = (in.fast ? 2.0 : 0.5) * dt;
    camera.p += camera.q * Vec3(in.move_right * speed, 0, -in.move_forward * speed) + Vec3(0, in.move_up * speed, 0);

    const TimeNs t = MonotonicClock::instance().now_ns();
    if (inputs.before_frame) inputs.before_frame(t);
    read_hands(t);
    read_servo_snapshot();
    run_frame_hook(t, frame, camera, in.keys_pressed);
    compose(draws, *drawer, static_cast<double>(t - start) * 1e-9, (*target)->extent().width,
            (*target)->extent().height);
    if (options.hud) draws.hud.push_back({"drag: look   W/A/S/D/Q/E: move   shift: fast   Esc: quit",
                                          {16.0f, static_cast<float>((*target)->extent().height) - 40.0f}, 1.5f,
                                          {0.8f, 0.8f, 0.8f, 1}, true});
    auto f = (*target)->acquire();
    if (!f) {
      return f.error();
    }
    const VkExtent2D extent = (*target)->extent();
    const render::View view{camera, render::symmetric_fov(static_cast<float>(60.0 * kPi / 180.0),
                                                          static_cast<float>(extent.width) /
                                                              static_cast<float>(std::max(1u, extent.height)))};
    const auto t0 = std::chrono::steady_clock::now();
    if (auto s = (*renderer)->render(draws, std::span(&view, 1), std::span(&f->target, 1), f->sync); !s) {
      return s.error();
    }
    if (auto s = (*target)->present(*f); !s) {
      return s.error();
    }
    render_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    ++frame;
  }
  (void)(*renderer)->wait_idle();
  shutdown_haptics();
  return report(OutputMode::window, (*ctx)->describe(), frame);
}

App::App(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) { impl_->stop = &stop_; }

App::~App() {
  if (impl_) impl_->shutdown_haptics();
}

Result<std::unique_ptr<App>> App::create(Scene scene, AppInputs inputs, AppOptions options) {
  if (auto s = options.validate(); !s) return s.error();
  if (auto s = scene.validate(); !s) return s.error();
  auto impl = std::make_unique<Impl>();
  impl->scene = std::move(scene);
  impl->inputs = std::move(inputs);
  impl->options = options;
  impl->hand_model = impl->inputs.hand_model;
  if (!impl->hand_model) {
    auto shape = HandShape::from_measurements(0.19, 0.09);
    if (!shape) return shape.error();
    impl->hand_model = std::make_shared<const HandModel>(*shape);
  }
  for (const Entity& e : impl->scene.entities) {
    impl->entity_poses.push_back(e.body.T_world_object);
    impl->frame_context.entities.push_back({true, e.body.rgba});
  }
  if (auto s = impl->build_servo(); !s) return s.error();
  return std::unique_ptr<App>(new App(std::move(impl)));
}

Result<AppReport> App::run() {
  Impl& m = *impl_;
  switch (m.options.output) {
    case OutputMode::headless: return m.run_headless();
    case OutputMode::window: return m.run_window();
    case OutputMode::xr: return m.run_xr();
    case OutputMode::automatic: break;
  }
  // Automatic: an HMD if an OpenXR runtime has one, else a window if there is
  // a display, else headless.
  if (xr_runtime_available()) {
    auto r = m.run_xr();
    if (r || r.error().code != Errc::unavailable) return r;
    logger().info("OpenXR: {}; trying a window", r.error().message);
  }
  auto w = m.run_window();
  if (w || w.error().code != Errc::unavailable) return w;
  logger().info("window: {}; rendering headless", w.error().message);
  return m.run_headless();
}

}  // namespace proprio::engine
