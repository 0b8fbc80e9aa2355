#include "proprio/stretch_array/capacitance.hpp"

#include <cmath>
#include <limits>

namespace proprio::stretch_array {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}  // namespace

double plate_capacitance_f(double relative_permittivity, double area_m2, double separation_m) noexcept {
  if (!(separation_m > 0.0) || !(area_m2 >= 0.0) || !std::isfinite(relative_permittivity)) return kNaN;
  return relative_permittivity * kVacuumPermittivity * area_m2 / separation_m;
}

double uniaxial_capacitance_ratio(double length_ratio) noexcept {
  return std::isfinite(length_ratio) && length_ratio > 0.0 ? length_ratio : kNaN;
}

double area_capacitance_ratio(double area_ratio) noexcept {
  return std::isfinite(area_ratio) && area_ratio >= 0.0 ? area_ratio * area_ratio : kNaN;
}

double area_ratio_from_capacitance(double capacitance_ratio) noexcept {
  return std::isfinite(capacitance_ratio) && capacitance_ratio >= 0.0 ? std::sqrt(capacitance_ratio) : kNaN;
}

double cell_capacitance_ratio(std::span<const double> rest_m2, std::span<const double> deformed_m2) noexcept {
  if (rest_m2.size() != deformed_m2.size() || rest_m2.empty()) return kNaN;
  double rest_total = 0.0, sum = 0.0;
  for (std::size_t i = 0; i < rest_m2.size(); ++i) {
    const double a0 = rest_m2[i], a = deformed_m2[i];
    if (!(std::isfinite(a0) && a0 > 0.0) || !(std::isfinite(a) && a >= 0.0)) return kNaN;
    rest_total += a0;
    // Each triangle is a plate capacitor of its own share C_j0 A_i0 / A_j0,
    // stretched uniformly: (4.3) per triangle, summed in parallel.
    sum += a * a / a0;
  }
  return sum / rest_total;
}

Status Timer555::validate() const {
  if (!(std::isfinite(r1_ohm) && r1_ohm > 0.0) || !(std::isfinite(r2_ohm) && r2_ohm > 0.0)) {
    return make_error(Errc::invalid_argument, "555 read-out: R1 and R2 must be positive (ohm)");
  }
  if (!(std::isfinite(gate_s) && gate_s > 0.0 && gate_s < 10.0)) {
    return make_error(Errc::invalid_argument, "555 read-out: the gate must be in (0, 10) s");
  }
  if (!(std::isfinite(reference_clock_hz) && reference_clock_hz > 1e3)) {
    return make_error(Errc::invalid_argument, "555 read-out: the reference clock must be above 1 kHz");
  }
  return {};
}

double Timer555::frequency_hz(double capacitance_f) const noexcept {
  if (!(std::isfinite(capacitance_f) && capacitance_f > 0.0)) return kNaN;
  return 1.0 / ((r1_ohm + 2.0 * r2_ohm) * capacitance_f * std::log(2.0));
}

double Timer555::capacitance_f(double frequency_hz) const noexcept {
  if (!(std::isfinite(frequency_hz) && frequency_hz > 0.0)) return kNaN;
  return 1.0 / (frequency_hz * (r1_ohm + 2.0 * r2_ohm) * std::log(2.0));
}

double Timer555::resolution_f(double capacitance_f) const noexcept {
  // The period T = (R1 + 2 R2) C ln 2 is timed with the reference clock: one
  // count is 1 / f_ref of period, i.e. dC = dT / ((R1 + 2 R2) ln 2).
  if (!(std::isfinite(capacitance_f) && capacitance_f > 0.0)) return kNaN;
  return 1.0 / (reference_clock_hz * (r1_ohm + 2.0 * r2_ohm) * std::log(2.0));
}

}  // namespace proprio::stretch_array
