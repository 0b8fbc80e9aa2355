#include "proprio/stretch_array_sim/array_electrical.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

// How series resistance changes what a 555 astable reads.
//
// The 555's threshold and trigger pins watch the timing node on the board.
// The cells hang off that node behind their strips and leads: a row is an RC
// tree, not a capacitor. Take one capacitor C behind a series resistance Rs,
// with no capacitance at the node itself. While charging through Ra = R1 + R2
// from Vcc, the current i = (Vcc - Vc) / (Ra + Rs) raises the pin above the
// capacitor by i Rs, so the pin reaches 2 Vcc / 3 when the capacitor is at
//   Vc_hi = Vcc - (Vcc / 3)(1 + Rs / Ra);
// while discharging through R2 the pin sits i Rs below the capacitor and
// reaches Vcc / 3 when
//   Vc_lo = (Vcc / 3)(1 + Rs / R2).
// The capacitor swings between those with time constants (Ra + Rs) C and
// (R2 + Rs) C:
//   t_c = (Ra + Rs) C ln[(2 - Rs / R2) / (1 + Rs / Ra)]
//   t_d = (R2 + Rs) C ln[(2 - Rs / Ra) / (1 + Rs / R2)]
// (Rs = 0 gives (R1 + 2 R2) C ln 2), and to first order in Rs
//   T / T0 = 1 - Rs (2 - 2 ln 2 + Ra / (2 R2) + R2 / (2 Ra)) / ((R1 + 2 R2) ln 2)
//          ~ 1 - Rs / 63 kOhm  for R1 = 470 k, R2 = 47 k.
// The discharge leg dominates: R2 is small, so the discharge current, and its
// drop over Rs, is large. The board then reads C T / T0, less than the cells
// hold, and because Rs grows as (l/l0)^2 with stretch, a stretched cell reads
// low relative to its own rest reading: eq. 4.8 over-predicts. (For Rs >= R2
// the lumped circuit has no oscillation left; the capacitance at the node
// keeps the real one going, which is why the node is simulated with it.)
//
// A row is simulated as the network itself: the node capacitance (parasitics)
// at the pin; per source strip, a chain from the pin through the lead and the
// strip's pieces to each charging cell's position on it; each cell behind the
// resistance of its other (grounded) strip back to the board. A cell's
// capacitor and its return resistance are in series, so they are swapped to
// put every capacitor to ground; the resistive chain nodes are eliminated
// (Schur complement of the conductance matrix). Per phase the system
// C dv/dt = -G v + g V_src e_pin is linear, solved exactly through the
// eigen-decomposition of C^-1/2 G C^-1/2, and the comparator crossings are
// found by scanning and bisection. The oscillator is run to its periodic
// state and one period is what the board times. The lumped formula above is
// the one-capacitor case (the tests check the two agree). Left out: the
// current through a cell whose two strips are both sources (a pair row's own
// crossing; the two strips differ in voltage only through their resistances),
// the strips' capacitance to the shielding layers, and the 555's discharge
// transistor's on-resistance (tens of ohms).
//
// Jitter: each comparator decision has input-referred noise sigma_v. At the
// upper threshold the node rises at (Vcc / 3) / (Ra C), so its time moves by
// 3 sigma_v Ra C / Vcc; at the lower one by 3 sigma_v R2 C / Vcc: with 0.5 mV
// on 5 V, about 4e-4 of the period, independent from period to period.
// Quantisation: the counter counts reference-clock edges in one period,
// starting at a random phase of the clock.

namespace proprio::stretch_array_sim {

namespace sa = proprio::stretch_array;

namespace {

constexpr double kLn2 = std::numbers::ln2;

std::uint64_t mix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
// Counter-based randomness: the same (seed, keys) always gives the same
// number, whatever was asked before.
double uniform(std::uint64_t seed, std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  const std::uint64_t h = mix(seed ^ mix(a ^ mix(b ^ mix(c))));
  return (static_cast<double>(h >> 11) + 0.5) * 0x1.0p-53;
}
double normal(std::uint64_t seed, std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  const double u1 = uniform(seed, a, b, 2 * c), u2 = uniform(seed, a, b, 2 * c + 1);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}
enum Stream : std::uint64_t {
  kStripParasitic = 1,
  kDriftPeriod,
  kDriftPhase,
  kDonning,
  kJitterHigh,
  kJitterLow,
  kClockPhase,
};

double drift(std::uint64_t seed, std::uint64_t id, double t, const BoardOptions::Parasitic& p) {
  double sum = 0.0;
  for (std::uint64_t m = 0; m < 3; ++m) {
    const double period = p.drift_period_min_s * std::pow(p.drift_period_max_s / p.drift_period_min_s, uniform(seed, kDriftPeriod, id, m));
    const double phase = 2.0 * std::numbers::pi * uniform(seed, kDriftPhase, id, m);
    sum += std::sin(2.0 * std::numbers::pi * t / period + phase);
  }
  return p.drift_std_f * std::sqrt(2.0 / 3.0) * sum;
}

// One row's circuit: capacitor 0 is the timing node, the others the cells.
struct Network {
  Eigen::VectorXd C;  // per capacitor node (F)
  Eigen::MatrixXd G;  // reduced conductance between capacitor nodes (S), no source
};

struct ChainBranch {
  double c_f;
  double along_ohm;   // from the pin along the lead and strip to this branch's attach point
  double return_ohm;  // from the attach point through the cell's other strip to ground
};

// chains: per source strip, its branches ordered along the strip.
Network build_network(double node_f, const std::vector<std::vector<ChainBranch>>& chains) {
  std::size_t n_cap = 1, n_chain = 0;
  for (const auto& ch : chains) {
    n_cap += ch.size();
    n_chain += ch.size();
  }
  const std::size_t N = n_cap + n_chain;
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(N), static_cast<Eigen::Index>(N));
  auto add = [&](std::size_t a, std::size_t b, double ohm) {
    const double g = 1.0 / ohm;
    const auto ia = static_cast<Eigen::Index>(a), ib = static_cast<Eigen::Index>(b);
    G(ia, ia) += g;
    G(ib, ib) += g;
    G(ia, ib) -= g;
    G(ib, ia) -= g;
  };
  Network net;
  net.C.resize(static_cast<Eigen::Index>(n_cap));
  net.C[0] = node_f;
  std::size_t cap = 1, chain = n_cap;
  for (const auto& ch : chains) {
    std::size_t prev = 0;
    double prev_along = 0.0;
    for (std::size_t j = 0; j < ch.size(); ++j) {
      // Coincident attach points still get a (tiny) resistor: chain nodes
      // carry no capacitance, so this adds no stiffness.
      const double seg = std::max(ch[j].along_ohm - prev_along, j == 0 ? 1.0 : 1e-6);
      add(prev, chain, seg);
      add(chain, cap, std::max(ch[j].return_ohm, 1.0));
      net.C[static_cast<Eigen::Index>(cap)] = ch[j].c_f;
      prev = chain;
      prev_along = ch[j].along_ohm;
      ++cap;
      ++chain;
    }
  }
  const auto nc = static_cast<Eigen::Index>(n_cap), nx = static_cast<Eigen::Index>(n_chain);
  if (nx == 0) {
    net.G = G.topLeftCorner(nc, nc);
  } else {
    const Eigen::MatrixXd Gxx = G.bottomRightCorner(nx, nx);
    const Eigen::MatrixXd Gcx = G.topRightCorner(nc, nx);
    net.G = G.topLeftCorner(nc, nc) - Gcx * Gxx.llt().solve(Gcx.transpose());
  }
  return net;
}

// One phase: the node fed from v_src through conductance g.
class Phase {
 public:
  Phase(const Network& net, double g, double v_src) : v_src_(v_src) {
    const Eigen::VectorXd s = net.C.cwiseSqrt().cwiseInverse();
    Eigen::MatrixXd A = net.G;
    A(0, 0) += g;
    const Eigen::MatrixXd S = s.asDiagonal() * A * s.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (S + S.transpose()));
    lambda_ = es.eigenvalues().cwiseMax(1e-3);
    Q_ = es.eigenvectors();
    back_ = s.asDiagonal() * Q_;                          // C^-1/2 Q
    fwd_ = Q_.transpose() * net.C.cwiseSqrt().asDiagonal();  // Q^T C^1/2
  }
  double slowest_tau() const { return 1.0 / lambda_.minCoeff(); }
  // Runs until the node crosses `threshold` (rising or falling), updating v;
  // returns the time taken, or NaN when it never does within max_t.
  double run_until(Eigen::VectorXd& v, double threshold, bool rising, double max_t) const {
    const Eigen::VectorXd c = fwd_ * (v.array() - v_src_).matrix();
    const Eigen::VectorXd w0 = back_.row(0).transpose().cwiseProduct(c);  // node's modal weights
    auto node = [&](double t) { return v_src_ + (w0.array() * (-lambda_.array() * t).exp()).sum(); };
    auto past = [&](double t) { return rising ? node(t) >= threshold : node(t) <= threshold; };
    double lo = 0.0, hi = -1.0;
    if (past(0.0)) {
      hi = 0.0;
    } else {
      const double dt = slowest_tau() / 64.0;
      for (double t = dt; t <= max_t + dt; t += dt) {
        if (past(t)) {
          hi = t;
          break;
        }
        lo = t;
      }
      if (hi < 0.0) return std::numeric_limits<double>::quiet_NaN();
      for (int i = 0; i < 60; ++i) {
        const double mid = 0.5 * (lo + hi);
        (past(mid) ? hi : lo) = mid;
      }
    }
    const double t = hi;
    v = (v_src_ + (back_ * (c.array() * (-lambda_.array() * t).exp()).matrix()).array()).matrix();
    return t;
  }

 private:
  double v_src_;
  Eigen::VectorXd lambda_;
  Eigen::MatrixXd Q_, back_, fwd_;
};

// The periodic state's period, then one more period with the thresholds
// moved by (noise_hi, noise_lo) volts: what the board times.
double network_period(const Network& net, double ra, double r2, double vcc, double noise_hi, double noise_lo) {
  const Phase charge(net, 1.0 / ra, vcc), discharge(net, 1.0 / r2, 0.0);
  const double hi = 2.0 * vcc / 3.0, lo = vcc / 3.0;
  Eigen::VectorXd v = Eigen::VectorXd::Constant(net.C.size(), lo);
  const double max_t = 40.0 * std::max(charge.slowest_tau(), discharge.slowest_tau());
  double last = 0.0;
  for (int cycle = 0; cycle < 40; ++cycle) {
    const double tc = charge.run_until(v, hi, true, max_t);
    const double td = discharge.run_until(v, lo, false, max_t);
    const double T = tc + td;
    if (!std::isfinite(T)) return std::numeric_limits<double>::quiet_NaN();
    if (cycle > 1 && std::abs(T - last) <= 1e-10 * T) break;
    last = T;
  }
  if (noise_hi == 0.0 && noise_lo == 0.0) return last;
  const double tc = charge.run_until(v, hi + noise_hi, true, max_t);
  const double td = discharge.run_until(v, lo + noise_lo, false, max_t);
  return tc + td;
}

// No resistance: one capacitor, the textbook 555 (with the noisy thresholds).
double lumped_period(double c_f, double ra, double r2, double vcc, double noise_hi, double noise_lo) {
  const double hi = 2.0 * vcc / 3.0 + noise_hi, lo = vcc / 3.0;
  const double tc = ra * c_f * std::log((vcc - lo) / (vcc - hi));
  const double td = r2 * c_f * std::log(hi / (lo + noise_lo));
  return tc + td;
}

Error board_error(const std::string& what) { return make_error(Errc::invalid_argument, "array board: " + what); }
bool finite_in(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

}  // namespace

Status BoardOptions::validate() const {
  if (auto t = timer.validate(); !t) return t.error().with_context("array board");
  if (!finite_in(supply_v, 1.0, 30.0)) return board_error("supply_v must be in [1, 30] V");
  const auto& r = resistance;
  if (!finite_in(r.sheet_ohm_per_square, 0.0, 1e7) || !finite_in(r.lead_ohm, 0.0, 1e7) || !finite_in(r.longest_strip_ohm, 0.0, 1e7)) {
    return board_error("resistances must be in [0, 10 MOhm]");
  }
  const auto& p = parasitic;
  if (!finite_in(p.board_f, 0.0, 1e-9) || !finite_in(p.strip_min_f, 0.0, 1e-9) || !finite_in(p.strip_max_f, p.strip_min_f, 1e-9)) {
    return board_error("parasitics must be in [0, 1 nF] with strip_min_f <= strip_max_f");
  }
  if (!finite_in(p.drift_std_f, 0.0, 1e-10) || !(p.drift_period_min_s > 0.0) || !finite_in(p.drift_period_max_s, p.drift_period_min_s, 1e7)) {
    return board_error("parasitic drift: std in [0, 100 pF], 0 < drift_period_min_s <= drift_period_max_s");
  }
  if (!finite_in(timing.row_rate_hz, 1.0, 1e6)) return board_error("timing.row_rate_hz must be in [1, 1e6] Hz");
  if (!finite_in(jitter.comparator_noise_v, 0.0, 0.05 * supply_v)) return board_error("jitter.comparator_noise_v must be in [0, 5 % of the supply]");
  if (!finite_in(over_stretch.limit, 1.0, 100.0) || !finite_in(over_stretch.gain_change, -0.9, 10.0)) {
    return board_error("over_stretch: limit must be >= 1 and gain_change in [-0.9, 10]");
  }
  if (!finite_in(donning.offset_std_f, 0.0, 1e-10)) return board_error("donning.offset_std_f must be in [0, 100 pF]");
  if (broken_lead.enabled && !std::isfinite(broken_lead.from_s)) return board_error("broken_lead.from_s must be finite");
  return {};
}

std::string BoardOptions::describe() const {
  std::ostringstream o;
  o << "555 R1 " << timer.r1_ohm / 1e3 << " kOhm, R2 " << timer.r2_ohm / 1e3 << " kOhm, clock "
    << timer.reference_clock_hz / 1e6 << " MHz, Vcc " << supply_v << " V, seed " << seed << "; resistance ";
  if (resistance.enabled) {
    o << resistance.sheet_ohm_per_square << " ohm/sq + lead " << resistance.lead_ohm << " ohm";
    if (resistance.longest_strip_ohm > 0) o << " scaled to a longest strip of " << resistance.longest_strip_ohm << " ohm";
  } else {
    o << "off";
  }
  o << "; parasitic ";
  if (parasitic.enabled) {
    o << "board " << parasitic.board_f * 1e12 << " pF, strips " << parasitic.strip_min_f * 1e12 << "-"
      << parasitic.strip_max_f * 1e12 << " pF, drift " << parasitic.drift_std_f * 1e12 << " pF";
  } else {
    o << "off";
  }
  o << "; rows ";
  if (timing.enabled) o << "at " << timing.row_rate_hz << " /s"; else o << "simultaneous";
  o << "; jitter ";
  if (jitter.enabled) o << jitter.comparator_noise_v * 1e3 << " mV"; else o << "off";
  o << "; quantise " << (quantise ? "on" : "off") << "; broken lead ";
  if (broken_lead.enabled) {
    o << (broken_lead.top ? "top " : "bottom ") << broken_lead.strip << " from " << broken_lead.from_s << " s";
  } else {
    o << "none";
  }
  o << "; over-stretch ";
  if (over_stretch.enabled) o << "beyond " << over_stretch.limit << "x, gain " << over_stretch.gain_change; else o << "off";
  o << "; donning ";
  if (donning.enabled) o << "#" << donning.index << ", " << donning.offset_std_f * 1e12 << " pF per strip"; else o << "off";
  return o.str();
}

BoardOptions BoardOptions::ideal() {
  BoardOptions o;
  o.resistance.enabled = false;
  o.parasitic.enabled = false;
  o.timing.enabled = false;
  o.jitter.enabled = false;
  o.quantise = false;
  o.broken_lead.enabled = false;
  o.over_stretch.enabled = false;
  o.donning.enabled = false;
  return o;
}

Result<BoardSimulator> BoardSimulator::create(ArraySheet sheet, BoardOptions options) {
  if (auto v = options.validate(); !v) return v.error();
  const auto& L = sheet.layout();
  if (options.broken_lead.enabled && options.broken_lead.strip >= (options.broken_lead.top ? L.top_strips.size() : L.bottom_strips.size())) {
    return board_error("broken_lead.strip " + std::to_string(options.broken_lead.strip) + " does not exist in that layer");
  }
  BoardSimulator b;
  b.plan_ = L.measurement_plan(true);
  b.M_ = L.measurement_matrix(true);
  b.r_square_ = options.resistance.sheet_ohm_per_square;
  b.r_lead_ = options.resistance.lead_ohm;
  if (options.resistance.longest_strip_ohm > 0.0) {
    const double longest = *std::max_element(sheet.strip_rest_squares().begin(), sheet.strip_rest_squares().end());
    const double now = b.r_lead_ + b.r_square_ * longest;
    if (!(now > 0.0)) return board_error("resistance.longest_strip_ohm needs a non-zero sheet or lead resistance to scale");
    const double k = options.resistance.longest_strip_ohm / now;
    b.r_square_ *= k;
    b.r_lead_ *= k;
  }
  const std::size_t strips = L.top_strips.size() + L.bottom_strips.size();
  b.strip_parasitic_f_.resize(strips);
  for (std::size_t s = 0; s < strips; ++s) {
    b.strip_parasitic_f_[s] = options.parasitic.strip_min_f +
                              (options.parasitic.strip_max_f - options.parasitic.strip_min_f) * uniform(options.seed, kStripParasitic, s, 0);
  }
  b.damaged_.assign(L.cells.size(), 0);
  b.sheet_ = std::move(sheet);
  b.options_ = options;
  b.set_donning(options.donning.index);
  return b;
}

void BoardSimulator::set_donning(std::uint32_t index) {
  options_.donning.index = index;
  const std::size_t strips = sheet_.layout().top_strips.size() + sheet_.layout().bottom_strips.size();
  donning_offset_f_.assign(strips, 0.0);
  // A strip's lead parasitic cannot go below zero: offsets are clamped at it.
  for (std::size_t s = 0; s < strips; ++s) {
    const double off = options_.donning.offset_std_f * normal(options_.seed, kDonning, index, s);
    donning_offset_f_[s] = std::max(off, -strip_parasitic_f_[s]);
  }
}

double BoardSimulator::frame_period_s() const noexcept { return static_cast<double>(plan_.size()) / options_.timing.row_rate_hz; }

bool BoardSimulator::lead_broken(bool top, std::size_t strip, double t_s) const {
  const auto& b = options_.broken_lead;
  return b.enabled && b.top == top && b.strip == strip && t_s >= b.from_s;
}

// The thesis's parasitic channel: two unconnected connector-board pads,
// wired through the same switch board and flexible wires as the strips, so
// it reads the board and one typical lead (the middle of the strips' range),
// not any particular strip's lead, and one lead where a pair row has two.
double BoardSimulator::open_pads_f(double t_s) const {
  if (!options_.parasitic.enabled) return 0.0;
  const auto& p = options_.parasitic;
  return std::max(0.0, p.board_f + 0.5 * (p.strip_min_f + p.strip_max_f) + drift(options_.seed, 0, t_s, p));
}

double BoardSimulator::board_node_f(double t_s) const {
  if (!options_.parasitic.enabled) return 0.0;
  return std::max(0.0, options_.parasitic.board_f + drift(options_.seed, 0, t_s, options_.parasitic));
}

double BoardSimulator::node_parasitic_f(std::size_t row, double t_s) const {
  const auto& m = plan_[row];
  const std::size_t n_top = sheet_.layout().top_strips.size();
  double c = board_node_f(t_s);
  auto strip = [&](std::size_t s) {
    double v = 0.0;
    if (options_.parasitic.enabled) v += strip_parasitic_f_[s] + drift(options_.seed, 1 + s, t_s, options_.parasitic);
    if (options_.donning.enabled) v += donning_offset_f_[s];
    return std::max(0.0, v);
  };
  for (std::size_t t : m.top_sources) c += strip(t);
  for (std::size_t b : m.bottom_sources) c += strip(n_top + b);
  return c;
}

double BoardSimulator::measure_period_s(std::size_t row, const SheetState& state, double t_s, std::uint64_t frame_key, bool noisy) const {
  const auto& L = sheet_.layout();
  const auto& m = plan_[row];
  const auto& tm = options_.timer;
  const double ra = tm.r1_ohm + tm.r2_ohm, r2 = tm.r2_ohm, vcc = options_.supply_v;
  auto is_src_top = [&](std::size_t t) { return std::find(m.top_sources.begin(), m.top_sources.end(), t) != m.top_sources.end(); };
  auto is_src_bot = [&](std::size_t b) { return std::find(m.bottom_sources.begin(), m.bottom_sources.end(), b) != m.bottom_sources.end(); };
  auto cell_c = [&](std::size_t c) {
    double v = state.cell_f[c];
    if (options_.over_stretch.enabled && damaged_[c]) v *= 1.0 + options_.over_stretch.gain_change;
    return v;
  };
  // A broken grounded strip floats: a cell charging into it sees, in series,
  // the strip's other cells that go to ground through their own strips.
  auto floating_series = [&](std::size_t c, bool via_top) {
    double rest = 0.0;
    for (std::size_t o = 0; o < L.cells.size(); ++o) {
      if (o == c) continue;
      if (via_top ? L.cells[o].top != L.cells[c].top : L.cells[o].bottom != L.cells[c].bottom) continue;
      const bool other_src = via_top ? is_src_bot(L.cells[o].bottom) : is_src_top(L.cells[o].top);
      if (!other_src) rest += cell_c(o);
    }
    const double ci = cell_c(c);
    return rest > 0.0 ? ci * rest / (ci + rest) : 0.0;
  };

  // Per source strip, its charging cells in order along it.
  std::vector<std::vector<ChainBranch>> chains;
  double total_c = node_parasitic_f(row, t_s);
  const bool res = options_.resistance.enabled;
  auto add_chain = [&](bool top, std::size_t s) {
    if (lead_broken(top, s, t_s)) return;  // its cells are cut off; its lead's parasitic stays
    std::vector<std::pair<double, ChainBranch>> branches;
    for (std::size_t c = 0; c < L.cells.size(); ++c) {
      const auto& cell = L.cells[c];
      if (top ? cell.top != s : cell.bottom != s) continue;
      const bool other_broken = top ? lead_broken(false, cell.bottom, t_s) : lead_broken(true, cell.top, t_s);
      const bool other_src = !other_broken && (top ? is_src_bot(cell.bottom) : is_src_top(cell.top));
      if (other_src) continue;  // both plates on the source: no charge
      const double cf = other_broken ? floating_series(c, !top) : cell_c(c);
      if (!(cf > 0.0)) continue;
      const double along_sq = top ? state.top_squares[c] : state.bottom_squares[c];
      const double return_sq = top ? state.bottom_squares[c] : state.top_squares[c];
      branches.push_back({along_sq, {cf, r_lead_ + r_square_ * along_sq, r_lead_ + r_square_ * return_sq}});
      total_c += cf;
    }
    std::sort(branches.begin(), branches.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<ChainBranch> chain;
    for (auto& b : branches) chain.push_back(b.second);
    if (!chain.empty()) chains.push_back(std::move(chain));
  };
  for (std::size_t t : m.top_sources) add_chain(true, t);
  for (std::size_t b : m.bottom_sources) add_chain(false, b);

  double noise_hi = 0.0, noise_lo = 0.0;
  if (noisy && options_.jitter.enabled) {
    noise_hi = options_.jitter.comparator_noise_v * normal(options_.seed, kJitterHigh, frame_key, row);
    noise_lo = options_.jitter.comparator_noise_v * normal(options_.seed, kJitterLow, frame_key, row);
  }
  // The node needs some capacitance of its own for the network to be a
  // circuit; a 555's pins alone have a few pF. Without parasitics modelled,
  // a token 1e-4 pF keeps the network well posed while changing nothing.
  if (!res || chains.empty()) return lumped_period(total_c, ra, r2, vcc, noise_hi, noise_lo);
  const double node_f = std::max(node_parasitic_f(row, t_s), 1e-16);
  return network_period(build_network(node_f, chains), ra, r2, vcc, noise_hi, noise_lo);
}

Result<double> BoardSimulator::apparent_row_f(std::size_t row, const SheetState& state, double t_s) const {
  if (row >= plan_.size()) return board_error("row " + std::to_string(row) + " is beyond the plan's " + std::to_string(plan_.size()));
  if (state.cell_f.size() != sheet_.cell_count()) return board_error("the sheet state does not match the layout's cells");
  const double T = measure_period_s(row, state, t_s, 0, false);
  const auto& tm = options_.timer;
  return T / ((tm.r1_ohm + 2.0 * tm.r2_ohm) * kLn2);
}

Result<BoardFrame> BoardSimulator::measure_frame(double t_frame_s, const StateProvider& sheet_at) {
  if (!sheet_at) return board_error("no sheet provider");
  const std::uint64_t key = ++frames_;
  const auto& tm = options_.timer;
  BoardFrame f;
  f.t_s = t_frame_s;
  f.row_time_s.resize(plan_.size());
  f.rows_pf.resize(plan_.size());
  for (std::size_t r = 0; r < plan_.size(); ++r) {
    const double t = options_.timing.enabled ? t_frame_s + static_cast<double>(r) / options_.timing.row_rate_hz : t_frame_s;
    f.row_time_s[r] = t;
    auto state = sheet_at(t);
    if (!state) return state.error().with_context("array board, row " + std::to_string(r) + " at t = " + std::to_string(t) + " s");
    if (state->cell_f.size() != sheet_.cell_count() || state->top_squares.size() != sheet_.cell_count() ||
        state->bottom_squares.size() != sheet_.cell_count() || state->cell_max_stretch.size() != sheet_.cell_count()) {
      return board_error("the provider's sheet state does not match the layout's " + std::to_string(sheet_.cell_count()) + " cells");
    }
    if (options_.over_stretch.enabled) {
      for (std::size_t c = 0; c < damaged_.size(); ++c) {
        if (state->cell_max_stretch[c] > options_.over_stretch.limit) damaged_[c] = 1;
      }
    }
    double T = measure_period_s(r, *state, t, key, true);
    if (options_.quantise && std::isfinite(T)) {
      // Edges counted from a random phase of the reference clock.
      const double phase = uniform(options_.seed, kClockPhase, key, r);
      T = std::floor(T * tm.reference_clock_hz + phase) / tm.reference_clock_hz;
    }
    // A row with nothing that oscillates (or a period of zero counts) reads
    // as the board's full scale would: not a number.
    f.rows_pf[r] = T > 0.0 ? tm.capacitance_f(1.0 / T) * 1e12 : std::numeric_limits<double>::quiet_NaN();
  }
  double pads = open_pads_f(f.row_time_s.back());
  if (pads > 0.0) {
    // The reference channel goes through the same 555 and counter.
    double T = lumped_period(pads, tm.r1_ohm + tm.r2_ohm, tm.r2_ohm, options_.supply_v, 0.0, 0.0);
    if (options_.quantise) T = std::floor(T * tm.reference_clock_hz + uniform(options_.seed, kClockPhase, key, plan_.size())) / tm.reference_clock_hz;
    pads = T > 0.0 ? tm.capacitance_f(1.0 / T) : 0.0;
  }
  f.open_pads_pf = pads * 1e12;
  return f;
}

Result<BoardFrame> BoardSimulator::measure_frame(double t_frame_s, const VertexProvider& vertices_at) {
  if (!vertices_at) return board_error("no vertex provider");
  return measure_frame(t_frame_s, StateProvider([&](double t) -> Result<SheetState> {
                         auto v = vertices_at(t);
                         if (!v) return v.error();
                         return sheet_.evaluate(*v);
                       }));
}

Result<BoardFrame> BoardSimulator::measure_static(double t_frame_s, const SheetState& state) {
  return measure_frame(t_frame_s, StateProvider([&](double) -> Result<SheetState> { return state; }));
}

Result<RestCalibration> BoardSimulator::calibrate_at_rest(double t_s, int frames) {
  if (frames < 1) return board_error("calibrate_at_rest needs at least one frame");
  const SheetState& rest = sheet_.rest_state();
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(plan_.size()));
  double pads = 0.0;
  for (int k = 0; k < frames; ++k) {
    auto f = measure_static(t_s + k * frame_period_s(), rest);
    if (!f) return f.error();
    for (std::size_t r = 0; r < plan_.size(); ++r) sum[static_cast<Eigen::Index>(r)] += f->rows_pf[r];
    pads += f->open_pads_pf;
  }
  Eigen::VectorXd c0(static_cast<Eigen::Index>(rest.cell_f.size()));
  for (std::size_t c = 0; c < rest.cell_f.size(); ++c) c0[static_cast<Eigen::Index>(c)] = rest.cell_f[c] * 1e12;
  const Eigen::VectorXd ideal = M_ * c0;
  RestCalibration cal;
  cal.parasitic_pf.resize(plan_.size());
  for (std::size_t r = 0; r < plan_.size(); ++r) cal.parasitic_pf[r] = sum[static_cast<Eigen::Index>(r)] / frames - ideal[static_cast<Eigen::Index>(r)];
  cal.open_pads_pf = pads / frames;
  return cal;
}

}  // namespace proprio::stretch_array_sim
