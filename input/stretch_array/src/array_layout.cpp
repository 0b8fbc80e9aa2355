#include "proprio/stretch_array/array_layout.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::stretch_array {

namespace {

double polygon_area(const std::vector<Point2>& p) {
  double a = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Point2& u = p[i];
    const Point2& v = p[(i + 1) % p.size()];
    a += u.x() * v.y() - v.x() * u.y();
  }
  return 0.5 * a;
}

// Whether segments ab and cd cross at interior points.
bool segments_cross(const Point2& a, const Point2& b, const Point2& c, const Point2& d) {
  const auto orient = [](const Point2& p, const Point2& q, const Point2& r) {
    const double v = (q - p).x() * (r - p).y() - (q - p).y() * (r - p).x();
    return (v > 1e-15) - (v < -1e-15);
  };
  return orient(a, b, c) * orient(a, b, d) < 0 && orient(c, d, a) * orient(c, d, b) < 0;
}

bool simple_polygon(const std::vector<Point2>& p) {
  const std::size_t n = p.size();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 2; j < n; ++j) {
      if (i == 0 && j == n - 1) continue;  // neighbours through the closing edge
      if (segments_cross(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n])) return false;
    }
  }
  return true;
}

Status bad(const std::string& what) { return make_error(Errc::invalid_argument, "stretch array layout: " + what); }

bool positive_size(double v) { return std::isfinite(v) && v > 0.0 && v < 10.0; }

}  // namespace

std::vector<Point2> StripArrayLayout::outline(std::size_t c) const {
  const ArrayCell& cell = cells.at(c);
  if (!cell.outline_m.empty()) return cell.outline_m;
  const Strip& t = top_strips.at(cell.top);
  const Strip& b = bottom_strips.at(cell.bottom);
  const double x0 = t.centre_m - 0.5 * t.width_m, x1 = t.centre_m + 0.5 * t.width_m;
  const double y0 = b.centre_m - 0.5 * b.width_m, y1 = b.centre_m + 0.5 * b.width_m;
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

double StripArrayLayout::rest_area_m2(std::size_t c) const { return std::abs(polygon_area(outline(c))); }

Point2 StripArrayLayout::centroid(std::size_t c) const {
  const auto p = outline(c);
  const double a = polygon_area(p);
  Point2 s = Point2::Zero();
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Point2& u = p[i];
    const Point2& v = p[(i + 1) % p.size()];
    const double w = u.x() * v.y() - v.x() * u.y();
    s += (u + v) * w;
  }
  return s / (6.0 * a);
}

std::vector<StripArrayLayout::Measurement> StripArrayLayout::measurement_plan(bool with_m2) const {
  std::vector<Measurement> plan;
  for (std::size_t t = 0; t < top_strips.size(); ++t) {
    for (std::size_t b = 0; b < bottom_strips.size(); ++b) plan.push_back({{t}, {b}, true});
  }
  if (with_m2) {
    for (std::size_t t = 0; t < top_strips.size(); ++t) plan.push_back({{t}, {}, false});
    for (std::size_t b = 0; b < bottom_strips.size(); ++b) plan.push_back({{}, {b}, false});
  }
  return plan;
}

Eigen::MatrixXd StripArrayLayout::measurement_matrix(bool with_m2) const {
  const auto plan = measurement_plan(with_m2);
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(plan.size()), static_cast<Eigen::Index>(cells.size()));
  for (std::size_t r = 0; r < plan.size(); ++r) {
    const auto& m = plan[r];
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const bool top_source = std::find(m.top_sources.begin(), m.top_sources.end(), cells[c].top) != m.top_sources.end();
      const bool bottom_source =
          std::find(m.bottom_sources.begin(), m.bottom_sources.end(), cells[c].bottom) != m.bottom_sources.end();
      // Exactly one plate on the source electrode: the cell charges.
      if (top_source != bottom_source) M(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = 1.0;
    }
  }
  return M;
}

Status StripArrayLayout::validate() const {
  if (top_strips.empty() || bottom_strips.empty()) return bad("needs at least one top and one bottom strip");
  if (cells.empty()) return bad("has no cells");
  std::set<std::string> names;
  for (const auto* strips : {&top_strips, &bottom_strips}) {
    for (const Strip& s : *strips) {
      if (s.name.empty()) return bad("a strip has no name");
      if (!names.insert(s.name).second) return bad("strip name '" + s.name + "' is used twice");
      if (!std::isfinite(s.centre_m)) return bad("strip '" + s.name + "': centre_m must be finite");
      if (!positive_size(s.width_m)) return bad("strip '" + s.name + "': width_m must be in (0, 10) m");
    }
  }
  std::set<std::string> cell_names;
  std::set<std::pair<std::size_t, std::size_t>> crossings;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const ArrayCell& cell = cells[c];
    if (cell.top >= top_strips.size() || cell.bottom >= bottom_strips.size()) {
      return bad("cell '" + cell.name + "' names a strip that does not exist");
    }
    if (!cell_names.insert(cell.name).second) return bad("cell name '" + cell.name + "' is used twice");
    if (!crossings.insert({cell.top, cell.bottom}).second) {
      return bad("strips '" + top_strips[cell.top].name + "' and '" + bottom_strips[cell.bottom].name +
                 "' cross twice (cells '" + cell.name + "' and another): each pair may cross at most once");
    }
    if (!cell.outline_m.empty()) {
      if (cell.outline_m.size() < 3) return bad("cell '" + cell.name + "': an outline needs at least 3 points");
      for (const Point2& p : cell.outline_m) {
        if (!p.allFinite()) return bad("cell '" + cell.name + "': outline points must be finite");
      }
      if (!simple_polygon(cell.outline_m)) return bad("cell '" + cell.name + "': the outline crosses itself");
      if (polygon_area(cell.outline_m) <= 0.0) {
        return bad("cell '" + cell.name + "': the outline must run counter-clockwise and enclose an area");
      }
    }
    if (!(rest_area_m2(c) > 1e-10)) return bad("cell '" + cell.name + "' has no area");
  }
  const SheetMaterial& m = sheet;
  if (!positive_size(m.dielectric_thickness_m) || !positive_size(m.total_thickness_m) ||
      m.total_thickness_m < m.dielectric_thickness_m) {
    return bad("sheet thicknesses must be positive, the total at least the dielectric's");
  }
  if (!(std::isfinite(m.relative_permittivity) && m.relative_permittivity >= 1.0 && m.relative_permittivity < 100.0)) {
    return bad("sheet relative_permittivity must be in [1, 100)");
  }
  if (!(std::isfinite(m.youngs_modulus_pa) && m.youngs_modulus_pa > 1e3 && m.youngs_modulus_pa < 1e10)) {
    return bad("sheet youngs_modulus_pa must be in (1 kPa, 10 GPa)");
  }
  if (!(std::isfinite(m.poisson_ratio) && m.poisson_ratio > 0.0 && m.poisson_ratio < 0.5)) {
    return bad("sheet poisson_ratio must be in (0, 0.5)");
  }
  return {};
}

// --- readability ---------------------------------------------------------------

namespace {

void rank_and_condition(const Eigen::MatrixXd& M, long& rank, double& condition) {
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(M);
  const auto& s = svd.singularValues();
  const double tol = std::max(M.rows(), M.cols()) * (s.size() ? s(0) : 0.0) * std::numeric_limits<double>::epsilon() * 16;
  rank = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i) rank += s(i) > tol;
  condition = rank == M.cols() && s.size() ? s(0) / s(s.size() - 1) : std::numeric_limits<double>::infinity();
}

}  // namespace

LayoutCheck check_layout(const StripArrayLayout& layout) {
  LayoutCheck r;
  r.cells = layout.cell_count();
  const Eigen::MatrixXd M1 = layout.measurement_matrix(false);
  const Eigen::MatrixXd M = layout.measurement_matrix(true);
  r.rows_m1 = static_cast<std::size_t>(M1.rows());
  r.rows_all = static_cast<std::size_t>(M.rows());
  rank_and_condition(M1, r.rank_m1, r.condition_m1);
  rank_and_condition(M, r.rank_all, r.condition_all);
  if (!r.readable()) {
    Eigen::FullPivLU<Eigen::MatrixXd> lu(M);
    const Eigen::MatrixXd K = lu.kernel();
    for (std::size_t c = 0; c < layout.cells.size(); ++c) {
      if (K.row(static_cast<Eigen::Index>(c)).cwiseAbs().maxCoeff() > 1e-9) r.indistinguishable.push_back(layout.cells[c].name);
    }
  }
  return r;
}

std::string LayoutCheck::describe() const {
  char buf[256];
  const auto cond = [](double c) {
    if (!std::isfinite(c)) return std::string("inf");
    char b[32];
    std::snprintf(b, sizeof b, "%.3g", c);
    return std::string(b);
  };
  std::snprintf(buf, sizeof buf,
                "%zu cells; M^I: %zu rows, rank %ld, condition %s; M^I + M^II: %zu rows, rank %ld, condition %s", cells,
                rows_m1, rank_m1, cond(condition_m1).c_str(), rows_all, rank_all, cond(condition_all).c_str());
  std::string s = buf;
  s += readable() ? " (readable)" : " (NOT readable)";
  return s;
}

Status require_readable(const StripArrayLayout& layout) {
  const LayoutCheck r = check_layout(layout);
  if (r.readable()) return {};
  std::string cells;
  for (const auto& n : r.indistinguishable) cells += (cells.empty() ? "" : ", ") + n;
  return make_error(Errc::invalid_argument,
                    "stretch array layout '" + layout.name + "' cannot be read out: " + r.describe() +
                        "; these cells cannot be told apart: " + cells +
                        ". Move some of them to other strips (docs/stretch-arrays.md, 'Designing a layout')");
}

// --- examples ------------------------------------------------------------------

StripArrayLayout StripArrayLayout::grid(std::string name, std::size_t n, std::size_t k, double pitch_m, double width_m,
                                        int band) {
  StripArrayLayout L;
  L.name = std::move(name);
  for (std::size_t t = 0; t < n; ++t) L.top_strips.push_back({"T" + std::to_string(t + 1), pitch_m * static_cast<double>(t), width_m});
  for (std::size_t b = 0; b < k; ++b) {
    L.bottom_strips.push_back({"B" + std::to_string(b + 1), pitch_m * static_cast<double>(b), width_m});
  }
  for (std::size_t t = 0; t < n; ++t) {
    for (std::size_t b = 0; b < k; ++b) {
      const long d = static_cast<long>(t) - static_cast<long>(b);
      if (band >= 0 && std::labs(d) > band) continue;
      L.cells.push_back({L.top_strips[t].name + "-" + L.bottom_strips[b].name, t, b, {}});
    }
  }
  return L;
}

StripArrayLayout StripArrayLayout::prototype_92() {
  // 12 + 12 strips at 12 mm, 8 mm wide: cells of 8 x 8 mm, 4 mm of plain
  // silicone between them.
  StripArrayLayout L = grid("prototype_92", 12, 12, 0.012, 0.008, 4);
  for (auto [t, b] : {std::pair<std::size_t, std::size_t>{0, 5}, {5, 0}, {11, 6}, {6, 11}}) {
    L.cells.push_back({L.top_strips[t].name + "-" + L.bottom_strips[b].name, t, b, {}});
  }
  return L;
}

StripArrayLayout StripArrayLayout::biceps_144() { return grid("biceps_144", 12, 12, 0.012, 0.008); }

// --- TOML ------------------------------------------------------------------------

Result<StripArrayLayout> StripArrayLayout::parse(std::string_view toml_text, const std::string& source_name) {
  auto c = Config::parse(toml_text, source_name);
  if (!c) return c.error();
  constexpr std::string_view kHint = "docs/stretch-arrays.md, 'Layout files'";
  if (auto k = c->check_keys("top level", {"name", "sheet", "top_strip", "bottom_strip", "cell"}, kHint); !k) {
    return k.error();
  }
  StripArrayLayout L;
  auto name = c->get_string_or("name", "");
  if (!name) return name.error();
  L.name = *name;
  if (c->contains("sheet")) {
    auto s = c->table("sheet");
    if (!s) return s.error();
    if (auto k = s->check_keys("sheet", {"dielectric_thickness_m", "total_thickness_m", "relative_permittivity",
                                         "youngs_modulus_pa", "poisson_ratio"}, kHint);
        !k) {
      return k.error();
    }
    SheetMaterial& m = L.sheet;
    const struct {
      const char* key;
      double* value;
      double min, max;
    } fields[] = {{"dielectric_thickness_m", &m.dielectric_thickness_m, 1e-6, 0.1},
                  {"total_thickness_m", &m.total_thickness_m, 1e-6, 0.1},
                  {"relative_permittivity", &m.relative_permittivity, 1.0, 100.0},
                  {"youngs_modulus_pa", &m.youngs_modulus_pa, 1e3, 1e10},
                  {"poisson_ratio", &m.poisson_ratio, 0.0, 0.4999}};
    for (const auto& f : fields) {
      auto v = s->get_double_or(f.key, *f.value, f.min, f.max);
      if (!v) return v.error();
      *f.value = *v;
    }
  }
  const auto strips = [&](const char* key, std::vector<Strip>& out) -> Status {
    if (!c->contains(key)) return make_error(Errc::invalid_argument, source_name + ": needs [[" + key + "]] tables");
    auto ts = c->tables(key);
    if (!ts) return ts.error();
    for (const Config& t : *ts) {
      if (auto k = t.check_keys(key, {"name", "centre_m", "width_m"}, kHint); !k) return k.error();
      Strip s;
      auto n = t.get_string("name");
      if (!n) return n.error();
      s.name = *n;
      auto centre = t.get_double_or("centre_m", 0.0, -10.0, 10.0);
      if (!centre) return centre.error();
      s.centre_m = *centre;
      auto width = t.get_double_or("width_m", s.width_m, 1e-5, 1.0);
      if (!width) return width.error();
      s.width_m = *width;
      out.push_back(std::move(s));
    }
    return {};
  };
  if (auto st = strips("top_strip", L.top_strips); !st) return st.error();
  if (auto st = strips("bottom_strip", L.bottom_strips); !st) return st.error();
  const auto index_of = [](const std::vector<Strip>& v, const std::string& n) -> long {
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (v[i].name == n) return static_cast<long>(i);
    }
    return -1;
  };
  if (!c->contains("cell")) return make_error(Errc::invalid_argument, source_name + ": needs [[cell]] tables");
  auto cells = c->tables("cell");
  if (!cells) return cells.error();
  for (const Config& t : *cells) {
    if (auto k = t.check_keys("cell", {"name", "top", "bottom", "outline_m"}, kHint); !k) return k.error();
    auto top = t.get_string("top");
    if (!top) return top.error();
    auto bottom = t.get_string("bottom");
    if (!bottom) return bottom.error();
    const long ti = index_of(L.top_strips, *top), bi = index_of(L.bottom_strips, *bottom);
    if (ti < 0) return make_error(Errc::invalid_argument, t.where("top") + ": no top strip named '" + printable(*top, 40) + "'");
    if (bi < 0) {
      return make_error(Errc::invalid_argument, t.where("bottom") + ": no bottom strip named '" + printable(*bottom, 40) + "'");
    }
    ArrayCell cell;
    cell.top = static_cast<std::size_t>(ti);
    cell.bottom = static_cast<std::size_t>(bi);
    auto n = t.get_string_or("name", *top + "-" + *bottom);
    if (!n) return n.error();
    cell.name = *n;
    if (t.contains("outline_m")) {
      auto flat = t.get_doubles("outline_m");
      if (!flat) return flat.error();
      if (flat->size() % 2 != 0 || flat->size() < 6) {
        return make_error(Errc::invalid_argument,
                          t.where("outline_m") + ": outline_m is a flat list x1, y1, x2, y2, ... of at least 3 points");
      }
      for (std::size_t i = 0; i < flat->size(); i += 2) cell.outline_m.emplace_back((*flat)[i], (*flat)[i + 1]);
    }
    L.cells.push_back(std::move(cell));
  }
  if (auto st = L.validate(); !st) return st.error().with_context(source_name);
  return L;
}

Result<StripArrayLayout> StripArrayLayout::load(const std::filesystem::path& path) {
  auto text = read_input_file(path, "stretch array layout", 4 * 1024 * 1024);
  if (!text) return text.error();
  return parse(*text, path.string());
}

std::string StripArrayLayout::to_toml() const {
  std::ostringstream s;
  s.precision(9);
  s << "# A stretch sensor array layout (docs/stretch-arrays.md).\nname = \"" << name << "\"\n\n[sheet]\n"
    << "dielectric_thickness_m = " << sheet.dielectric_thickness_m << "\ntotal_thickness_m = " << sheet.total_thickness_m
    << "\nrelative_permittivity = " << sheet.relative_permittivity << "\nyoungs_modulus_pa = " << sheet.youngs_modulus_pa
    << "\npoisson_ratio = " << sheet.poisson_ratio << "\n";
  for (const auto& [key, strips] : {std::pair{"top_strip", &top_strips}, std::pair{"bottom_strip", &bottom_strips}}) {
    for (const Strip& st : *strips) {
      s << "\n[[" << key << "]]\nname = \"" << st.name << "\"\ncentre_m = " << st.centre_m << "\nwidth_m = " << st.width_m
        << "\n";
    }
  }
  for (const ArrayCell& c : cells) {
    s << "\n[[cell]]\nname = \"" << c.name << "\"\ntop = \"" << top_strips[c.top].name << "\"\nbottom = \""
      << bottom_strips[c.bottom].name << "\"\n";
    if (!c.outline_m.empty()) {
      s << "outline_m = [";
      for (std::size_t i = 0; i < c.outline_m.size(); ++i) {
        s << (i ? ", " : "") << c.outline_m[i].x() << ", " << c.outline_m[i].y();
      }
      s << "]\n";
    }
  }
  return s.str();
}

}  // namespace proprio::stretch_array
