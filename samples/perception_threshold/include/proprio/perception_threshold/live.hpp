#pragma once
// The experiment with a real participant, on the engine: an HMD through
// OpenXR, or a desktop window; hands from any source (the runtime's
// XR_EXT_hand_tracking, e.g. Proprio's layer serving VIST or a glove, or an
// in-process source); the contact force to a fingertip device.
//
// The frame hook runs the protocol: it places the scene in the participant's
// head frame on the first tracked frame, runs the familiarisation (Enter ends
// it early), then each trial's adaptation, blind and answer phases, and takes
// the answer from the keyboard: B = blue, R = red, Space = "need another
// look" (the trial is shown again; nothing is recorded). A 1 kHz thread sends
// the contact force of the current haptic sphere through the safety gate.
// Every answer is written and fsync'ed before the next trial starts.
#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "proprio/core/mailbox.hpp"
#include "proprio/engine/app.hpp"
#include "proprio/engine/scene.hpp"
#include "proprio/perception_threshold/protocol.hpp"
#include "proprio/perception_threshold/trial.hpp"

namespace proprio::perception {

// The scene the engine draws: the half cylinder (placed by the hook).
engine::Scene live_scene(const PerceptionProtocol& protocol);

class LiveExperiment {
 public:
  // `channel` may be null (no fingertip device: Experiment 2 then has no cue).
  static Result<std::unique_ptr<LiveExperiment>> create(const PerceptionProtocol& protocol,
                                                        const study::StudyDesign& design,
                                                        const study::SessionOptions& session,
                                                        std::unique_ptr<ForceChannel> channel);
  ~LiveExperiment();  // stops the force thread and zeroes the device

  // The HMD calibration (hmd_calibration): the transform from the graphics
  // frame to the HMD frame; markers are drawn where the participant sees
  // them at the intended place. Identity by default.
  void set_hmd_calibration(const Pose& T_hmd_graphics) { T_hmd_graphics_ = T_hmd_graphics; }
  // The engine's frame hook (AppInputs::on_frame).
  void on_frame(engine::FrameContext& frame);
  // The first error (a failed write ends the run), or success.
  Status status() const;
  int completed_trials() const;
  int planned_trials() const;

 private:
  LiveExperiment() = default;
  void force_loop();
  void on_frame_uncalibrated(engine::FrameContext& frame);
  void start_trial(TimeNs now);

  enum class Stage { waiting_for_hand, familiarisation, trial, answering, done };
  struct HapticTarget {
    bool active = false;
    Vec3 p_centre_in_world = Vec3::Zero();
    Quat q_world_tip = Quat::Identity();
    TimeNs time_ns = 0;
    haptics::HalfCylinderShape cylinder;  // a copy: the force thread shares nothing else with the frame hook
  };

  PerceptionProtocol protocol_;
  study::StudyDesign design_;
  std::optional<study::Session> session_;
  std::unique_ptr<ForceChannel> channel_;
  PlacedScene scene_;
  Pose T_hmd_graphics_;
  Stage stage_ = Stage::waiting_for_hand;
  TimeNs stage_start_ns_ = 0;
  std::optional<study::Trial> trial_;
  TrialPresentation presentation_;
  Cue cue_ = Cue::none;
  TimeNs next_cue_ns_ = 0;
  double peak_force_n_ = 0;
  std::optional<Error> error_;
  Mailbox<HapticTarget> haptic_target_;
  std::atomic<double> felt_force_n_{0.0};
  std::atomic<bool> stop_{false};
  std::thread force_thread_;
};

}  // namespace proprio::perception
