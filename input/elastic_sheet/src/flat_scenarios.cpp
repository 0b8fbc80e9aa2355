// The flat rigs (see flat_scenarios.hpp).
#include "proprio/elastic_sheet/flat_scenarios.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "membrane_solver.hpp"

namespace proprio::elastic_sheet {

Status FlatSheetOptions::validate() const {
  if (auto m = material.validate(); !m) return m;
  if (max_iterations < 1 || !(tolerance_m > 0.0) || !(max_step_m > 0.0)) {
    return make_error(Errc::invalid_argument, "flat sheet: max_iterations >= 1, tolerance_m and max_step_m > 0");
  }
  return Status::success();
}

FlatSheet::FlatSheet(FlatSheet&&) noexcept = default;
FlatSheet& FlatSheet::operator=(FlatSheet&&) noexcept = default;
FlatSheet::~FlatSheet() = default;

Result<FlatSheet> FlatSheet::create(SheetMesh mesh, std::vector<std::uint32_t> held, const FlatSheetOptions& options) {
  if (auto v = options.validate(); !v) return v.error();
  auto membrane = Membrane::create(mesh, options.material);
  if (!membrane) return membrane.error();
  const std::size_t n = mesh.vertices_m.size();
  std::vector<std::uint8_t> pinned(n, 0);
  for (auto i : held) {
    if (i >= n) return make_error(Errc::invalid_argument, "flat sheet: a held vertex is out of range");
    pinned[i] = 1;
  }
  if (held.empty()) {
    return make_error(Errc::invalid_argument, "flat sheet: hold at least one vertex, or the sheet floats away");
  }
  FlatSheet s;
  s.membrane_ = std::make_unique<Membrane>(std::move(*membrane));
  s.solver_ = std::make_unique<detail::MembraneSolver>();
  if (auto st = s.solver_->init(*s.membrane_, pinned, std::vector<double>(n, 0.0)); !st) return st.error();
  s.q_ = mesh.vertices_m;
  s.x_.resize(n);
  for (std::size_t i = 0; i < n; ++i) s.x_[i] = Vec3(s.q_[i].x(), s.q_[i].y(), 0.0);
  s.mesh_ = std::move(mesh);
  s.held_ = std::move(held);
  s.options_ = options;
  return s;
}

void FlatSheet::set_positions(const std::vector<Eigen::Vector2d>& p) {
  if (p.size() != q_.size()) return;
  q_ = p;
  for (std::size_t i = 0; i < q_.size(); ++i) x_[i] = Vec3(q_[i].x(), q_[i].y(), 0.0);
}

Result<FlatSolveReport> FlatSheet::solve(const std::vector<Eigen::Vector2d>& held_positions) {
  if (held_positions.size() != held_.size()) {
    return make_error(Errc::invalid_argument, "flat sheet: give one position per held vertex (" +
                                                  std::to_string(held_.size()) + ")");
  }
  for (std::size_t k = 0; k < held_.size(); ++k) q_[held_[k]] = held_positions[k];
  const std::size_t n = q_.size();
  // The plane is its own exact linearisation: x = (q, 0).
  detail::LinearisedSurface lin;
  lin.q0 = q_;
  lin.x0.resize(n);
  Mat32 plane;
  plane << 1, 0, 0, 1, 0, 0;
  lin.jacobian.assign(n, plane);
  for (std::size_t i = 0; i < n; ++i) lin.x0[i] = Vec3(q_[i].x(), q_[i].y(), 0.0);
  const std::vector<Vec3> no_targets(n, Vec3::Zero());
  const auto out = solver_->solve(*membrane_, lin, no_targets, q_, options_.max_iterations, options_.tolerance_m,
                                  options_.max_step_m);
  if (!std::isfinite(out.energy_j)) {
    return make_error(Errc::out_of_range, "flat sheet: a triangle collapsed; move the held vertices in smaller steps");
  }
  for (std::size_t i = 0; i < n; ++i) x_[i] = Vec3(q_[i].x(), q_[i].y(), 0.0);
  return FlatSolveReport{out.iterations, out.converged, out.energy_j};
}

Result<SheetMesh> rectangle_mesh(double width_m, double length_m, double spacing_m) {
  if (!(width_m > 0.0) || !(length_m > 0.0) || !(spacing_m > 0.0) || spacing_m > std::min(width_m, length_m)) {
    return make_error(Errc::invalid_argument, "rectangle mesh: need positive sizes and 0 < spacing <= the shorter side");
  }
  const int nx = static_cast<int>(std::ceil(width_m / spacing_m - 1e-9));
  const int ny = static_cast<int>(std::ceil(length_m / spacing_m - 1e-9));
  SheetMesh m;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) m.vertices_m.emplace_back(width_m * i / nx, length_m * j / ny);
  }
  auto id = [nx](int i, int j) { return static_cast<std::uint32_t>(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const auto a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      if ((i + j) % 2 == 0) {
        m.triangles.push_back({a, b, c});
        m.triangles.push_back({a, c, d});
      } else {
        m.triangles.push_back({a, b, d});
        m.triangles.push_back({b, c, d});
      }
    }
  }
  m.cell_of_triangle.assign(m.triangles.size(), 0);
  return m;
}

Status UniaxialOptions::validate() const {
  if (!(width_m > 0.0) || !(length_m > 0.0) || !(spacing_m > 0.0)) {
    return make_error(Errc::invalid_argument, "uniaxial rig: width, length and spacing must be positive");
  }
  return sheet.validate();
}

std::string UniaxialOptions::describe() const {
  std::ostringstream s;
  s << "uniaxial cell " << width_m * 1e3 << " x " << length_m * 1e3 << " mm, clamped at the short ends, mesh "
    << spacing_m * 1e3 << " mm, " << sheet.material.describe();
  return s.str();
}

Result<UniaxialStretchRig> UniaxialStretchRig::create(const UniaxialOptions& options) {
  if (auto v = options.validate(); !v) return v.error();
  auto mesh = rectangle_mesh(options.width_m, options.length_m, options.spacing_m);
  if (!mesh) return mesh.error();
  std::vector<std::uint32_t> held;
  for (std::size_t i = 0; i < mesh->vertices_m.size(); ++i) {
    const double y = mesh->vertices_m[i].y();
    if (y < 1e-12 || y > options.length_m - 1e-12) held.push_back(static_cast<std::uint32_t>(i));
  }
  auto sheet = FlatSheet::create(std::move(*mesh), std::move(held), options.sheet);
  if (!sheet) return sheet.error();
  return UniaxialStretchRig(std::move(*sheet), options);
}

Result<FlatSolveReport> UniaxialStretchRig::set_stretch(double lambda) {
  if (!(lambda > 0.3) || lambda > 4.0) {
    return make_error(Errc::invalid_argument, "uniaxial rig: stretch must be in (0.3, 4]");
  }
  // Warm start: the current state scaled affinely along the pull.
  std::vector<Eigen::Vector2d> guess(sheet_.vertices_m().size());
  for (std::size_t i = 0; i < guess.size(); ++i) {
    guess[i] = Eigen::Vector2d(sheet_.vertices_m()[i].x(), sheet_.vertices_m()[i].y() * lambda / lambda_);
  }
  sheet_.set_positions(guess);
  std::vector<Eigen::Vector2d> held;
  for (auto i : sheet_.held_vertices()) {
    const auto& r = sheet_.mesh().vertices_m[i];
    held.emplace_back(r.x(), r.y() < 0.5 * options_.length_m ? 0.0 : lambda * options_.length_m);
  }
  auto r = sheet_.solve(held);
  if (r) lambda_ = lambda;
  return r;
}

double UniaxialStretchRig::mid_width_m() const {
  const auto& rest = sheet_.mesh().vertices_m;
  double best_dy = 1e9;
  for (const auto& p : rest) best_dy = std::min(best_dy, std::abs(p.y() - 0.5 * options_.length_m));
  double lo = 1e9, hi = -1e9;
  for (std::size_t i = 0; i < rest.size(); ++i) {
    if (std::abs(std::abs(rest[i].y() - 0.5 * options_.length_m) - best_dy) > 1e-12) continue;
    if (rest[i].y() < 0.5 * options_.length_m - 1e-12 && best_dy > 1e-12) continue;  // one row only
    lo = std::min(lo, sheet_.vertices_m()[i].x());
    hi = std::max(hi, sheet_.vertices_m()[i].x());
  }
  return hi - lo;
}

Status StringPullOptions::validate() const {
  if (strings < 1 || strings > 16) return make_error(Errc::invalid_argument, "string rig: 1-16 strings");
  if (!(max_pull_m > 0.0) || !(clip_radius_m > 0.0) || !(inner_fraction > 0.0) || inner_fraction > 0.9) {
    return make_error(Errc::invalid_argument,
                      "string rig: max_pull_m and clip_radius_m must be positive, inner_fraction in (0, 0.9]");
  }
  return sheet.validate();
}

std::string StringPullOptions::describe() const {
  std::ostringstream s;
  s << "string-pulled sheet: " << strings << " strings (seed " << seed << "), pull up to " << max_pull_m * 1e3
    << " mm, clips of " << clip_radius_m * 1e3 << " mm, frame held";
  return s.str();
}

Result<StringPullRig> StringPullRig::create(SheetMesh mesh, const StringPullOptions& options) {
  if (auto v = options.validate(); !v) return v.error();
  if (mesh.vertices_m.empty()) return make_error(Errc::invalid_argument, "string rig: the sheet mesh is empty");
  Eigen::Vector2d lo = mesh.vertices_m[0], hi = lo;
  for (const auto& p : mesh.vertices_m) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector2d centre = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  // Seeded attachments, kept apart so clips do not overlap.
  std::uint64_t state = options.seed * 0x9E3779B97F4A7C15ull + 7;
  auto uniform = [&state](double a, double b) {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return a + (b - a) * (static_cast<double>(z >> 11) * 0x1.0p-53);
  };
  std::vector<PullString> strings;
  for (int tries = 0; tries < 1000 && static_cast<int>(strings.size()) < options.strings; ++tries) {
    const Eigen::Vector2d a = centre + Eigen::Vector2d(uniform(-1, 1) * half.x(), uniform(-1, 1) * half.y()) *
                                           options.inner_fraction;
    bool apart = true;
    for (const auto& s : strings) apart = apart && (s.attachment_m - a).norm() > 4.0 * options.clip_radius_m + options.max_pull_m;
    if (!apart) continue;
    const double angle = uniform(0.0, 2.0 * 3.14159265358979323846);
    strings.push_back({a, Eigen::Vector2d(std::cos(angle), std::sin(angle)), {}});
  }
  if (static_cast<int>(strings.size()) < options.strings) {
    return make_error(Errc::invalid_argument, "string rig: cannot place that many strings apart on this sheet; use fewer");
  }
  std::vector<std::uint32_t> held;
  std::vector<std::int32_t> string_of_held;
  const double eps = 1e-9;
  for (std::size_t i = 0; i < mesh.vertices_m.size(); ++i) {
    const auto& p = mesh.vertices_m[i];
    const bool frame = p.x() < lo.x() + eps || p.x() > hi.x() - eps || p.y() < lo.y() + eps || p.y() > hi.y() - eps;
    std::int32_t owner = frame ? -1 : -2;
    for (std::size_t s = 0; s < strings.size() && owner == -2; ++s) {
      if ((p - strings[s].attachment_m).norm() <= options.clip_radius_m) owner = static_cast<std::int32_t>(s);
    }
    if (owner == -2) continue;
    if (owner >= 0) strings[static_cast<std::size_t>(owner)].clip_vertices.push_back(static_cast<std::uint32_t>(i));
    held.push_back(static_cast<std::uint32_t>(i));
    string_of_held.push_back(owner);
  }
  for (const auto& s : strings) {
    if (s.clip_vertices.empty()) {
      return make_error(Errc::invalid_argument, "string rig: a clip holds no vertex; make clip_radius_m larger than the mesh spacing");
    }
  }
  auto sheet = FlatSheet::create(std::move(mesh), std::move(held), options.sheet);
  if (!sheet) return sheet.error();
  StringPullRig rig(std::move(*sheet), options);
  rig.strings_ = std::move(strings);
  rig.string_of_held_ = std::move(string_of_held);
  for (std::size_t s = 0; s < rig.strings_.size(); ++s) {
    MotionSignalOptions mo;
    mo.seed = options.seed * 1000003ull + s;
    rig.signals_.emplace_back(mo);
  }
  return rig;
}

double StringPullRig::pull_m(std::size_t s, double t) const {
  return s < signals_.size() ? options_.max_pull_m * signals_[s].unipolar(t) : 0.0;
}

Result<FlatSolveReport> StringPullRig::step(double t) {
  std::vector<Eigen::Vector2d> held;
  const auto& ids = sheet_.held_vertices();
  held.reserve(ids.size());
  for (std::size_t k = 0; k < ids.size(); ++k) {
    Eigen::Vector2d p = sheet_.mesh().vertices_m[ids[k]];
    if (string_of_held_[k] >= 0) {
      const auto s = static_cast<std::size_t>(string_of_held_[k]);
      p += pull_m(s, t) * strings_[s].direction;
    }
    held.push_back(p);
  }
  return sheet_.solve(held);
}

}  // namespace proprio::elastic_sheet
