#include "proprio/stretch_array/matrix_readout.hpp"

#include <Eigen/LU>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array/capacitance.hpp"

namespace proprio::stretch_array {

Status ReadoutOptions::validate() const {
  auto bad = [](const char* field, double v, const char* what) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "read-out option %s = %g is not usable: %s", field, v, what);
    return make_error(Errc::invalid_argument, buf);
  };
  if (solve_every < 1 || solve_every > 100000) return bad("solve_every", solve_every, "must be 1-100000 updates");
  if (mean_filter_frames < 1 || mean_filter_frames > 1000) {
    return bad("mean_filter_frames", mean_filter_frames, "must be 1-1000 frames");
  }
  if (!(full_scale_pf > 0.0) || !std::isfinite(full_scale_pf)) {
    return bad("full_scale_pf", full_scale_pf, "must be the board's full scale in pF, above 0");
  }
  if (!(dead_fraction >= 0.0 && dead_fraction < 1.0)) {
    return bad("dead_fraction", dead_fraction, "must be a fraction of the rest capacitance, 0 to below 1");
  }
  if (dead_after_frames < 0 || dead_after_frames > 100000) {
    return bad("dead_after_frames", dead_after_frames, "must be 0 (one cycle plus the filter window) to 100000 frames");
  }
  if (cached_factorisations < 1 || cached_factorisations > 4096) {
    return bad("cached_factorisations", cached_factorisations, "must be 1-4096");
  }
  return {};
}

std::string ReadoutOptions::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "solve every %d updates, mean filter over %d frames, full scale %.0f pF, dead below %.0f%% of C0 for "
                "%d frames (0 = a cycle plus the window), %d cached factorisations",
                solve_every, mean_filter_frames, full_scale_pf, dead_fraction * 100.0, dead_after_frames,
                cached_factorisations);
  return buf;
}

std::string_view to_string(CellStatus s) noexcept {
  switch (s) {
    case CellStatus::valid: return "valid";
    case CellStatus::unobservable: return "unobservable";
    case CellStatus::dead: return "dead";
  }
  return "invalid_status";
}

bool CellFrame::all_valid() const noexcept {
  return std::all_of(status.begin(), status.end(), [](CellStatus s) { return s == CellStatus::valid; });
}

Result<MatrixReadout> MatrixReadout::create(Eigen::MatrixXd M, std::vector<double> rest_pf, ReadoutOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  if (M.cols() == 0 || M.rows() < M.cols() || rest_pf.size() != static_cast<std::size_t>(M.cols())) {
    return make_error(Errc::invalid_argument,
                      "matrix read-out: needs at least as many measurements as cells and one rest capacitance per "
                      "cell (" + std::to_string(M.rows()) + " x " + std::to_string(M.cols()) + ", " +
                          std::to_string(rest_pf.size()) + " rest capacitances)");
  }
  for (double c0 : rest_pf) {
    if (!(std::isfinite(c0) && c0 > 0.0)) {
      return make_error(Errc::invalid_argument, "matrix read-out: rest capacitances must be finite and positive (pF)");
    }
  }
  if (Eigen::FullPivLU<Eigen::MatrixXd> lu(M); lu.rank() < M.cols()) {
    return make_error(Errc::invalid_argument, "matrix read-out: the measurement matrix has rank " +
                                                  std::to_string(lu.rank()) + " for " + std::to_string(M.cols()) +
                                                  " cells; they cannot all be read out");
  }
  MatrixReadout r;
  r.options_ = options;
  r.M_ = std::move(M);
  r.rest_pf_ = std::move(rest_pf);
  const auto m = static_cast<Eigen::Index>(r.measurement_count());
  const auto n = static_cast<Eigen::Index>(r.cell_count());
  r.latest_ = Eigen::VectorXd::Zero(m);
  r.latest_usable_.assign(static_cast<std::size_t>(m), 0);
  r.window_ = Eigen::MatrixXd::Zero(m, options.mean_filter_frames);
  r.window_usable_.assign(static_cast<std::size_t>(m * options.mean_filter_frames), 0);
  r.mask_.assign((static_cast<std::size_t>(m) + 63) / 64, 0);
  r.rhs_ = Eigen::VectorXd::Zero(m);
  r.solution_ = Eigen::VectorXd::Zero(n);
  r.last_good_.assign(r.rest_pf_.begin(), r.rest_pf_.end());
  r.frames_below_.assign(static_cast<std::size_t>(n), 0);
  r.dead_after_ = options.dead_after_frames > 0
                      ? options.dead_after_frames
                      : static_cast<int>((m + options.solve_every - 1) / options.solve_every) + options.mean_filter_frames;
  r.cache_.reserve(static_cast<std::size_t>(options.cached_factorisations));
  // The fault-free case, factorised up front so the steady state never does.
  std::vector<std::uint64_t> all(r.mask_.size(), 0);
  for (Eigen::Index i = 0; i < m; ++i) all[static_cast<std::size_t>(i / 64)] |= std::uint64_t{1} << (i % 64);
  (void)r.factorisation_for(all);
  return r;
}

CellFrame MatrixReadout::make_frame() const {
  CellFrame f;
  f.cells_pf.assign(cell_count(), 0.0f);
  f.status.assign(cell_count(), CellStatus::unobservable);
  return f;
}

void MatrixReadout::reset() {
  latest_.setZero();
  std::fill(latest_usable_.begin(), latest_usable_.end(), 0);
  window_.setZero();
  std::fill(window_usable_.begin(), window_usable_.end(), 0);
  window_next_ = 0;
  window_filled_ = 0;
  last_good_.assign(rest_pf_.begin(), rest_pf_.end());
  std::fill(frames_below_.begin(), frames_below_.end(), 0);
  updates_ = 0;
  rejected_ = 0;
  frames_ = 0;
  due_ = false;
  latest_time_ns_ = 0;
}

const MatrixReadout::Factorisation& MatrixReadout::factorisation_for(const std::vector<std::uint64_t>& mask) {
  ++use_clock_;
  for (auto& f : cache_) {
    if (f.mask == mask) {
      f.last_used = use_clock_;
      return f;
    }
  }
  // A new fault pattern: least squares on the rows still in use. Zeroing the
  // other rows of M leaves their columns of M^+ zero, which is the
  // pseudo-inverse of the reduced system.
  Eigen::MatrixXd Mr = M_;
  for (Eigen::Index r = 0; r < Mr.rows(); ++r) {
    if (!(mask[static_cast<std::size_t>(r / 64)] >> (r % 64) & 1u)) Mr.row(r).setZero();
  }
  Factorisation f;
  f.mask = mask;
  f.last_used = use_clock_;
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(Mr);
  f.pinv = cod.pseudoInverse();
  f.observable.assign(static_cast<std::size_t>(Mr.cols()), 1);
  if (cod.rank() < Mr.cols()) {
    // A cell is determined by the remaining rows exactly when no null-space
    // direction moves it.
    Eigen::FullPivLU<Eigen::MatrixXd> lu(Mr);
    const Eigen::MatrixXd K = lu.kernel();
    for (Eigen::Index c = 0; c < Mr.cols(); ++c) {
      if (K.row(c).cwiseAbs().maxCoeff() > 1e-9) f.observable[static_cast<std::size_t>(c)] = 0;
    }
  }
  if (cache_.size() < static_cast<std::size_t>(options_.cached_factorisations)) {
    cache_.push_back(std::move(f));
    return cache_.back();
  }
  // Evict the least recently used, but never the fault-free entry (index 0).
  auto victim = std::min_element(cache_.begin() + 1, cache_.end(),
                                 [](const Factorisation& a, const Factorisation& b) { return a.last_used < b.last_used; });
  if (victim == cache_.end()) victim = cache_.begin();
  *victim = std::move(f);
  return *victim;
}

void MatrixReadout::write_frame(const Eigen::VectorXd& rhs, const Factorisation& f, TimeNs time_ns, bool streaming,
                                CellFrame& out) {
  solution_.noalias() = f.pinv * rhs;
  const std::size_t n = cell_count();
  if (out.cells_pf.size() != n) out.cells_pf.assign(n, 0.0f);
  if (out.status.size() != n) out.status.assign(n, CellStatus::unobservable);
  for (std::size_t c = 0; c < n; ++c) {
    const double v = solution_(static_cast<Eigen::Index>(c));
    if (!f.observable[c] || !std::isfinite(v)) {
      out.status[c] = CellStatus::unobservable;
      out.cells_pf[c] = last_good_[c];
      continue;
    }
    const bool below = v < options_.dead_fraction * rest_pf_[c];
    // A single C_m vector has no history: judge it as it is.
    const int below_frames = below ? (streaming ? frames_below_[c] + 1 : dead_after_ + 1) : 0;
    if (streaming) frames_below_[c] = below_frames;
    if (below_frames > dead_after_) {
      out.status[c] = CellStatus::dead;
      out.cells_pf[c] = static_cast<float>(v);
    } else {
      out.status[c] = CellStatus::valid;
      out.cells_pf[c] = static_cast<float>(v);
      last_good_[c] = out.cells_pf[c];
    }
  }
  out.time_ns = time_ns;
  out.sequence = frames_++;
}

bool MatrixReadout::push(std::size_t combination, double capacitance_pf, TimeNs time_ns, CellFrame& out) {
  return record(combination, capacitance_pf, time_ns) && solve_due(out);
}

bool MatrixReadout::record(std::size_t combination, double capacitance_pf, TimeNs time_ns) {
  if (combination >= measurement_count()) {
    ++rejected_;
    return due_;
  }
  const auto row = static_cast<Eigen::Index>(combination);
  latest_usable_[combination] = usable(capacitance_pf) ? 1 : 0;
  latest_(row) = latest_usable_[combination] ? capacitance_pf : 0.0;
  latest_time_ns_ = time_ns;
  if (++updates_ % static_cast<std::uint64_t>(options_.solve_every) == 0) due_ = true;
  return due_;
}

bool MatrixReadout::solve_due(CellFrame& out) {
  if (!due_) return false;
  due_ = false;
  const TimeNs time_ns = latest_time_ns_;

  // This frame of C_m: the latest value of every combination.
  const Eigen::Index m = M_.rows();
  const int F = options_.mean_filter_frames;
  window_.col(window_next_) = latest_;
  std::copy(latest_usable_.begin(), latest_usable_.end(),
            window_usable_.begin() + static_cast<std::ptrdiff_t>(window_next_) * m);
  window_next_ = (window_next_ + 1) % F;
  window_filled_ = std::min(window_filled_ + 1, F);

  // Mean filter per row over the frames in which it was usable; a row whose
  // latest reading is unusable sits out until it is measured again.
  std::fill(mask_.begin(), mask_.end(), 0);
  std::size_t used = 0;
  for (Eigen::Index r = 0; r < m; ++r) {
    double sum = 0.0;
    int count = 0;
    if (latest_usable_[static_cast<std::size_t>(r)]) {
      for (int k = 0; k < window_filled_; ++k) {
        if (window_usable_[static_cast<std::size_t>(k * m + r)]) {
          sum += window_(r, k);
          ++count;
        }
      }
    }
    if (count > 0) {
      rhs_(r) = sum / count;
      mask_[static_cast<std::size_t>(r / 64)] |= std::uint64_t{1} << (r % 64);
      ++used;
    } else {
      rhs_(r) = 0.0;
    }
  }
  const Factorisation& f = factorisation_for(mask_);
  write_frame(rhs_, f, time_ns, true, out);
  out.rows_used = used;
  out.rows_excluded = static_cast<std::size_t>(m) - used;
  return true;
}

Status MatrixReadout::solve(std::span<const double> measurements_pf, TimeNs time_ns, CellFrame& out) {
  if (measurements_pf.size() != measurement_count()) {
    return make_error(Errc::invalid_argument, "a C_m vector for this layout has " +
                                                  std::to_string(measurement_count()) +
                                                  " measurements (top_strips x bottom_strips), but this one has " +
                                                  std::to_string(measurements_pf.size()));
  }
  std::fill(mask_.begin(), mask_.end(), 0);
  std::size_t used = 0;
  for (std::size_t r = 0; r < measurements_pf.size(); ++r) {
    const bool ok = usable(measurements_pf[r]);
    rhs_(static_cast<Eigen::Index>(r)) = ok ? measurements_pf[r] : 0.0;
    if (ok) {
      mask_[r / 64] |= std::uint64_t{1} << (r % 64);
      ++used;
    }
  }
  const Factorisation& f = factorisation_for(mask_);
  write_frame(rhs_, f, time_ns, false, out);
  out.rows_used = used;
  out.rows_excluded = measurements_pf.size() - used;
  return {};
}

Result<MatrixReadout> make_array_readout(const StripArrayLayout& layout, ReadoutOptions options) {
  if (auto st = layout.validate(); !st) return st.error();
  std::vector<double> rest_pf;
  for (std::size_t c = 0; c < layout.cell_count(); ++c) {
    rest_pf.push_back(1e12 * plate_capacitance_f(layout.sheet.relative_permittivity, layout.rest_area_m2(c),
                                                 layout.sheet.dielectric_thickness_m));
  }
  return MatrixReadout::create(layout.measurement_matrix(true), std::move(rest_pf), options);
}

}  // namespace proprio::stretch_array
