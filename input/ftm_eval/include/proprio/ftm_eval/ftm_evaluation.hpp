#pragma once
// The FTM glove's evaluation (Lee 2021 ch. 4; issue 27 §5), what `proprio
// bench ftm` runs. Every case goes through the full pipeline: the compass and
// mounting calibration come from the simulated wearer's figure-eight and its
// imperfectly held poses (ftm_sim::calibrate_from_wearer), never from truth.
//
// Cases:
//  * imu_bench: the thesis's bench, one IMU turned about 90° about X, Y and Z
//    in turn (sim::ImuSimulator, MPU-9250 noise and turn-on offsets, raw
//    compass); it lies still for 2 s at turn-on (gyro offset), then its
//    compass and accelerometer offset are calibrated from a figure-eight; error of the ZYX Euler angles of the
//    rotation from the start pose while each turn is held.
//  * free_motion, pinch_grasp: held-out subjects; error of the 9 tracked DOFs,
//    the synergy DOFs (reported apart, not tracked) and the thumb/index/middle
//    fingertips relative to the wrist.
//  * disturbance: pinch-grasp with the fingertip devices' current on during
//    contacts and a drill, a fan and an earphone case each held near the hand
//    for 10 s; the detector's hit and false-alarm rates against a truth of
//    disturbances that matter (FtmBenchOptions::disturbance_truth_heading_deg,
//    or the true field beyond the detector's own tolerances; its release
//    window counted apart), the same against the simulator's 2°/3 %
//    "disturbed", and the heading error with gate_mag on and off (two
//    trackers fed the same samples).
// Simulated accuracy is not real-world accuracy.
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/ftm/mag_disturbance.hpp"
#include "proprio/sim/soft_tissue.hpp"

namespace proprio::ftm_eval {

// Subjects 10..14 of sim/subjects.hpp: no unit test uses them (the same
// held-out set as the stretch glove's bench).
inline constexpr int kFirstHeldOutSubject = 10;

enum class FtmCase : std::uint8_t { imu_bench, free_motion, pinch_grasp, disturbance };
std::string_view to_string(FtmCase c) noexcept;
Result<FtmCase> parse_ftm_case(std::string_view name);
std::vector<FtmCase> all_ftm_cases();

struct FtmBenchOptions {
  // Subjects first_subject, +1, ...: the held-out ones by default. Tuning
  // (the detector's thresholds) uses the held-in 0..4, never these.
  int first_subject = kFirstHeldOutSubject;
  int subjects = 5;
  double task_s = 60.0;    // task length per on-hand session
  std::uint64_t seed = 1;  // first seed; subject i uses seed + i
  // How long each magnetic object stays near the hand (issue: 10 s).
  double disturbance_hold_s = 10.0;
  // disturbance: the truth the detector is scored against. A compass sample
  // is disturbed when the dipoles turn the horizontal field at its IMU by more
  // than this: what matters for heading (the issue's ≤ 3° heading target;
  // 2° leaves a margin). The simulator's own "disturbed" (2° of direction or
  // 3 % of magnitude) also counts field changes that move no heading; its
  // rates are reported too (_field_2deg_3pct).
  double disturbance_truth_heading_deg = 2.0;
  // disturbance: the detector the gated and plain trackers run.
  ftm::MagDisturbanceOptions detector{};
  // imu_bench: how long each 90° turn is held (the error is averaged over it).
  double bench_hold_s = 5.0;
  // imu_bench ablation: the compass without hard and soft iron (its noise and
  // quantisation kept), to tell the figure-eight calibration's share of the
  // bench error. Off in `bench ftm`.
  bool bench_ideal_compass = false;
  // imu_bench: estimate the IMUs' turn-on offsets from their own readings
  // (imu_bias.hpp: gyro from a 2 s still start, accelerometer from a sphere
  // fit over the figure-eight), as a user does. false: the filter learns the
  // gyro offset online only and the accelerometer's is left in (ablation).
  bool bench_turn_on_bias = true;
  // The glove's IMUs on skin (sim/soft_tissue.hpp); rigid() for the idealised glove.
  sim::SoftTissueOptions soft_tissue;
  Status validate() const;  // Errc::invalid_argument naming the field
  std::string describe() const;
};

// One case's outcome. metrics are (name, value) in a fixed order, units in
// the name (_deg, _mm, _rate); counts are sample counts behind them.
struct FtmCaseResult {
  FtmCase which = FtmCase::imu_bench;
  bool ran = false;
  std::string reason;  // why it did not run (ran == false)
  int sessions = 0;
  std::vector<std::pair<std::string, double>> metrics;
  std::vector<std::pair<std::string, std::uint64_t>> counts;
  double metric(std::string_view name) const;  // NaN when absent
};

// Runs one case; never throws. A case that cannot run (a session whose
// calibration or tracker fails, no samples) comes back with ran = false and
// the reason; `progress` (may be empty) is called after each session with
// (sessions done, sessions in this case).
using FtmProgress = void (*)(void* user, int done, int total);
FtmCaseResult run_ftm_case(FtmCase which, const FtmBenchOptions& options, FtmProgress progress = nullptr,
                           void* progress_user = nullptr);

}  // namespace proprio::ftm_eval
