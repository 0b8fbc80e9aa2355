#include "proprio/rig_device/kit.hpp"

#include <cmath>
#include <iomanip>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::rig_device {
namespace {

constexpr int kMaxCount = 256;
constexpr int kMinOutlets = 2;
constexpr int kMaxOutlets = 8;
constexpr std::size_t kMaxNameChars = 64;
// Lengths are millimetres to decimetres on a hand-held device; a metre is a typo.
constexpr double kMaxLengthM = 1.0;
constexpr double kUnitTolerance = 1e-6;
constexpr double kKitDegPerRad = 180.0 / M_PI;
constexpr std::string_view kHint = "docs/rig-device.md, 'Kit files'";

Quat kit_about(const Vec3& axis, double angle_rad) { return Quat(Eigen::AngleAxisd(angle_rad, axis)); }

Status name_ok(const std::string& name, const std::string& field) {
  if (name.empty()) return make_error(Errc::invalid_argument, field + " is empty; give it a name");
  if (name.size() > kMaxNameChars) {
    return make_error(Errc::invalid_argument,
                      field + " is " + std::to_string(name.size()) + " characters; at most " +
                          std::to_string(kMaxNameChars));
  }
  for (unsigned char c : name) {
    if (c < 0x20 || c == 0x7f) {
      return make_error(Errc::invalid_argument, field + " '" + printable(name, 80) + "' holds a control character");
    }
  }
  return Status::success();
}

Status length_ok(double v, const std::string& field) {
  if (!std::isfinite(v) || v <= 0.0 || v > kMaxLengthM) {
    return make_error(Errc::invalid_argument,
                      field + " must be a finite length in (0, 1] m; it is " + std::to_string(v));
  }
  return Status::success();
}

// TOML basic string: names hold no control characters (validate), so only
// the quote and the backslash need escaping.
std::string toml_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

}  // namespace

Quat outlet_rotation(const OutletAngles& a) {
  return (kit_about(Vec3::UnitZ(), a.azimuth_deg / kKitDegPerRad) * kit_about(Vec3::UnitY(), a.tilt_deg / kKitDegPerRad) *
          kit_about(Vec3::UnitZ(), a.roll_deg / kKitDegPerRad))
      .normalized();
}

OutletAngles outlet_angles_for(const Quat& q) {
  // R = Rz(a) Ry(t) Rz(r): R22 = cos t, R02 = cos a sin t, R12 = sin a sin t,
  // R20 = -sin t cos r, R21 = sin t sin r.
  const Mat3 R = q.normalized().toRotationMatrix();
  OutletAngles out;
  const double sin_t = std::hypot(R(0, 2), R(1, 2));
  out.tilt_deg = std::atan2(sin_t, R(2, 2)) * kKitDegPerRad;
  if (sin_t > 1e-9) {
    out.azimuth_deg = std::atan2(R(1, 2), R(0, 2)) * kKitDegPerRad;
    out.roll_deg = std::atan2(R(2, 1), -R(2, 0)) * kKitDegPerRad;
  } else if (R(2, 2) > 0.0) {
    out.roll_deg = std::atan2(R(1, 0), R(0, 0)) * kKitDegPerRad;
  } else {
    // Folded straight back (tilt 180): Rz(a) Ry(pi) Rz(r) = Ry(pi) Rz(r - a).
    out.roll_deg = std::atan2(R(1, 0), -R(0, 0)) * kKitDegPerRad;
  }
  return out;
}

Status Kit::validate() const {
  if (auto s = name_ok(joint.name, "joint.name"); !s) return s;
  if (joint_count < 0 || joint_count > kMaxCount) {
    return make_error(Errc::invalid_argument,
                      "joint count " + std::to_string(joint_count) + " is outside 0.." + std::to_string(kMaxCount));
  }
  if (auto s = length_ok(joint.length_in_m, "joint.length_in_m"); !s) return s;
  if (auto s = length_ok(joint.length_out_m, "joint.length_out_m"); !s) return s;
  if (!std::isfinite(joint.bend_limit_rad) || joint.bend_limit_rad <= 0.0 || joint.bend_limit_rad > M_PI / 2.0) {
    return make_error(Errc::invalid_argument, "joint.bend_limit must be in (0, 90] deg; it is " +
                                                  std::to_string(joint.bend_limit_rad * kKitDegPerRad) + " deg");
  }
  if (joint.twist_rings < 1 || joint.twist_rings > 2) {
    return make_error(Errc::invalid_argument,
                      "joint.twist_rings must be 1 or 2; it is " + std::to_string(joint.twist_rings));
  }
  if (splitter_kinds.size() != splitter_counts.size()) {
    return make_error(Errc::invalid_argument, "the kit has " + std::to_string(splitter_kinds.size()) +
                                                  " splitter kinds but " + std::to_string(splitter_counts.size()) +
                                                  " counts; give one count per kind");
  }
  if (splitter_kinds.size() > static_cast<std::size_t>(kMaxSplitterKinds)) {
    return make_error(Errc::invalid_argument, "the kit has " + std::to_string(splitter_kinds.size()) +
                                                  " splitter kinds; at most " + std::to_string(kMaxSplitterKinds));
  }
  std::set<std::string> names;
  for (std::size_t k = 0; k < splitter_kinds.size(); ++k) {
    const SplitterKind& s = splitter_kinds[k];
    const std::string field = "splitter[" + std::to_string(k) + "]";
    if (auto st = name_ok(s.name, field + ".name"); !st) return st;
    const std::string named = "splitter '" + printable(s.name, 80) + "'";
    if (!names.insert(s.name).second) {
      return make_error(Errc::invalid_argument, named + " appears twice; splitter names must be unique");
    }
    if (splitter_counts[k] < 0 || splitter_counts[k] > kMaxCount) {
      return make_error(Errc::invalid_argument, named + ": count " + std::to_string(splitter_counts[k]) +
                                                    " is outside 0.." + std::to_string(kMaxCount));
    }
    if (auto st = length_ok(s.arm_length_m, named + ": arm_length_m"); !st) return st;
    const auto n = static_cast<int>(s.q_inlet_outlet.size());
    if (n < kMinOutlets || n > kMaxOutlets) {
      return make_error(Errc::invalid_argument, named + " has " + std::to_string(n) + " outlets; a splitter has " +
                                                    std::to_string(kMinOutlets) + ".." + std::to_string(kMaxOutlets));
    }
    for (int i = 0; i < n; ++i) {
      const Quat& q = s.q_inlet_outlet[static_cast<std::size_t>(i)];
      if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0) > kUnitTolerance) {
        return make_error(Errc::invalid_argument,
                          named + ": outlet " + std::to_string(i) + "'s rotation is not a unit quaternion");
      }
    }
  }
  return Status::success();
}

std::string Kit::describe() const {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  s << joint_count << " x " << joint.name << " (Cardan joint, " << joint.twist_rings << " twist ring"
    << (joint.twist_rings == 1 ? "" : "s") << ", shafts " << joint.length_in_m * 1e3 << " + "
    << joint.length_out_m * 1e3 << " mm, bend limit " << joint.bend_limit_rad * kKitDegPerRad << " deg)\n";
  for (std::size_t k = 0; k < splitter_kinds.size() && k < splitter_counts.size(); ++k) {
    const SplitterKind& sp = splitter_kinds[k];
    s << splitter_counts[k] << " x " << sp.name << " (splitter, " << sp.valence() << " outlets:";
    for (const Quat& q : sp.q_inlet_outlet) {
      const OutletAngles a = outlet_angles_for(q);
      s << " [tilt " << a.tilt_deg << ", azimuth " << a.azimuth_deg << "]";
    }
    s << ")\n";
  }
  return s.str();
}

int Kit::total_splitters() const {
  int total = 0;
  for (int c : splitter_counts) total += c;
  return total;
}

Kit default_kit() {
  Kit kit;
  kit.joint = JointKind{};
  // 70 deg per hinge and between the shafts: the stops where the Hall
  // sensing stays unambiguous (hall_joint.hpp: the 2-D reading folds short of
  // 90 deg, for some as-built joints inside 80).
  kit.joint.bend_limit_rad = 70.0 / kKitDegPerRad;
  kit.joint_count = 18;
  const auto splitter = [](std::string name, std::vector<OutletAngles> outlets) {
    SplitterKind s;
    s.name = std::move(name);
    for (const OutletAngles& o : outlets) s.q_inlet_outlet.push_back(outlet_rotation(o));
    return s;
  };
  kit.splitter_kinds = {
      splitter("Y2", {{0.0, 30.0, 0.0}, {180.0, 30.0, 0.0}}),
      splitter("T2", {{0.0, 90.0, 0.0}, {180.0, 90.0, 0.0}}),
      splitter("T3", {{0.0, 0.0, 0.0}, {0.0, 90.0, 0.0}, {180.0, 90.0, 0.0}}),
      splitter("Y3", {{0.0, 45.0, 0.0}, {120.0, 45.0, 0.0}, {240.0, 45.0, 0.0}}),
  };
  kit.splitter_counts = {2, 2, 2, 1};
  return kit;
}

Result<Kit> parse_kit_toml(std::string_view text, const std::string& origin) {
  auto c = Config::parse(text, origin);
  if (!c) return c.error();
  if (auto k = c->check_keys("top level", {"joint", "splitter"}, kHint); !k) return k.error();
  Kit kit;
  kit.splitter_kinds.clear();
  kit.splitter_counts.clear();
  if (c->contains("joint")) {
    auto j = c->table("joint");
    if (!j) return j.error();
    if (auto k = j->check_keys("joint", {"name", "count", "length_in_m", "length_out_m", "bend_limit_deg",
                                         "twist_rings"},
                               kHint);
        !k) {
      return k.error();
    }
    auto name = j->get_string_or("name", kit.joint.name);
    if (!name) return name.error();
    kit.joint.name = *name;
    auto count = j->get_int_or("count", kit.joint_count, 0, kMaxCount);
    if (!count) return count.error();
    kit.joint_count = static_cast<int>(*count);
    auto lin = j->get_double_or("length_in_m", kit.joint.length_in_m, 1e-4, kMaxLengthM);
    if (!lin) return lin.error();
    kit.joint.length_in_m = *lin;
    auto lout = j->get_double_or("length_out_m", kit.joint.length_out_m, 1e-4, kMaxLengthM);
    if (!lout) return lout.error();
    kit.joint.length_out_m = *lout;
    auto limit = j->get_double_or("bend_limit_deg", kit.joint.bend_limit_rad * kKitDegPerRad, 0.1, 90.0);
    if (!limit) return limit.error();
    kit.joint.bend_limit_rad = *limit / kKitDegPerRad;
    auto rings = j->get_int_or("twist_rings", kit.joint.twist_rings, 1, 2);
    if (!rings) return rings.error();
    kit.joint.twist_rings = static_cast<int>(*rings);
  }
  if (c->contains("splitter")) {
    auto ts = c->tables("splitter");
    if (!ts) return ts.error();
    if (ts->size() > static_cast<std::size_t>(kMaxSplitterKinds)) {
      return make_error(Errc::invalid_argument, c->where("splitter") + ": " + std::to_string(ts->size()) +
                                                    " [[splitter]] kinds; at most " + std::to_string(kMaxSplitterKinds));
    }
    for (const Config& t : *ts) {
      if (auto k = t.check_keys("splitter", {"name", "count", "arm_length_m", "outlet"}, kHint); !k) return k.error();
      SplitterKind s;
      auto name = t.get_string("name");
      if (!name) return name.error();
      s.name = *name;
      auto count = t.get_int_or("count", 1, 0, kMaxCount);
      if (!count) return count.error();
      auto arm = t.get_double_or("arm_length_m", s.arm_length_m, 1e-4, kMaxLengthM);
      if (!arm) return arm.error();
      s.arm_length_m = *arm;
      if (!t.contains("outlet")) {
        return make_error(Errc::invalid_argument, t.where("name") + ": splitter '" + printable(s.name, 80) +
                                                      "' needs [[splitter.outlet]] tables (" +
                                                      std::to_string(kMinOutlets) + ".." +
                                                      std::to_string(kMaxOutlets) + ")");
      }
      auto outs = t.tables("outlet");
      if (!outs) return outs.error();
      if (outs->size() < static_cast<std::size_t>(kMinOutlets) || outs->size() > static_cast<std::size_t>(kMaxOutlets)) {
        return make_error(Errc::invalid_argument, t.where("outlet") + ": splitter '" + printable(s.name, 80) + "' has " +
                                                      std::to_string(outs->size()) + " outlets; a splitter has " +
                                                      std::to_string(kMinOutlets) + ".." + std::to_string(kMaxOutlets));
      }
      for (const Config& o : *outs) {
        if (auto k = o.check_keys("splitter.outlet", {"azimuth_deg", "tilt_deg", "roll_deg"}, kHint); !k) {
          return k.error();
        }
        OutletAngles a;
        auto az = o.get_double_or("azimuth_deg", 0.0, -360.0, 360.0);
        if (!az) return az.error();
        auto tilt = o.get_double_or("tilt_deg", 0.0, 0.0, 180.0);
        if (!tilt) return tilt.error();
        auto roll = o.get_double_or("roll_deg", 0.0, -360.0, 360.0);
        if (!roll) return roll.error();
        a.azimuth_deg = *az;
        a.tilt_deg = *tilt;
        a.roll_deg = *roll;
        s.q_inlet_outlet.push_back(outlet_rotation(a));
      }
      kit.splitter_kinds.push_back(std::move(s));
      kit.splitter_counts.push_back(static_cast<int>(*count));
    }
  }
  if (auto st = kit.validate(); !st) return st.error().with_context(origin);
  return kit;
}

Result<Kit> load_kit(const std::filesystem::path& file) {
  auto text = read_input_file(file, "rig device kit", kMaxKitFileBytes);
  if (!text) return text.error();
  return parse_kit_toml(*text, file.string());
}

std::string kit_to_toml(const Kit& kit) {
  std::ostringstream s;
  s << std::setprecision(17);
  s << "# A rig device kit (docs/rig-device.md, 'Kit files'). Outlet rotation:\n"
       "# q_inlet_outlet = Rz(azimuth) * Ry(tilt) * Rz(roll), shafts along +z.\n\n";
  s << "[joint]\nname = " << toml_string(kit.joint.name) << "\ncount = " << kit.joint_count
    << "\nlength_in_m = " << kit.joint.length_in_m << "\nlength_out_m = " << kit.joint.length_out_m
    << "\nbend_limit_deg = " << kit.joint.bend_limit_rad * kKitDegPerRad << "\ntwist_rings = " << kit.joint.twist_rings
    << "\n";
  for (std::size_t k = 0; k < kit.splitter_kinds.size(); ++k) {
    const SplitterKind& sp = kit.splitter_kinds[k];
    s << "\n[[splitter]]\nname = " << toml_string(sp.name)
      << "\ncount = " << (k < kit.splitter_counts.size() ? kit.splitter_counts[k] : 0)
      << "\narm_length_m = " << sp.arm_length_m << "\n";
    for (const Quat& q : sp.q_inlet_outlet) {
      const OutletAngles a = outlet_angles_for(q);
      // Round-off near zero prints as 1e-15; a person reads 0.
      const auto tidy = [](double v) { return std::abs(v) < 1e-9 ? 0.0 : v; };
      s << "[[splitter.outlet]]\nazimuth_deg = " << tidy(a.azimuth_deg) << "\ntilt_deg = " << tidy(a.tilt_deg)
        << "\nroll_deg = " << tidy(a.roll_deg) << "\n";
    }
  }
  return s.str();
}

}  // namespace proprio::rig_device
