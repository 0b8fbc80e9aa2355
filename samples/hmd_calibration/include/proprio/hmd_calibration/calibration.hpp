#pragma once
// HMD calibration by "reaching without seeing" (Lee 2021, section 2.2.3).
//
// What an HMD shows is rendered about a graphics frame {G} that need not be
// the tracked HMD frame {H}. A sphere commanded at p_cmd (in {G}) appears
// where R_HG p_cmd + p_HG is in {H} (eq. 2.1). The participant reaches for
// each sphere without seeing the finger; the tracked fingertip p_H is then a
// noisy measurement of that point, and the rigid transform {H} <- {G} is the
// least-squares fit of the pairs (Umeyama 1991 / Besl & McKay 1992, through
// Eigen::umeyama without scaling). Targets are drawn at random (r, theta,
// phi) with theta, phi in [-30, 30] deg and r in [30, 50] cm, in {H}'s
// spherical coordinates (theta right, phi up, as the perception sample).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::hmd_calibration {

struct TargetOptions {
  int trials = 100;
  double r_min_m = 0.30, r_max_m = 0.50;
  double angle_max_deg = 30.0;  // |theta|, |phi|
  std::uint64_t seed = 1;
  Status validate() const;
};
// The commanded sphere positions, p_cmd in {G}.
std::vector<Vec3> calibration_targets(const TargetOptions& options);

struct RigidFit {
  Pose T_hmd_graphics;              // p_H = T_hmd_graphics * p_cmd
  std::vector<double> residuals_m;  // |T p_cmd - p_H| per pair
  double rms_m = 0, max_m = 0;
  int pairs = 0;
  std::string describe() const;
};
// Needs at least 3 pairs that are not collinear.
Result<RigidFit> fit_hmd_graphics(const std::vector<Vec3>& p_cmd_in_graphics, const std::vector<Vec3>& p_finger_in_hmd);

// A simulated participant reaching without seeing: the finger lands at the
// point the sphere appears at, plus proprioceptive error N(0, sd^2) per axis.
std::vector<Vec3> simulate_reaching(const Pose& T_hmd_graphics_true, const std::vector<Vec3>& p_cmd_in_graphics,
                                    double proprioceptive_sd_m, std::uint64_t seed);

// TOML: [hmd_calibration] translation_m = [x, y, z], rotation_xyzw = [...], rms_m, max_m, pairs.
Status save_calibration(const std::filesystem::path& path, const RigidFit& fit);
Result<Pose> load_calibration(const std::filesystem::path& path);

}  // namespace proprio::hmd_calibration
