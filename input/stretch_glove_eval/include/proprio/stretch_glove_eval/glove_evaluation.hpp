#pragma once
// The stretch glove on simulated subjects, through the real run-time
// pipeline (read-out, calibration, ONNX model, hand), scored against the
// simulator's ground-truth joint angles. `proprio bench glove`, the tests and
// the demo run it. Training and the thesis's Table 5.1 scenarios that need a
// model per subject (personalised, fine-tuned) live in tools/stretch_glove.
//
// Simulated accuracy is not real-world accuracy: the simulator's skin model
// is plausible, not measured, and real gloves slip, crease and age.
#include <array>
#include <filesystem>
#include <optional>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/time.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_glove/glove_hand_source.hpp"
#include "proprio/stretch_glove/glove_tracker.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"

namespace proprio::stretch_glove_eval {

// The shipped generic model is trained on these simulated subjects; the others are held out.
inline constexpr int kFirstHeldOutSubject = 10;

enum class CalibrationMode : std::uint8_t {
  session,  // the thesis's on-the-fly min-max from this session's exploration phase (scenario 4)
  global,   // min-max over the training data, from the model's sidecar (scenario 3)
};
std::string_view to_string(CalibrationMode m) noexcept;

// The simulated glove's departures from an ideal one, each of which a
// session can switch off (`bench glove --realism-ablation`).
enum class GloveRealismEffect : std::uint8_t {
  noise,        // the read-out's white noise
  outliers,     // spikes (a touch, a contact bounce)
  drift,        // the slow common gain drift
  fabrication,  // the cells' C0 spread (per glove)
  donning,      // per-donning gain, offset, pre-stretch and slip of the cells
  creep,        // the glove creeping over the session
  wrist,        // wrist motion the glove feels but the model does not output
};
inline constexpr std::array<GloveRealismEffect, 7> kGloveRealismEffects{
    GloveRealismEffect::noise,    GloveRealismEffect::outliers, GloveRealismEffect::drift, GloveRealismEffect::fabrication,
    GloveRealismEffect::donning,  GloveRealismEffect::creep,    GloveRealismEffect::wrist};
std::string_view to_string(GloveRealismEffect e) noexcept;
std::optional<GloveRealismEffect> parse_glove_realism_effect(std::string_view s) noexcept;

struct GloveSessionSpec {
  int subject = kFirstHeldOutSubject;
  int session = 0;  // the donning
  double exploration_s = 60.0;
  double task_s = 120.0;
  std::uint64_t seed = 1;
  CalibrationMode calibration = CalibrationMode::session;
  sim::StretchFaults faults;
  // The simulated glove; its seeds are set from seed, subject and session.
  sim::StretchGloveSimOptions simulator;
  bool wrist_motion = true;

  void switch_off(GloveRealismEffect e);
};

struct GloveSessionResult {
  GloveSessionSpec spec;
  std::size_t frames = 0;  // scored task frames
  double mean_deg = 0.0;   // mean absolute joint-angle error over the 20 DoFs, network output (no 1€ filter)
  double p95_deg = 0.0;
  double filtered_mean_deg = 0.0;  // the same after the 1€ filter (what an app sees, lag included)
  std::array<double, kHandDofCount> dof_mean_deg{};
  double calibration_coverage = 0.0;  // exploration coverage (calibration.hpp), 0-1
  double task_seconds = 0.0;
  double pipeline_seconds = 0.0;      // wall time in read-out + tracker over the task
  std::size_t pipeline_frames = 0;
  stretch_glove::GloveTrackerStats tracker;
  std::vector<float> errors_deg;  // per frame and DoF, for pooling
};

Result<GloveSessionResult> run_glove_session(const StretchGloveLayout& layout, const std::filesystem::path& model,
                                             const GloveSessionSpec& spec);

struct GloveAggregate {
  std::size_t sessions = 0, frames = 0;
  double mean_deg = 0.0, p95_deg = 0.0, filtered_mean_deg = 0.0;
  std::array<double, kHandDofCount> dof_mean_deg{};
  double pipeline_us_per_frame = 0.0;
};
GloveAggregate aggregate(const std::vector<GloveSessionResult>& sessions);


// The exploration phase of a simulated wearer through the real read-out and
// calibrator: the min-max calibration `proprio calibrate glove` would save.
struct SimulatedCalibration {
  stretch_glove::MinMaxCalibration calibration;
  stretch_glove::CalibrationProgress progress;
};
Result<SimulatedCalibration> calibrate_simulated(const StretchGloveLayout& layout, int subject, std::uint64_t seed,
                                                 double exploration_s, std::string source = {});

// A simulated subject wearing the stretch glove, live: the exploration phase
// runs first (off-line, in well under a second) for the min-max calibration,
// then the free-motion task is measured in real time and fed to a
// GloveHandSource, as a read-out board's reader thread would. The OpenXR
// layer's `glove` source with `input = "sim"` is this.
struct SimGloveSourceOptions {
  int subject = 3;
  std::uint64_t seed = 1;
  std::filesystem::path model;
  StretchGloveLayout layout = StretchGloveLayout::thesis_default();
  double exploration_s = 60.0;
  // Which hand wears the glove; empty: the subject's dominant hand.
  std::optional<Handedness> hand;
  stretch_glove::GloveTrackerOptions tracker;  // size is the subject's, hand as above
  PoseHistoryOptions history;
  // The wearer's true hand (sim::HandTruthWriter CSV), in the source's world
  // and time base: the same hand size and the tracker's wrist (the glove's
  // fixed T_world_wrist_fixed), so its fingers compare directly with the
  // served poses. Empty: not written. One row every truth_every measurements
  // (8: 120 Hz, twice the pose rate, so a reader can interpolate).
  std::filesystem::path truth_path;
  int truth_every = 8;

  Status validate() const;
  std::string describe() const;
};
Result<std::unique_ptr<HandSource>> make_sim_glove_source(const SimGloveSourceOptions& options,
                                                          const Clock& clock = MonotonicClock::instance());

// The same wearer behind the real device code path: the wearer's
// capacitances are what an emulated read-out board (devices::StretchEmulator)
// measures, served in real time over the in-memory HID link
// (StretchEmulatorServer, emulator time 0 = when the source starts) and read
// by the real driver and pipeline (stretch_glove::GloveBoardSource). The
// OpenXR layer's `glove` source with `input = "emulated"` is this.
//
// The board measures the combinations in the simulator's own cycle at its
// rate, so each reading is the simulator's measurement at that time (noise,
// spikes and saturation included). After a board restart (an unplug) the
// board's cycle starts again at combination 0 and no longer lines up with the
// simulator's: a reading is then the combination's sum of the simulator's
// cells at the nearest measurement time, with that measurement's drift, noise
// and spike. While the board is off the wearer keeps moving; the truth rows
// of that time are written when it comes back.
struct EmulatedGloveSourceOptions {
  SimGloveSourceOptions wearer;  // subject, seed, model, layout, calibration, pipeline, truth
  // The board's faults (emulator time). Each unplug also pulls the cable
  // (hid::FakeHidLink), so the host sees the board vanish and come back.
  devices::StretchEmulatorFaults faults;
  devices::StretchServeOptions serve;    // link latency and the emulator's pumping
  devices::StretchDeviceOptions device;  // the driver's (strip counts and flagged delivery are set from the layout)

  Status validate() const;
  std::string describe() const;
};

class EmulatedGloveSource final : public HandSource {
 public:
  ~EmulatedGloveSource() override;
  std::string_view name() const noexcept override { return "glove"; }
  bool available(Handedness hand) const noexcept override;
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override;
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override;

  stretch_glove::GloveSourceStats stats() const;
  devices::StretchDeviceStats device_stats();
  devices::StretchEmulatorStats emulator_stats() const;
  // CLOCK_MONOTONIC of emulator time 0 (the unplugs' time base).
  TimeNs time_zero_ns() const;
  // Readings made while the board's cycle did not line up with the simulator's (after a restart).
  std::uint64_t off_cycle_readings() const;

 private:
  friend Result<std::unique_ptr<EmulatedGloveSource>> make_emulated_glove_source(const EmulatedGloveSourceOptions&);
  struct Impl;
  explicit EmulatedGloveSource(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};
Result<std::unique_ptr<EmulatedGloveSource>> make_emulated_glove_source(const EmulatedGloveSourceOptions& options);

}  // namespace proprio::stretch_glove_eval
