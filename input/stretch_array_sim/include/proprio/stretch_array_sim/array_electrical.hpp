#pragma once
// What the array's read-out board measures (issue 30; Glauser 2019, Sec.
// 4.3.2, 4.5.1 and Appendix B.2), including what the capacitance model of
// eq. 4.8 ignores. One row of the measurement plan (M^I pairs, then M^II
// single strips: StripArrayLayout::measurement_plan(true)) connects its
// source strips to the timing node of a 555 astable and grounds the others;
// the cells with exactly one strip on the source charge. The board times one
// oscillation period against its reference clock and converts it back to
// capacitance as the firmware does, C = T / ((R1 + 2 R2) ln 2).
//
// Effects, each switchable in BoardOptions:
//  (a) resistance: strips of conductive silicone (the thesis: ~1 kOhm per
//      square; "about 50 kOhm" for its longest strip) plus the lead from the
//      sheet to the board; R ~ (l/l0)^2 along the strip (array_sheet.hpp).
//      The row is simulated as the RC network it is (see array_electrical.cpp
//      for the derivation): series resistance lets the 555's pin run ahead of
//      the cells' own voltage, so each period ends early and the board reads
//      less than the cells hold, more so the farther the cells are along
//      their strips and the more the strips are stretched;
//  (b) parasitic capacitance at the timing node: the board's own (what the
//      "unconnected pads" channel measures) plus each source strip's lead and
//      trace, with a slow drift;
//  (c) rows at different instants: row r of a frame starting at t_k is
//      measured at t_k + r / row_rate (the caller's provider gives the sheet
//      at any t);
//  (d) the 555's period jitter (comparator noise on its two thresholds) and
//      the counter's quantisation (one reference-clock count per period);
//  (e) a broken lead: a strip disconnected at the board from a time on;
//  (f) over-stretch: a cell stretched beyond the damage limit (Fig. 4.17:
//      2.25x) changes its gain for good;
//  (g) a per-donning parasitic offset on each strip's lead.
//
// Output: measured pF per plan row, parasitics included, plus the board's
// open-pads reference reading. Subtracting parasitics is the host's job:
// either the open-pads reading (the thesis's way: it reads the board and one
// typical lead, so each strip's own difference from that, and the second lead
// of a pair row, stay in) or a rest calibration (calibrate_at_rest(): each row's
// reading on the flat rest sheet minus M C0 from eq. 4.1, which also absorbs
// the rest-state resistance error).
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/capacitance.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"

namespace proprio::stretch_array_sim {

struct BoardOptions {
  // R1, R2 and the reference clock. Its gate_s is not used: one period is
  // timed per row, and rows come at timing.row_rate_hz.
  stretch_array::Timer555 timer;
  double supply_v = 5.0;          // the 555's Vcc (thresholds at Vcc/3 and 2 Vcc/3)
  std::uint64_t seed = 1;

  struct Resistance {
    bool enabled = true;
    double sheet_ohm_per_square = 1000.0;  // the thesis's four-point-probe value
    double lead_ohm = 1000.0;              // per strip: routing to the sheet edge, pad, PET foil, wires, switch
    // > 0: scale the sheet and lead resistances together so that the longest
    // strip's rest resistance (lead + strip to its far end) is this (the
    // thesis: "about 50 kOhm").
    double longest_strip_ohm = 0.0;
  } resistance;

  struct Parasitic {
    bool enabled = true;
    double board_f = 4e-12;  // switch and sensing boards at the timing node
    // Each strip's lead and trace, drawn once per strip (seeded) in this range.
    double strip_min_f = 1.5e-12, strip_max_f = 6e-12;
    // Slow drift (temperature, cable movement): std of the drift of the board
    // and of each strip, as a sum of three sinusoids with periods in range.
    double drift_std_f = 0.2e-12;
    double drift_period_min_s = 20.0, drift_period_max_s = 600.0;
  } parasitic;

  struct Timing {
    bool enabled = true;       // false: every row of a frame at the frame's time
    double row_rate_hz = 960;  // rows per second (one per 555 gate)
  } timing;

  struct Jitter {
    bool enabled = true;
    // Noise at each comparator decision, referred to its input (supply
    // ripple and the comparator's own noise). 0.5 mV on a 5 V supply gives
    // a period jitter of about 4e-4 T at the 555 values; see array_electrical.cpp.
    double comparator_noise_v = 0.5e-3;
  } jitter;

  bool quantise = true;  // the period counted in whole reference-clock ticks

  struct BrokenLead {
    bool enabled = false;
    bool top = true;        // which layer
    std::size_t strip = 0;  // index in that layer
    double from_s = 0.0;    // disconnected from this time on
  } broken_lead;

  struct OverStretch {
    bool enabled = true;
    double limit = 2.25;        // largest principal stretch (Fig. 4.17)
    double gain_change = 0.05;  // relative, permanent (an assumption: the thesis shows a change but gives no number)
  } over_stretch;

  struct Donning {
    bool enabled = true;
    double offset_std_f = 0.5e-12;  // per strip lead, redrawn each time the sleeve is put on
    std::uint32_t index = 0;        // which donning (set_donning() changes it)
  } donning;

  Status validate() const;
  std::string describe() const;
  // Every effect off: the board reads M C exactly (with the board's R1, R2).
  static BoardOptions ideal();
};

struct BoardFrame {
  double t_s = 0.0;                 // the frame's start
  std::vector<double> row_time_s;   // when each row was measured
  std::vector<double> rows_pf;      // measured, parasitics included, plan order
  // The reference channel (at the frame's end): two unconnected pads, i.e.
  // the board's node and one typical lead, none of the sheet.
  double open_pads_pf = 0.0;
};

// Per-row parasitic a host calibration obtains, to subtract from rows_pf.
struct RestCalibration {
  std::vector<double> parasitic_pf;  // per row: rest reading - M C0 (eq. 4.1)
  double open_pads_pf = 0.0;         // the reference channel during calibration
};

using StateProvider = std::function<Result<SheetState>(double t_s)>;
using VertexProvider = std::function<Result<std::vector<Eigen::Vector3d>>(double t_s)>;

class BoardSimulator {
 public:
  static Result<BoardSimulator> create(ArraySheet sheet, BoardOptions options = {});

  // One frame: every plan row, row r at t_frame_s + r / row_rate. The
  // provider is called once per row. Over-stretch damage is remembered.
  Result<BoardFrame> measure_frame(double t_frame_s, const StateProvider& sheet_at);
  Result<BoardFrame> measure_frame(double t_frame_s, const VertexProvider& vertices_at);
  // A frame of a sheet that does not move.
  Result<BoardFrame> measure_static(double t_frame_s, const SheetState& state);

  // The apparent capacitance of one row (F) with its resistances and
  // parasitics at time t, noiseless and unquantised: what the network makes
  // of the row before the counter sees it.
  Result<double> apparent_row_f(std::size_t row, const SheetState& state, double t_s) const;

  // Averages `frames` frames of the flat rest sheet (no motion).
  Result<RestCalibration> calibrate_at_rest(double t_s, int frames);

  // The sleeve taken off and put on again: new per-strip offsets.
  void set_donning(std::uint32_t index);
  const std::vector<std::uint8_t>& damaged_cells() const noexcept { return damaged_; }
  void repair() { std::fill(damaged_.begin(), damaged_.end(), 0); }

  std::size_t row_count() const noexcept { return plan_.size(); }
  double frame_period_s() const noexcept;
  const Eigen::MatrixXd& measurement_matrix() const noexcept { return M_; }
  const ArraySheet& sheet() const noexcept { return sheet_; }
  const BoardOptions& options() const noexcept { return options_; }
  // The resistances in use (after longest_strip_ohm scaling).
  double sheet_ohm_per_square() const noexcept { return r_square_; }
  double lead_ohm() const noexcept { return r_lead_; }

 private:
  BoardSimulator() = default;
  struct Branch {
    std::size_t cell = 0;
    double c_f = 0.0;
    double return_ohm = 0.0;
  };
  // Row physics at time t: parasitic at the node, branches per source chain.
  double node_parasitic_f(std::size_t row, double t_s) const;
  double measure_period_s(std::size_t row, const SheetState& state, double t_s, std::uint64_t frame_key, bool noisy) const;
  double open_pads_f(double t_s) const;
  double board_node_f(double t_s) const;
  bool lead_broken(bool top, std::size_t strip, double t_s) const;

  ArraySheet sheet_;
  BoardOptions options_;
  std::vector<stretch_array::StripArrayLayout::Measurement> plan_;
  Eigen::MatrixXd M_;
  double r_square_ = 0.0, r_lead_ = 0.0;
  std::vector<double> strip_parasitic_f_;  // top strips, then bottom
  std::vector<double> donning_offset_f_;
  std::vector<std::uint8_t> damaged_;
  std::uint64_t frames_ = 0;
};

}  // namespace proprio::stretch_array_sim
