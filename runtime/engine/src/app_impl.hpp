#pragma once
// App internals shared by the frame loops (app.cpp: headless and window;
// xr_session.cpp: OpenXR).
#include <atomic>
#include <string>
#include <vector>

#include "proprio/engine/app.hpp"
#include "proprio/render/renderer.hpp"
#include "scene_drawer.hpp"

namespace proprio::engine {

struct App::Impl {
  Scene scene;
  AppInputs inputs;
  AppOptions options;
  std::atomic<bool>* stop = nullptr;
  std::shared_ptr<const HandModel> hand_model;
  std::unique_ptr<haptics::ServoLoop> servo;
  std::vector<Pose> entity_poses;
  // Per entity: its index among the simulation's free objects (the servo
  // snapshot's object_poses), or -1.
  std::vector<int> entity_free_object;
  HandPose tracked;
  int frames_with_hand = 0;  // frames whose hand source gave a usable pose
  HandPose proxy;
  std::string hud_status;
  double peak_force_n = 0;
  std::vector<double> render_ms;
  TimeNs next_tick_ns = 0;  // simulated time: the servo's next tick
  FrameContext frame_context;  // the frame hook's state (entity styles persist across frames)

  Status build_servo();
  void read_hands(TimeNs t);
  void step_haptics_to(TimeNs from, TimeNs to);
  void read_servo_snapshot();
  // Runs inputs.on_frame (when set) for this frame.
  void run_frame_hook(TimeNs t, int frame, const Pose& T_world_head, std::vector<std::string> keys);
  // `width`/`height`: the view's pixels, for centring the participant prompt.
  void compose(render::DrawList& draws, const SceneDrawer& drawer, double t_s, std::uint32_t width,
               std::uint32_t height);
  Pose head_pose(int frame) const;
  Result<AppReport> run_headless();
  Result<AppReport> run_window();
  Result<AppReport> run_xr();
  AppReport report(OutputMode mode, const std::string& device, int frames) const;
  void shutdown_haptics();

  // Every way out of a frame loop (errors included) stops haptic output;
  // shutdown_haptics() is idempotent.
  struct HapticsOffOnExit {
    Impl& app;
    ~HapticsOffOnExit() { app.shutdown_haptics(); }
  };
};


// True when an OpenXR loader finds a runtime (XR_RUNTIME_JSON or the system's
// active_runtime.json), without creating a session.
bool xr_runtime_available();

}  // namespace proprio::engine
