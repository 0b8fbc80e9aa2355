#pragma once
// The compass's own calibration (issue 27): hard iron (a constant offset from
// magnetised parts near the sensor) and soft iron (a linear distortion from
// nearby ferromagnetic material and the sensor's own axis gains), fitted from
// a figure-eight motion. Raw samples of a constant field then lie on an
// ellipsoid; the fit maps it back onto a sphere whose radius is the field's
// magnitude.
#include <cstddef>
#include <span>
#include <string>
#include <utility>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::ftm {

struct MagCalibration {
  Vec3 hard_iron_uT = Vec3::Zero();
  Mat3 soft_iron_inv = Mat3::Identity();  // m_cal = soft_iron_inv * (m_raw - hard_iron)

  Vec3 apply(const Vec3& raw_uT) const noexcept { return soft_iron_inv * (raw_uT - hard_iron_uT); }
};

struct MagFitOptions {
  // Nine unknowns; far more samples than that are needed for noise to average out.
  std::size_t min_samples = 100;
  // Fraction of 32 equal-area direction bins (8 azimuth x 4 bands) the
  // corrected samples must reach: a fit from one side of the sphere
  // extrapolates its hard iron freely. A good figure-eight reaches 0.6-0.9.
  double min_coverage = 0.4;
  // The fitted field must be a plausible Earth field (25-65 µT) within these
  // bounds; outside them the fit is rejected as a wrong unit or a magnet.
  double min_field_uT = 10.0;
  double max_field_uT = 200.0;
  // Soft iron beyond this condition number (largest/smallest axis) is not a
  // glove's distortion but a degenerate fit.
  double max_axis_ratio = 3.0;

  Status validate() const;
  std::string describe() const;
};

struct MagFitReport {
  std::size_t samples = 0;
  double field_uT = 0.0;         // radius of the corrected sphere
  double residual_rms_uT = 0.0;  // RMS of |m_cal| - field over the samples
  double coverage = 0.0;         // fraction of direction bins covered
};

// General ellipsoid least squares: x'Qx + 2b'x = 1 (nine unknowns, Eigen),
// then centre c = -Q⁻¹b and soft_iron_inv = r·sqrt(Q/k) with k = 1 + c'Qc and
// r chosen so det(soft_iron_inv) = 1 (the correction keeps the volume: the
// field's magnitude is the geometric mean of the ellipsoid's semi-axes).
// Errors: too few samples, non-finite input, poor direction coverage, a
// quadric that is not an ellipsoid, an implausible field.
Result<std::pair<MagCalibration, MagFitReport>> fit_mag_ellipsoid(std::span<const Vec3> raw_uT,
                                                                  const MagFitOptions& options = {});

// Fraction of the 32 direction bins that the unit directions of `v` reach.
double direction_coverage(std::span<const Vec3> v) noexcept;

}  // namespace proprio::ftm
