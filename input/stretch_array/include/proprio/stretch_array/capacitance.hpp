#pragma once
// The capacitance model of a stretch sensor cell (Glauser 2019, Sec. 4.3.1,
// eqs. 4.1-4.8) and the 555-timer read-out that measures it (Sec. 4.3.2 and
// Appendix B.2).
//
//   C = er e0 A / d                                       (4.1) plate capacitor
//   C / C0 = l / l0                                       (4.2) uniaxial stretch (d/d0 = w/w0)
//   C / C0 = (A / A0)^2                                   (4.3) area stretch, volume conserved, uniform
//   A / A0 = sqrt(C / C0)                                 (4.4)
//   C_j / C_j0 = (1 / A_j0) sum_i A_i^2 / A_i0            (4.8) non-uniform: a cell as triangles i
//
// The read-out: a 555 astable oscillator whose timing capacitor is the
// measured electrode pair runs at f = 1 / ((R1 + 2 R2) C ln 2), so
// C = 1 / (f (R1 + 2 R2) ln 2), with the thesis's R1 = 470 kOhm and
// R2 = 47 kOhm. What the board measures includes the parasitic capacitance of
// its traces and the leads, which is subtracted before the solve.
#include <span>

#include "proprio/core/result.hpp"

namespace proprio::stretch_array {

inline constexpr double kVacuumPermittivity = 8.8541878128e-12;  // F/m

// (4.1)
double plate_capacitance_f(double relative_permittivity, double area_m2, double separation_m) noexcept;
// (4.2) and (4.3): C / C0 for a cell stretched uniaxially to l/l0, and for one
// whose area changed uniformly to A/A0.
double uniaxial_capacitance_ratio(double length_ratio) noexcept;
double area_capacitance_ratio(double area_ratio) noexcept;
// (4.4): A / A0 from C / C0; NaN for a negative or non-finite ratio.
double area_ratio_from_capacitance(double capacitance_ratio) noexcept;
// (4.8): C / C0 of a cell made of triangles with rest areas `rest_m2` and
// deformed areas `deformed_m2` (same order). NaN when the sizes differ, a
// rest area is not positive, or a value is not finite.
double cell_capacitance_ratio(std::span<const double> rest_m2, std::span<const double> deformed_m2) noexcept;

// The 555 astable read-out.
struct Timer555 {
  double r1_ohm = 470e3;
  double r2_ohm = 47e3;
  // The counter's time base: the frequency is counted over this gate.
  double gate_s = 1.0 / 960.0;
  double reference_clock_hz = 48e6;  // what the gate's edges are counted with

  Status validate() const;
  // The oscillation frequency for a timing capacitance, and back.
  double frequency_hz(double capacitance_f) const noexcept;
  double capacitance_f(double frequency_hz) const noexcept;
  // The smallest capacitance step the counter resolves at capacitance C: one
  // count of the reference clock over one period.
  double resolution_f(double capacitance_f) const noexcept;
};

}  // namespace proprio::stretch_array
