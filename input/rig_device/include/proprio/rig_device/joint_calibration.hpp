#pragma once
// Per-joint calibration: the on-board microcontroller's map from the six Hall
// channels to the four joint angles, fitted from jig data alone.
//
// Why a fitted forward model, inverted: the fields superpose and the sensors
// are linear, so each channel is a sum of terms that each depend on few
// angles (hall_joint.hpp's geometry):
//   bend x/y      = F(bend_x, bend_y) + G(twist_out)
//       (own bend magnet and inlet ring magnet, both in yoke 1; the outlet
//        ring's magnet turning 13 mm away)
//   twist_in a/b  = H(twist_in)
//       (ring magnet; the bend magnet sits on the axis, so only its tilt
//        shows, as a function of twist_in)
//   twist_out a/b = H(twist_out) + K(bend_x, bend_y)
//       (ring magnet; both yoke-1 magnets seen from yoke 2)
// F, K: products of {1, cos k b, sin k b; k = 1..3} of each bend (49 terms;
// the ideal dipole is exactly in this span, tilts and offsets add products
// and higher harmonics). G: harmonics 1..2 of twist_out. H: harmonics 0..3 (an
// off-centre disc adds the higher ones). Least squares per channel gives
// 53 / 7 / 55 coefficients; a per-axis polynomial or a lookup table would
// need the cross terms anyway, and tables need far more jig poses for 0.1 deg.
// The map inverts it: twist_in by Gauss-Newton on H from the first-harmonic
// atan2; bends and twist_out jointly (4 channels, 3 unknowns) by Gauss-Newton
// from the 4 best entries of a coarse 33 x 33 table of F (near the stops the
// nearest entry in counts can lie far off in angle). That is ~50 k flops a
// report: about a millisecond on a Cortex-M4F; a part without an FPU would
// want fixed point or fewer starts.
#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/rig_device/hall_joint.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"

namespace proprio::rig_device {

// Harmonics per bend angle in F and K: 1 holds the ideal dipole; 2 and 3
// hold magnet offsets and the inlet ring magnet, whose distance to the 2-D
// sensor changes with the bends (with 2 only, an earlier geometry left
// 1.5 counts rms of misfit on the jig).
inline constexpr int kBendHarmonics = 3;
inline constexpr int kBendBasisSize = (2 * kBendHarmonics + 1) * (2 * kBendHarmonics + 1);  // F, K (K without the constant)
inline constexpr int kTwistCrossBasisSize = 4;   // G
inline constexpr int kTwistBasisSize = 7;        // H
inline constexpr int kBendChannelCoeffs = kBendBasisSize + kTwistCrossBasisSize;    // 53
inline constexpr int kTwistInChannelCoeffs = kTwistBasisSize;                       // 7
inline constexpr int kTwistOutChannelCoeffs = kTwistBasisSize + kBendBasisSize - 1; // 55
inline constexpr std::uint64_t kMaxCalibrationFileBytes = 256 * 1024;

class JointCalibration {
 public:
  // From jig samples only (angles the jig commanded, readings). Needs enough
  // distinct poses to pin every coefficient (the fit refuses a rank-deficient
  // set, naming the channel). bend_limit_rad: the joint's stops, which the jig
  // covered; the map keeps bends within them plus 0.05 rad (the fit is
  // extrapolation beyond, and may mimic a reading there).
  static Result<JointCalibration> fit(const std::vector<JigSample>& samples, double bend_limit_rad,
                                      std::string joint_id = "joint");

  // The angles for one report (twists in (-pi, pi]).
  JointAngles angles(const HallReadings& readings) const;
  // The same, also starting from the previous report's angles, as the
  // firmware does when it runs continuously: more robust where the 2-D
  // reading is compressed near the stops.
  JointAngles angles(const HallReadings& readings, const JointAngles& previous) const;
  // The fitted forward model (counts) at given angles: for tests and for the
  // fit's residual report.
  HallReadings predict(const JointAngles& angles) const;

  // RMS fit residual per channel over the jig data, counts: bend x, y,
  // twist_in a, b, twist_out a, b.
  const std::array<double, 6>& fit_rms_counts() const { return fit_rms_counts_; }
  const std::string& joint_id() const { return joint_id_; }
  double bend_limit_rad() const { return bend_limit_rad_; }

  // TOML (format "proprio-rig-joint-calibration", version 1). Parsing is
  // bounded: exact coefficient counts, finite values of sane size, known keys.
  std::string to_toml() const;
  static Result<JointCalibration> parse_toml(std::string_view text, const std::string& origin);
  static Result<JointCalibration> load(const std::filesystem::path& file);

 private:
  JointCalibration() = default;
  void build_search_table();
  JointAngles solve_angles(const HallReadings& readings, const JointAngles* previous) const;

  std::string joint_id_ = "joint";
  double bend_limit_rad_ = 1.4;
  std::array<std::vector<double>, 2> bend_;       // kBendChannelCoeffs each
  std::array<std::vector<double>, 2> twist_in_;   // 7 each
  std::array<std::vector<double>, 2> twist_out_;  // kTwistOutChannelCoeffs each
  std::array<double, 6> fit_rms_counts_{};
  // Coarse grid of F for the bends' starting point (not stored in files).
  int table_n_ = 0;
  std::vector<std::array<double, 2>> table_;
  std::vector<bool> table_inside_;  // within the stops
};

}  // namespace proprio::rig_device
