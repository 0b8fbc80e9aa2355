#pragma once
// A stretch sensor array (input/stretch_array) on the stretch read-out board:
// the board plan that serves an array's measurement plan, an emulator
// provider that measures a known array, and StretchArrayReader, the host side
// that feeds the board's stream into the array's matrix read-out and yields
// cell capacitances.
//
// The plan. The board reports combination c for row c of
// StripArrayLayout::measurement_plan(true): c < n k is the pair (c / k, c % k)
// (M^I has a row for every pair, whether or not the two strips cross: a pair
// that does not cross still charges the cells of both strips), and
// n k <= c < n k + n + k is single strip c - n k, top strips first (M^II). So
// the combination is the row index of measurement_matrix(true), with no table
// in between; stretch_array_plan() refuses layouts the wire cannot carry.
//
// Parasitic capacitance. The board subtracts one stray capacitance from every
// reading (StretchDeviceInfo::parasitic_ff, measured on two unconnected pads;
// Glauser 2019, App. B.2). What remains differs per row: each source set has
// its own leads, traces and multiplexer channels. The reader subtracts a
// per-row vector (pF, row order) before the solve. It comes from a
// calibration recording averaged per row (StretchRowMeans):
//   - open leads: the sheet unplugged from the leads' far end, so the board
//     measures only leads and traces: the row means are the vector;
//   - at rest: the array flat and unstretched: the row means less the rows'
//     modelled rest capacitance (M C0, eq. 4.1 from each cell's rest area),
//     row_parasitics_at_rest(). This also absorbs the rest model's error
//     into the vector, so rest frames read exactly C0: fine for strain, not
//     for checking the model.
// Either is stored with the layout's calibration by whoever records it; the
// reader only takes the numbers.
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"

namespace proprio::devices {

// What a board must be set up to measure for a layout.
struct StretchArrayPlan {
  std::uint8_t top_strips = 0;
  std::uint8_t bottom_strips = 0;
  bool single_strips = true;
  std::size_t rows() const noexcept { return stretch_row_count(top_strips, bottom_strips, single_strips); }
};
// Errors (invalid_argument, naming the layout) when the layout is invalid,
// has more than 32 strips in a layer, or its rows do not fit the 10-bit
// combination field. single_strips = false is for a layout M^I alone can
// read; the reader still builds M with M^II and leaves those rows out.
Result<StretchArrayPlan> stretch_array_plan(const stretch_array::StripArrayLayout& layout, bool single_strips = true);

// The emulator options of `base` with the plan's strip counts and single strips.
Result<StretchEmulatorOptions> stretch_array_emulator_options(const stretch_array::StripArrayLayout& layout,
                                                              StretchEmulatorOptions base = {},
                                                              bool single_strips = true);

// Cell capacitances (pF, one per layout cell) at t_ns; fills `cells_pf`.
using StretchArrayCells = std::function<void(TimeNs t_ns, std::span<double> cells_pf)>;
// A provider for StretchEmulator that measures row c as the sum of the cells
// that charge in it (row c of measurement_matrix(true)) plus
// row_parasitic_pf[c] (empty: none), i.e. C_m = M C_c + p: what the reader
// inverts. The layout is copied. Combinations beyond the plan read NaN (no signal).
StretchCapacitanceProvider stretch_array_provider(const stretch_array::StripArrayLayout& layout,
                                                  StretchArrayCells cells, std::vector<double> row_parasitic_pf = {});

// Per-row means of a calibration recording (see the top of this file).
class StretchRowMeans {
 public:
  explicit StretchRowMeans(std::size_t rows) : sum_pf_(rows, 0.0), count_(rows, 0) {}
  // Flagged samples and combinations beyond `rows` are skipped (counted).
  void add(std::span<const StretchSample> samples) noexcept;
  // The mean of every row, or an error naming the rows with fewer than min_samples.
  Result<std::vector<double>> means(std::size_t min_samples = 1) const;
  std::size_t skipped() const noexcept { return skipped_; }

 private:
  std::vector<double> sum_pf_;
  std::vector<std::size_t> count_;
  std::size_t skipped_ = 0;
};
// The at-rest calibration: row means (pF, measurement_matrix(true) rows) less
// M C0. Errors when the sizes differ or a value is not finite.
Result<std::vector<double>> row_parasitics_at_rest(const stretch_array::StripArrayLayout& layout,
                                                   std::span<const double> row_means_pf);
// The rest capacitances make_array_readout() uses (eq. 4.1 from the rest areas), pF.
std::vector<double> array_rest_capacitances_pf(const stretch_array::StripArrayLayout& layout);

struct StretchArrayReaderOptions {
  // solve_every, the mean filter, dead cells. full_scale_pf defaults to the
  // wire's full scale: the board flags saturated readings itself (those are
  // left out by status), so the read-out need not guess the board's.
  stretch_array::ReadoutOptions readout = default_readout();
  // Subtracted from each row before the solve, pF, in row (combination)
  // order: empty (none) or one per row of measurement_plan(true).
  std::vector<double> row_parasitic_pf;
  // A reading the subtraction takes below zero by at most this much reads 0:
  // the wire's 1 fF step and calibration noise on a row that holds (almost)
  // nothing. Further below, the calibration no longer fits that row, and it
  // sits out of the solve like a flagged reading (counted below_parasitic).
  double negative_tolerance_pf = 0.01;
  // Refuse reports of a board that does not measure single strips (the
  // stream decoder calls them wrong_layout). Off: their rows sit out of the
  // solve, which works only where M^I alone has full rank.
  bool require_single_strips = true;

  static stretch_array::ReadoutOptions default_readout() {
    stretch_array::ReadoutOptions o;
    o.full_scale_pf = kStretchWireFullScalePf + 1.0;
    return o;
  }
  Status validate(std::size_t rows) const;
  std::string describe() const;
};

struct StretchArrayReaderStats {
  std::uint64_t measurements = 0;     // recorded into the read-out
  std::uint64_t flagged = 0;          // of them, flagged by board or host: recorded as unusable
  std::uint64_t clamped = 0;          // within negative_tolerance_pf below zero after the subtraction: recorded as 0
  std::uint64_t below_parasitic = 0;  // further below: recorded as unusable
  std::uint64_t out_of_plan = 0;      // combinations beyond the layout's rows: ignored
  std::uint64_t epochs = 0;           // times the read-out was reset for a new board epoch
  std::uint64_t frames = 0;
};

class StretchArrayReader {
 public:
  static Result<StretchArrayReader> create(const stretch_array::StripArrayLayout& layout,
                                           StretchArrayReaderOptions options = {});

  // A frame sized for the layout, for add() and push_report().
  stretch_array::CellFrame make_frame() const { return readout_.make_frame(); }

  // Records a burst of decoded samples (one report's, or a backlog the
  // reader thread took in one go) and solves once at its end if a frame is
  // due: true then, with the frame in `out`. Flagged samples make their row
  // unusable until it is measured again. A sample's time is its time_ns
  // (StretchDevice's host time), or its device time when that is 0 (the
  // stream decoder alone). A sample of another epoch (the board restarted)
  // resets the read-out first: its rows may mean other strips now.
  bool add(std::span<const StretchSample> samples, stretch_array::CellFrame& out);

  // The whole host path for one raw report: the stream decoder (with this
  // layout's expected strips and plan), then add(). `frame` says whether
  // `out` holds a new frame.
  struct PushResult {
    StretchPushResult report;
    bool frame = false;
  };
  PushResult push_report(std::span<const std::uint8_t> report, TimeNs receive_ns, stretch_array::CellFrame& out);

  // Options for a StretchStreamDecoder (or StretchDeviceOptions::stream) that
  // refuses boards measuring other strips or no single strips.
  StretchStreamOptions stream_options() const;
  const StretchStreamDecoder& stream() const noexcept { return stream_; }
  const stretch_array::MatrixReadout& readout() const noexcept { return readout_; }
  const StretchArrayPlan& plan() const noexcept { return plan_; }
  const StretchArrayReaderStats& stats() const noexcept { return stats_; }
  std::size_t rows() const noexcept { return readout_.measurement_count(); }
  void reset();

 private:
  StretchArrayReader(StretchArrayPlan plan, stretch_array::MatrixReadout readout, StretchArrayReaderOptions options);

  StretchArrayPlan plan_;
  stretch_array::MatrixReadout readout_;
  StretchArrayReaderOptions options_;
  StretchStreamDecoder stream_;
  StretchArrayReaderStats stats_;
  bool have_epoch_ = false;
  std::uint32_t epoch_ = 0;
};

}  // namespace proprio::devices
