#pragma once
// Matrix read-out of a capacitive stretch sensor array (Glauser 2019, Sec.
// 4.3.2 and 5.2.1): recovers the cell capacitances C_c from the board's
// time-multiplexed measurements C_m = M C_c by least squares, C_c = M^+ C_m
// (eq. 4.6). The one read-out of every such sensor: the stretch glove's
// (stretch_glove/readout.hpp gives it the glove layout's matrix) and the
// arrays' (make_array_readout() below).
//
// As in the thesis, measurements arrive one strip combination at a time; the
// read-out keeps the latest value of each combination, and every
// `solve_every` (16) updates it takes that vector as a frame of C_m, averages
// the last `mean_filter_frames` (5) frames and solves. So a frame mixes
// measurements up to one full cycle (182 updates, 0.19 s at 960 updates/s)
// plus the filter window old: a recovered frame lags the hand by about 0.14 s
// on average. CellFrame::time_ns is the time of the newest measurement in it.
//
// Robustness. A measurement that is NaN, negative or at/above the board's
// full scale is not used: its row is left out of the solve until the
// combination is measured again. The pseudo-inverse of each set of rows used
// is computed once and cached (the all-rows one up front), so the steady
// state neither factorises nor allocates. Cells the remaining rows cannot
// determine are flagged unobservable (and hold their last good value); a
// cell recovered far below its rest capacitance for longer than a spike could
// cause (an open lead) is flagged dead.
//
// Outliers are not rejected: with measurements of different ages in one
// C_m (a moving hand), residuals of 5-15 pF are normal, as large as small
// spikes, so a residual test would mostly throw away good rows.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio::stretch_array {

struct StripArrayLayout;

struct ReadoutOptions {
  int solve_every = 16;         // updates between solves (thesis: 16)
  int mean_filter_frames = 5;   // frames of C_m averaged before a solve (thesis: 5)
  double full_scale_pf = 500.0; // the board's full scale: readings at or above it are saturated
  // A cell recovered below this fraction of its rest capacitance C0 for more
  // than dead_after_frames frames in a row is dead (an open lead reads ~0; a
  // live cell on a hand reads about C0 or more). The wait keeps a spike in a
  // single measurement, which least squares spreads over many cells for up
  // to a cycle, from declaring a live cell dead. 0: one full cycle of
  // measurements plus the filter window (17 frames for the thesis glove).
  double dead_fraction = 0.2;
  int dead_after_frames = 0;
  // Pseudo-inverses kept for sets of rows with faults (least recently used goes first).
  int cached_factorisations = 16;

  Status validate() const;
  std::string describe() const;
};

enum class CellStatus : std::uint8_t {
  valid = 0,
  unobservable = 1,  // the rows in use do not determine it (or no measurement yet)
  dead = 2,          // recovered far below its rest capacitance
};
std::string_view to_string(CellStatus s) noexcept;

struct CellFrame {
  TimeNs time_ns = 0;          // the newest measurement in this frame
  std::uint64_t sequence = 0;  // frames produced by this read-out, from 0
  std::vector<float> cells_pf;       // recovered C_c, one per layout cell
  std::vector<CellStatus> status;    // per cell
  std::size_t rows_used = 0;         // measurement rows in the solve
  std::size_t rows_excluded = 0;     // rows left out (never measured, NaN, negative, saturated)

  bool valid(std::size_t cell) const noexcept { return status[cell] == CellStatus::valid; }
  bool all_valid() const noexcept;
};

class MatrixReadout {
 public:
  // M: measurements x cells, entries 0 or 1; rest_pf: each cell's rest
  // capacitance. Errors when the options are unusable, the sizes disagree or
  // M is rank-deficient (its cells cannot be read out).
  static Result<MatrixReadout> create(Eigen::MatrixXd M, std::vector<double> rest_pf, ReadoutOptions options = {});

  // A frame sized for this layout, to pass to push() and solve().
  CellFrame make_frame() const;

  // One measurement, `combination` being its row of M.
  // Returns true when this update completed a frame, which is then in `out`.
  // Does not allocate once `out` has been sized by make_frame() and the fault
  // pattern has been seen before. An out-of-range combination is ignored
  // (counted in rejected_updates()).
  bool push(std::size_t combination, double capacitance_pf, TimeNs time_ns, CellFrame& out);

  // For measurements that arrive in bursts (a read-out board sends 12 per
  // report): record() takes one without solving and returns whether a frame
  // is due (solve_every updates since the last one); solve_due() then makes
  // it from every measurement recorded so far, its time the newest one's.
  // Solving at the end of a burst instead of at the update that made the
  // frame due uses the rest of the burst, which is already in hand, so the
  // frame is fresher at no cost in delivery time. push() is record() and,
  // when due, solve_due().
  bool record(std::size_t combination, double capacitance_pf, TimeNs time_ns);
  bool solve_due(CellFrame& out);  // false (out untouched) when no frame is due
  bool frame_due() const noexcept { return due_; }

  // Solves one whole C_m vector (measurement_count() entries, row order of
  // the measurement matrix) directly: no window, same exclusion rules.
  Status solve(std::span<const double> measurements_pf, TimeNs time_ns, CellFrame& out);

  // Forget every measurement and frame (the factorisations stay cached).
  void reset();

  std::size_t cell_count() const noexcept { return static_cast<std::size_t>(M_.cols()); }
  std::size_t measurement_count() const noexcept { return static_cast<std::size_t>(M_.rows()); }
  std::uint64_t updates() const noexcept { return updates_; }
  std::uint64_t rejected_updates() const noexcept { return rejected_; }
  std::size_t cached_factorisation_count() const noexcept { return cache_.size(); }
  const ReadoutOptions& options() const noexcept { return options_; }

 private:
  MatrixReadout() = default;
  struct Factorisation {
    std::vector<std::uint64_t> mask;  // bit r set: row r used
    Eigen::MatrixXd pinv;             // cells x rows; columns of unused rows are zero
    std::vector<std::uint8_t> observable;
    std::uint64_t last_used = 0;
  };
  bool usable(double pf) const noexcept { return pf >= 0.0 && pf < options_.full_scale_pf; }  // false for NaN
  const Factorisation& factorisation_for(const std::vector<std::uint64_t>& mask);
  void write_frame(const Eigen::VectorXd& rhs, const Factorisation& f, TimeNs time_ns, bool streaming, CellFrame& out);

  ReadoutOptions options_;
  Eigen::MatrixXd M_;
  std::vector<double> rest_pf_;
  std::vector<Factorisation> cache_;
  std::uint64_t use_clock_ = 0;

  Eigen::VectorXd latest_;                    // latest value per combination
  std::vector<std::uint8_t> latest_usable_;   // 0 until measured, and while its latest reading is unusable
  Eigen::MatrixXd window_;                    // rows x mean_filter_frames
  std::vector<std::uint8_t> window_usable_;   // same layout, column-major
  int window_next_ = 0;
  int window_filled_ = 0;
  std::vector<std::uint64_t> mask_;
  Eigen::VectorXd rhs_;
  Eigen::VectorXd solution_;
  std::vector<float> last_good_;
  std::vector<int> frames_below_;  // consecutive streamed frames each cell was below the dead threshold
  int dead_after_ = 0;
  std::uint64_t updates_ = 0;
  std::uint64_t rejected_ = 0;
  std::uint64_t frames_ = 0;
  bool due_ = false;          // solve_every updates were recorded since the last frame
  TimeNs latest_time_ns_ = 0;  // of the newest recorded measurement
};

// A read-out for an array layout: its measurement plan (M^I + M^II) and
// each cell's rest capacitance from its area and the sheet (eq. 4.1).
Result<MatrixReadout> make_array_readout(const StripArrayLayout& layout, ReadoutOptions options = {});

}  // namespace proprio::stretch_array
