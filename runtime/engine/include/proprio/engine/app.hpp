#pragma once
// The app runtime: a scene, a hand source, the haptics servo loop and the
// renderer wired into one frame loop, with three outputs:
//   xr        an OpenXR session (stereo to an HMD; hands from the runtime's
//             XR_EXT_hand_tracking, e.g. Proprio's layer, or in-process),
//   window    a desktop window with a mouse/keyboard camera,
//   headless  N frames to PNG files from a fixed or orbiting camera.
// `automatic` tries them in that order.
//
// Time: headless runs can step simulated time (a ManualClock the hand source
// also reads), so they are deterministic and faster than real time; the
// haptics loop is then ticked 1000 times per simulated second from the frame
// loop. Otherwise the servo loop runs on its own 1 kHz thread.
//
// Shutdown always disengages the haptic gates and sends zero force, also on
// errors and Ctrl-C (request_stop()).
#include <array>
#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/time.hpp"
#include "proprio/engine/scene.hpp"
#include "proprio/haptics/servo_loop.hpp"

namespace proprio::engine {

enum class OutputMode { automatic, xr, window, headless };
std::string_view to_string(OutputMode mode) noexcept;

// How hands are drawn: `joints` (a sphere per joint, bone cylinders, axis
// triads) or `skinned` (a skinned glTF hand driven by the 26 joints: the hand
// generated from the hand model, or AppOptions::hand_gltf).
enum class HandLook { joints, skinned };
std::string_view to_string(HandLook look) noexcept;
std::optional<HandLook> parse_hand_look(std::string_view s) noexcept;  // "joints", "skinned"

enum class HeadlessCamera {
  head,   // a standing viewer's eyes, looking at the scene's focus
  orbit,  // circling the focus once over the run
};

struct AppOptions {
  OutputMode output = OutputMode::automatic;
  std::uint32_t width = 1280;  // per eye (headless, window); XR uses the runtime's recommended size
  std::uint32_t height = 720;
  bool stereo = true;          // headless: two eyes, written side by side
  double ipd_m = 0.063;
  int frames = 90;             // headless; 0 = until stopped (window, XR)
  double frame_rate_hz = 30.0; // headless
  std::filesystem::path out_dir;  // headless PNGs (frame_0000.png, ...); empty: render without writing
  HeadlessCamera camera = HeadlessCamera::head;
  bool software_renderer = false;  // force lavapipe
#ifdef NDEBUG
  bool validation = false;  // Vulkan validation layer (when installed); debug builds turn it on
#else
  bool validation = true;
#endif
  Handedness hand = Handedness::right;  // the hand that drives the haptic proxy
  bool show_tracked_hand = true;   // the tracked hand as a translucent ghost when a proxy is shown
  HandLook hand_look = HandLook::joints;
  // With hand_look = skinned: a skinned glTF hand whose skin joints carry the
  // OpenXR joint names (docs/engine.md); empty: the hand generated from the
  // hand model (AppInputs::hand_model). Either hand is mirrored for the other side.
  std::filesystem::path hand_gltf;
  bool hud = true;
  std::string describe() const;
  Status validate() const;
};

// A surface whose vertices the app moves every frame (a stretch array's
// reconstructed sheet): its triangles and vertex count are fixed up front,
// FrameContext::surfaces gives the positions.
struct DeformingSurface {
  std::string name;
  std::vector<std::uint32_t> triangles;  // counter-clockwise seen from the outside
  std::size_t vertex_count = 0;
  std::array<float, 4> rgba{0.85f, 0.55f, 0.3f, 1.0f};
};

// Per-frame app logic (a study's protocol) sees the frame's state and decides
// what is shown. The outputs persist from frame to frame unless noted.
struct FrameContext {
  // In.
  TimeNs time_ns = 0;
  int frame = 0;
  Pose T_world_head;                 // this frame's head (headless: the camera; window: the fly camera; XR: VIEW)
  const HandPose* tracked = nullptr; // never null; may be inactive
  const HandPose* proxy = nullptr;   // never null; inactive without haptics
  const haptics::ServoSnapshot* servo = nullptr;  // the newest servo snapshot; null without haptics
  std::vector<std::string> keys;     // keys pressed since the last frame: "a".."z", "0".."9", "space", "enter",
                                     // "left", "right", "up", "down", "backspace" (window only)
  // Out.
  bool show_scene = true;   // entities and floor; false: a black background as well
  bool show_hands = true;   // the tracked and proxy hands
  struct EntityStyle {
    bool visible = true;
    std::array<float, 4> rgba{};  // starts as the scene's colour
    // Drawn here instead of where the scene (or the simulation) puts it. Only
    // the drawing moves: a physics body stays where it is.
    std::optional<Pose> T_world_entity;
  };
  std::vector<EntityStyle> entities;  // one per scene entity, in scene order
  struct Marker {
    enum class Shape { sphere, box, cylinder } shape = Shape::sphere;
    Pose T_world_marker;
    Vec3 size_m = Vec3::Constant(0.01);   // sphere: radius in x; box: half extents; cylinder: radius x, half length z
    std::array<float, 4> rgba{1, 1, 1, 1};
  };
  std::vector<Marker> markers;         // cleared before every call
  // One per AppInputs::surfaces entry: its vertices in the world frame
  // (vertex_count of them, or none to hide it). Persist across frames.
  std::vector<std::vector<Vec3>> surfaces;
  std::string prompt;                  // large centred text for the participant (cleared before every call)
  bool stop = false;                   // end the run after this frame
};

// What the caller wires in. Everything is optional except a scene.
struct AppInputs {
  std::shared_ptr<HandSource> hands;
  // Haptic devices, one per finger; empty: no haptics (the hand is drawn as tracked).
  std::vector<haptics::ServoChannel> haptic_channels;
  haptics::ServoLoopOptions servo_options;
  // The contact simulation behind them (a study scene may need stiffer
  // finger coupling than the default to lift its objects).
  haptics::ContactSimOptions contact_options;
  std::shared_ptr<const HandModel> hand_model;  // for the proxy hand; a default adult hand when null
  // Headless, deterministic: the clock the hand source reads; the app
  // advances it each frame. Null: real time.
  std::shared_ptr<ManualClock> simulated_clock;
  // Called each frame before hands are read, with the frame's time (a
  // source without its own thread produces its sample here).
  std::function<void(TimeNs)> before_frame;
  // Called each frame after the hands and the servo snapshot are read and
  // before drawing.
  std::function<void(FrameContext&)> on_frame;
  // Surfaces the frame hook deforms (FrameContext::surfaces).
  std::vector<DeformingSurface> surfaces;
};

struct AppReport {
  OutputMode output = OutputMode::headless;
  std::string device;  // the Vulkan device
  int frames = 0;
  int frames_with_hand = 0;  // frames with a usable tracked hand (the hand source's, or the runtime's)
  std::vector<std::filesystem::path> images;
  double render_ms_mean = 0, render_ms_p95 = 0, render_ms_max = 0;  // CPU wall time of render + read-back
  double peak_fingertip_force_n = 0;  // after the safety gate, any channel
  haptics::ServoTiming servo;
  bool haptics = false;
  std::string describe() const;
};

class App {
 public:
  static Result<std::unique_ptr<App>> create(Scene scene, AppInputs inputs, AppOptions options);
  ~App();
  App(const App&) = delete;
  App& operator=(const App&) = delete;

  Result<AppReport> run();
  // From any thread or a signal handler: the loop ends after the current frame.
  void request_stop() noexcept { stop_.store(true); }

 private:
  struct Impl;
  explicit App(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  std::atomic<bool> stop_{false};
};

}  // namespace proprio::engine
