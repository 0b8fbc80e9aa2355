#pragma once
// Simulated stretch-sensing capacitive glove (Glauser 2019, ch. 5): skin
// stretch under the hand model -> cell capacitance -> the board's
// time-multiplexed measurements, with ground truth kept apart.
//
// Physics, cell by cell (details and numbers in docs/stretch-glove-layout.md):
//  * Skin strain. Flexing a joint by theta lengthens the dorsal skin over it
//    by about h * theta, h the skin's distance from the joint axis (the joint
//    radius of HandShape). The condyles act as a cam (h grows with flexion);
//    hyperextension folds the skin instead of shortening it as much. The glove
//    takes a share of that elongation (the rest slides) and spreads it along
//    the finger as a shear-lag (Laplace) profile around the joint, so a cell
//    feels its own joint most, its neighbours a little; the glove finger,
//    anchored at the fingertip, also carries a uniform share of the whole
//    finger's elongation (a fist stretches every along cell a bit).
//  * Finger volume: the circumference near a flexed joint grows (condyles,
//    extensor hood, intrinsic muscles bulging with flexion of the proximal
//    joints); across cells see that.
//  * Webs: the distance between neighbouring fingers (forward kinematics),
//    which grows with abduction and with differential flexion.
//  * Dorsum: MCP and thumb CMC flexion pull the back-of-hand skin toward the
//    knuckles (along cells, decaying with distance); spreading the fingers,
//    cupping the palm and interossei bulging stretch it across.
//  * The wrist, which the 20-DoF hand does not have but a glove strapped at
//    the wrist feels: flexion pulls the dorsum's skin toward the forearm
//    (strongest near the strap) and tensions the whole glove a little;
//    radial/ulnar deviation stretches one side of the dorsum. A nuisance the
//    pose network has to learn to ignore, as with the real glove.
//  * Each cell responds mostly in its own direction: the ventilation cuts
//    beside it absorb most stretch in the other one (thesis Sec. 5.2.1).
//  * The glove is one size: on a hand larger than its reference it is
//    pre-stretched, on a smaller one it runs slack, where silicone buckles
//    rather than compresses (a soft floor at stretch 1).
//  * A cell is split into elements along the bone, each with its own area
//    stretch; C/C0 = mean over elements of (A_e/A0_e)^2 (thesis eqs 4.3, 4.8).
//  * Per donning: each cell's gain, offset, pre-stretch and a slip of its
//    position along the bone are drawn anew; per glove: a fabrication spread
//    of C0. Within a session the glove creeps: each finger's (and the
//    dorsum's) slip walks slowly.
//  * Read-out: one measurement per (top, bottom) strip pair in cycle order,
//    C_m = M C_c (stretch_glove_layout.hpp) times a slow common gain drift,
//    plus white noise (absolute + relative, the NE555 timer's period jitter),
//    occasional spikes, and the board's full scale.
//
// Every random effect draws from its own stream (mix_seed), so switching one
// off leaves the others unchanged; the same options give the same bytes.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/core/time.hpp"
#include "proprio/sim/hand_motion.hpp"

namespace proprio::sim {

// The skin-and-glove model. Our own physically motivated approximation, not
// a measured one: each number says what it stands for; docs/stretch-glove-layout.md
// gives the reasoning.
struct StretchSkinModel {
  // The glove's reference hand (the one it fits without pre-stretch beyond
  // the textile's own) and that pre-stretch. The pool's hands (17-20.5 x 9-11
  // cm) are larger, so the smallest ones get the least pre-stretch, as the
  // thesis found its smallest hand the hardest (Table 5.1).
  double reference_hand_length_m = 0.175;
  double reference_hand_width_m = 0.095;
  double textile_prestretch = 1.04;
  // Share of the skin's elongation the glove takes (it slides on the rest).
  double transfer_efficiency = 0.55;
  // Shear-lag length of the glove over a finger and over the dorsum.
  double finger_shear_lag_m = 0.008;
  double dorsum_shear_lag_m = 0.015;
  // Share of a finger's total dorsal elongation spread evenly along the glove finger.
  double finger_tension_fraction = 0.12;
  // Cam: the skin offset grows by this fraction per radian of flexion (MCP, PIP, DIP).
  double cam_mcp = 0.30;
  double cam_pip = 0.15;
  double cam_dip = 0.10;
  // Hyperextension shortens the dorsal skin by this fraction of h * theta (it folds).
  double hyperextension_fold = 0.5;
  // Skin along the MCP also stretches with ab/adduction: this fraction of h * |abduction|.
  double abduction_skin = 0.2;
  // Finger circumference growth per radian of flexion at a joint (MCP, PIP,
  // DIP), decaying over volume_length_m along the finger.
  double volume_mcp = 0.06;
  double volume_pip = 0.05;
  double volume_dip = 0.03;
  double volume_length_m = 0.010;
  // Intrinsic muscles bulging with MCP (and thumb CMC) flexion, felt across
  // the whole proximal phalanx (thumb: its metacarpal, the thenar eminence).
  double muscle_bulge = 0.03;
  // Webs: the glove spanning the gap between two fingers (thumb-index: the
  // first web space) takes this share of the change in distance.
  double web_transfer = 0.5;
  double web_span_m = 0.012;
  double thumb_web_span_m = 0.030;
  // Dorsum across: strain per radian of spread between neighbouring fingers,
  // per radian of ring/little MCP flexion (palm cupping) and thumb CMC
  // flexion, per radian of |abduction| (interossei), decaying over dorsum_reach_m.
  double dorsum_spread = 0.08;
  double dorsum_cupping = 0.04;
  double dorsum_bulge = 0.05;
  double dorsum_reach_m = 0.025;
  // Wrist: the skin offset of the wrist's flexion axis, as a fraction of
  // hand width (the wrist is about 0.2 hand widths thick on the dorsal side),
  // the shear-lag length from the strap, the share of the wrist's elongation
  // every glove finger carries, and across-strain per radian of deviation at
  // the edge of the hand.
  double wrist_skin_offset = 0.2;
  double wrist_shear_lag_m = 0.02;
  double wrist_tension_fraction = 0.05;
  double wrist_deviation_gain = 0.06;
  // Sensitivity to stretch across a cell's own direction (the cuts beside it
  // absorb the rest; thesis Sec. 5.2.1).
  double cross_direction_gain = 0.35;
  // Width of the soft floor at stretch 1 (silicone buckles instead of
  // compressing).
  double slack_softness = 0.02;
  // Elements per cell for eq. 4.8.
  int elements_per_cell = 4;
};

struct StretchGloveSimOptions {
  std::uint64_t seed = 1;        // this session: donning, noise, outliers, drift
  std::uint64_t glove_seed = 1;  // the physical glove: fabrication spread of C0

  // 16 measurements per recovered frame at 60 Hz (thesis Sec. 5.2.1).
  double measurement_rate_hz = 960.0;
  // The board's full scale: readings at or above it are clipped and flagged.
  double full_scale_pf = 500.0;

  // White noise per measurement, sigma = sqrt(noise_pf^2 + (noise_relative * C)^2):
  // the NE555 timer's period jitter (relative) and a quantisation/pick-up
  // floor (absolute). Assumed; the thesis gives no noise figures.
  double noise_pf = 0.05;
  double noise_relative = 0.002;
  // Spikes (a touch, a contact bounce): with this probability a measurement
  // gets an extra uniform [min, max] pF. Rare: the thesis's glove is worn over
  // a nylon sock, which keeps body capacitance out (its Appendix B.3). At
  // 2e-5 a 6-minute session has about 7 spikes. Note that the read-out keeps a
  // spike for a whole cycle (and the mean filter a little longer), about 17
  // recovered frames, so a 20-frame median only partly hides it.
  double outlier_probability = 2e-5;
  double outlier_min_pf = 5.0;
  double outlier_max_pf = 60.0;
  // A slow common gain drift (temperature, sweat): random walk of the gain,
  // per sqrt(second).
  double drift_per_sqrt_s = 5e-4;

  // Fabrication: C0 of each cell is the layout's times (1 + N(0, sigma)).
  double fabrication_sigma = 0.03;
  // Donning: per cell gain (1 + N(0, sigma)), offset N(0, sigma) pF, pre-stretch
  // (1 + N(0, sigma)); slip of cell positions along the bone, common per
  // finger (and per dorsum) plus per cell.
  double donning_gain_sigma = 0.04;
  double donning_offset_sigma_pf = 0.3;
  double donning_prestretch_sigma = 0.02;
  double slip_common_sigma_m = 0.002;
  double slip_cell_sigma_m = 0.001;
  // Creep during a session: each region's slip is a random walk with this
  // step per sqrt(second), updated once a simulated second (1.7 mm over 5
  // minutes at 1e-4).
  double creep_per_sqrt_s_m = 1e-4;

  StretchSkinModel skin;

  bool enable_noise = true;
  bool enable_outliers = true;
  bool enable_drift = true;
  bool enable_fabrication_spread = true;
  bool enable_donning_variation = true;
  bool enable_creep = true;
  bool enable_saturation = true;

  // No noise, outliers, drift, fabrication spread or donning variation: the
  // measurements are exactly M C_c.
  static StretchGloveSimOptions ideal();
  // Errc::invalid_argument naming the field when a value is not usable.
  Status validate() const;
  std::string describe() const;
};

// Fault injection for tests.
struct StretchFaults {
  std::vector<std::uint64_t> nan_measurements;        // these measurement indices read NaN
  std::vector<std::uint64_t> saturated_measurements;  // these read the board's full scale
  std::vector<std::size_t> dead_cells;                // open lead: from dead_from_ns on, the cell is ~0 pF
  TimeNs dead_from_ns = 0;
};

// What the board reports for one measurement.
struct StretchMeasurement {
  std::uint64_t index = 0;        // running count since the simulator started
  std::uint16_t combination = 0;  // top * bottom_strips + bottom
  double capacitance_pf = 0.0;
  TimeNs time_ns = 0;
  bool saturated = false;  // at or above full scale, clipped to it
};

// The truth behind one measurement. Never part of what a tracker sees.
struct StretchMeasurementTruth {
  double noise_free_pf = 0.0;  // M C_c for this combination, drift included, before noise and clipping
  double noise_pf = 0.0;       // the white noise drawn
  double outlier_pf = 0.0;     // the spike added, 0 when none
  double drift_gain = 1.0;
};

// The wrist's own angles (not among the hand model's 20 DoFs), which the
// glove feels through its strap. Flexion: + toward the palm; deviation: +
// radial (toward the thumb).
struct WristAngles {
  double flexion_rad = 0.0;
  double deviation_rad = 0.0;
};

// Drawn per donning, per cell.
struct StretchDonning {
  int index = 0;
  std::vector<double> gain;
  std::vector<double> offset_pf;
  std::vector<double> prestretch;  // multiplies the cell's pre-stretch
  std::vector<double> slip_m;      // cell moved along its bone (dorsum: toward the knuckles), metres
};

// One cell's deformation at one pose (without gain, offset or drift).
struct CellStretch {
  double stretch_parallel = 1.0;       // mean length ratio in the cell's direction
  double stretch_perpendicular = 1.0;  // mean length ratio across it
  double area_stretch = 1.0;           // mean A/A0 over the elements
  double capacitance_ratio = 1.0;      // C/C0 = mean (A_e/A0_e)^2 (eq. 4.8)
  std::vector<double> element_area_stretch;
};

class StretchGloveSimulator {
 public:
  // Errors when the options or layout are invalid.
  static Result<StretchGloveSimulator> create(StretchGloveLayout layout, HandShape shape,
                                              StretchGloveSimOptions options, int donning = 0);

  // Take the glove off and put it on again: draws donning `index` (the same
  // index gives the same draw for the same seed).
  void don(int index);
  const StretchDonning& donning() const noexcept { return donning_; }

  // Cell capacitances (pF) at this pose with this donning's gain and offset
  // (and the creep so far), no drift or noise. out_pf has cell_count() entries.
  void cell_capacitances(const HandAngles& angles, std::span<double> out_pf, WristAngles wrist = {}) const;
  // Deformation of every cell at this pose (ground truth of eqs 4.3 and 4.8).
  std::vector<CellStretch> cell_stretch(const HandAngles& angles, WristAngles wrist = {}) const;
  // C0 of each cell of this glove (the layout's, with the fabrication spread).
  const std::vector<double>& rest_capacitance_pf() const noexcept { return c0_pf_; }

  // The next measurement of the cycle, taken at measurement_time(index) with
  // the hand at `angles`. truth (optional) receives what lies behind it.
  StretchMeasurement measure(const HandAngles& angles, StretchMeasurementTruth* truth = nullptr,
                             WristAngles wrist = {});
  std::uint64_t next_index() const noexcept { return next_index_; }
  TimeNs measurement_time(std::uint64_t index) const noexcept;
  // Cells a combination sums (its row of the measurement matrix).
  std::span<const std::uint16_t> cells_in(std::size_t combination) const;

  void set_faults(StretchFaults faults);

  const StretchGloveLayout& layout() const noexcept { return layout_; }
  const HandShape& shape() const noexcept { return shape_; }
  const StretchGloveSimOptions& options() const noexcept { return options_; }

 private:
  StretchGloveSimulator() = default;
  struct Term {
    std::uint16_t feature = 0;
    double coefficient = 0.0;
  };
  struct Element {
    std::vector<Term> along;   // skin strain along the bone (dorsum: toward the knuckles)
    std::vector<Term> across;  // skin strain around the finger (dorsum: across the hand)
  };
  struct CellModel {
    std::vector<Element> elements;
    double prestretch_along = 1.0;
    double prestretch_across = 1.0;
  };
  void build_cell_models();
  // Pose features the cell models are linear in (see the .cpp); webs need
  // forward kinematics, so they are filled only when asked.
  void features(const HandAngles& angles, WristAngles wrist, bool with_webs, std::vector<double>& out) const;
  double cell_ratio(std::size_t cell, const std::vector<double>& f, CellStretch* detail) const;
  double cell_pf(std::size_t cell, const std::vector<double>& f) const;

  StretchGloveLayout layout_;
  HandShape shape_;
  StretchGloveSimOptions options_;
  HandModel model_{HandShape{}};
  std::vector<double> c0_pf_;
  StretchDonning donning_;
  std::vector<CellModel> cells_;
  // Webs: the two points whose distance the web's skin spans, per web cell.
  struct Web {
    std::size_t cell = 0;
    HandJoint joint_a = HandJoint::wrist, joint_b = HandJoint::wrist;
    double along_a_m = 0.0, along_b_m = 0.0;  // down each bone from its joint
    double rest_distance_m = 0.0;
    double span_m = 0.01;
  };
  std::vector<Web> webs_;
  std::vector<std::vector<std::uint16_t>> combination_cells_;
  StretchFaults faults_;

  std::uint64_t next_index_ = 0;
  double drift_gain_ = 1.0;
  Rng noise_rng_{1}, outlier_rng_{1}, drift_rng_{1}, creep_rng_{1};
  std::array<double, kFingerCount + 1> creep_m_{};  // per finger, then the dorsum
  std::vector<std::size_t> region_;                 // of each cell: finger index, or kFingerCount for the dorsum
  std::vector<double> features_;  // scratch for measure(), sized once
};

// The calibration phase of Sec. 5.3.3: the user freely explores extreme
// poses. Keyframes cycle through postures that together reach both ends of
// every DoF's range (fist, flat and hyperextended, spread, hook, table-top,
// thumb out and across, pinches), in a seeded order with jitter, joined by
// minimum-jerk moves and held long enough for a 20-frame median filter.
struct ExplorationOptions {
  double transition_s = 0.8;
  double hold_s = 0.7;
  double jitter_rad = deg_to_rad(6.0);
  // Postures reach this fraction of each DoF's range from its middle.
  double reach = 0.95;
};

class ExplorationMotion {
 public:
  ExplorationMotion(JointLimits limits, ExplorationOptions options, std::uint64_t seed);
  // Angles at t >= 0; starts and (after whole cycles) rests at the relaxed pose.
  HandAngles sample(TimeNs t_ns);
  // The relaxed pose it starts from (the free-motion protocol's first keyframe).
  static HandAngles relaxed();

 private:
  const HandAngles& keyframe(std::size_t k);
  JointLimits limits_;
  ExplorationOptions options_;
  Rng rng_;
  std::vector<HandAngles> keyframes_;
  std::vector<std::size_t> order_;
};

// Slow random wrist motion: a new target every interval, minimum-jerk moves.
struct WristMotionOptions {
  double flexion_min_rad = deg_to_rad(-35.0);
  double flexion_max_rad = deg_to_rad(35.0);
  double deviation_min_rad = deg_to_rad(-12.0);
  double deviation_max_rad = deg_to_rad(18.0);
  double interval_s = 4.0;
  double transition_s = 1.2;
};

class WristMotion {
 public:
  WristMotion(WristMotionOptions options, std::uint64_t seed);
  WristAngles sample(TimeNs t_ns);

 private:
  WristMotionOptions options_;
  Rng rng_;
  std::vector<WristAngles> keyframes_;
};

enum class StretchPhase : std::uint8_t { exploration = 0, task = 1 };

struct StretchSessionOptions {
  double exploration_s = 60.0;  // calibration phase first (thesis: under a minute)
  double task_s = 300.0;        // then task motion (thesis sessions: about 5 minutes)
  ExplorationOptions exploration;
  HandMotionOptions task_motion;  // free motion by default; its seed is set from the session seed
  bool wrist_motion = true;       // move the wrist (a nuisance for the glove) through both phases
  WristMotionOptions wrist;
  std::string describe() const;
};

// One measurement with its ground truth.
struct StretchSample {
  StretchMeasurement measurement;
  StretchMeasurementTruth truth;
  HandAngles angles{};  // ground-truth joint angles at measurement.time_ns
  WristAngles wrist;
  StretchPhase phase = StretchPhase::exploration;
};

// A whole session on one donning: exploration, then task motion, measured
// one at a time. Time starts at 0 (simulated sessions, architecture.md).
class StretchGloveSession {
 public:
  StretchGloveSession(StretchGloveSimulator simulator, StretchSessionOptions options);
  // The next measurement; false once the session is over.
  bool next(StretchSample& out);
  std::uint64_t total_measurements() const noexcept { return total_; }
  StretchGloveSimulator& simulator() noexcept { return sim_; }
  const StretchSessionOptions& options() const noexcept { return options_; }

 private:
  StretchGloveSimulator sim_;
  StretchSessionOptions options_;
  ExplorationMotion exploration_;
  HandMotionGenerator task_;
  WristMotion wrist_;
  std::uint64_t total_ = 0;
  TimeNs exploration_end_ns_ = 0;
};

}  // namespace proprio::sim
