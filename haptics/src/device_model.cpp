#include "proprio/haptics/device_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::haptics {

namespace {

std::string text(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

constexpr const char* kDocs = "see docs/haptic-devices.md";

// Reads one device file. Every key is checked for presence, type and range
// where it is read, so each message can point at file:line:column and the
// full dotted key.
class Parser {
 public:
  explicit Parser(const Config& cfg) : cfg_(cfg) {}

  Result<std::unique_ptr<FingertipDeviceModel>> run() {
    auto kind = cfg_.get_string("kind");
    if (!kind) {
      return with_hint(kind.error(), " (the device kind: \"band_2dof\", \"platform_3dof\" or \"force_vector\")");
    }
    auto name = cfg_.get_string_or("name", "");
    if (!name) return name.error();
    auto limits = parse_limits();
    if (!limits) return limits.error();

    if (*kind == "band_2dof") {
      if (auto st = only_keys("", {"kind", "name", "limits", "motors", "band"}); !st) return st.error();
      auto p = parse_band();
      if (!p) return p.error();
      p->name = *name;
      return in_file(make_band_device(std::move(*p), *limits));
    }
    if (*kind == "platform_3dof") {
      if (auto st = only_keys("", {"kind", "name", "limits", "motors", "platform", "fingertip"}); !st) {
        return st.error();
      }
      auto p = parse_platform();
      if (!p) return p.error();
      p->name = *name;
      return in_file(make_platform_device(std::move(*p), *limits));
    }
    if (*kind == "force_vector") {
      if (auto st = only_keys("", {"kind", "name", "limits"}); !st) return st.error();
      ForceVectorParams p;
      p.name = *name;
      return in_file(make_force_vector_device(std::move(p), *limits));
    }
    return make_error(Errc::invalid_argument, cfg_.where("kind") + ": 'kind' = \"" + *kind +
                                                  "\" is not a device kind; use \"band_2dof\", \"platform_3dof\" "
                                                  "or \"force_vector\" (" + kDocs + ")");
  }

 private:
  static Error with_hint(const Error& e, const std::string& hint) {
    return Error{e.code, e.message + hint + "; " + kDocs};
  }

  // Errors from a model's own validation name keys but not the file.
  Result<std::unique_ptr<FingertipDeviceModel>> in_file(Result<std::unique_ptr<FingertipDeviceModel>> r) const {
    if (!r) return r.error().with_context(cfg_.source_name());
    return r;
  }

  Error error_at(const std::string& key, Errc code, const std::string& what) const {
    return make_error(code, cfg_.where(key) + ": '" + key + "' " + what);
  }

  // A key that is not part of the format is an error: a typo'd limit must not
  // silently fall back to a default.
  Status only_keys(const std::string& table, const std::vector<std::string_view>& allowed) const {
    const std::set<std::string> known(allowed.begin(), allowed.end());
    if (table.empty()) return cfg_.check_keys("top level", known, kDocs);
    auto t = cfg_.table(table);
    if (!t) return t.error();
    return t->check_keys(table, known, kDocs);
  }

  Status require_table(const std::string& table, const char* what) const {
    if (!cfg_.contains(table)) {
      return make_error(Errc::not_found, cfg_.source_name() + ": the table [" + table + "] (" + what +
                                             ") is missing; add it (" + kDocs + ")");
    }
    auto t = cfg_.table(table);
    if (!t) return t.error();
    return {};
  }

  // A number in [min, max] (or (min, max] with min_open). Missing keys are
  // errors unless a fallback is given.
  Result<double> number(const std::string& key, double min, double max, bool min_open, const char* what,
                        std::optional<double> fallback = std::nullopt) const {
    if (!cfg_.contains(key)) {
      if (fallback) return *fallback;
      return make_error(Errc::not_found, cfg_.source_name() + ": required key '" + key + "' (" + what +
                                             ") is missing; add it (" + kDocs + ")");
    }
    auto v = cfg_.get_double(key);
    if (!v) return v.error();
    if ((min_open ? !(*v > min) : !(*v >= min)) || !(*v <= max)) {
      return error_at(key, Errc::out_of_range,
                      "= " + text("%g", *v) + " is outside " + (min_open ? "(" : "[") + text("%g", min) + ", " +
                          text("%g", max) + "] (" + what + ")");
    }
    return v;
  }

  template <std::size_t N>
  Result<std::array<double, N>> numbers(const std::string& key, std::array<double, N> fallback,
                                        const char* what) const {
    if (!cfg_.contains(key)) return fallback;
    auto v = cfg_.get_doubles(key);
    if (!v) return v.error();
    if (v->size() != N) {
      return error_at(key, Errc::invalid_argument,
                      "must have " + std::to_string(N) + " numbers (" + what + "), but it has " +
                          std::to_string(v->size()));
    }
    std::array<double, N> out{};
    std::copy(v->begin(), v->end(), out.begin());
    return out;
  }

  Result<DeviceLimits> parse_limits() const {
    if (auto st = require_table("limits", "the force, rate and timing limits the safety gate enforces"); !st) {
      return st.error();
    }
    if (auto st = only_keys("limits", {"max_normal_n", "max_shear_n", "max_rate_n_per_s", "friction_coefficient",
                                       "ramp_in_s", "watchdog_ms"});
        !st) {
      return st.error();
    }
    DeviceLimits l;
    // The upper bounds are sanity bounds for a fingertip: a typo of 20 for 2.0 N must not load.
    auto n = number("limits.max_normal_n", 0.0, 10.0, true, "largest normal force, N; at most 10 N on a fingertip");
    if (!n) return n.error();
    auto s = number("limits.max_shear_n", 0.0, 10.0, false, "largest shear magnitude, N; at most 10 N");
    if (!s) return s.error();
    auto r = number("limits.max_rate_n_per_s", 0.0, 1e4, true, "slew limit on each force component, N/s");
    if (!r) return r.error();
    auto mu = number("limits.friction_coefficient", 0.0, 3.0, false, "|shear| <= mu * normal, dimensionless");
    if (!mu) return mu.error();
    auto ramp = number("limits.ramp_in_s", 0.0, 10.0, false, "seconds to ramp force in after engaging");
    if (!ramp) return ramp.error();
    auto wd = number("limits.watchdog_ms", 0.0, 1000.0, true,
                     "milliseconds without a fresh command before the output goes to zero", 50.0);
    if (!wd) return wd.error();
    l.max_normal_n = *n;
    l.max_shear_n = *s;
    l.max_rate_n_per_s = *r;
    l.friction_coefficient = *mu;
    l.ramp_in_s = *ramp;
    l.watchdog_ns = seconds_to_ns(*wd * 1e-3);
    if (auto st = l.validate(); !st) return st.error().with_context(cfg_.source_name());
    return l;
  }

  Result<MotorSpec> parse_motor_spec() const {
    MotorSpec m;
    auto gear = number("motors.gear_ratio", 0.0, 1e4, true, "motor turns per output-shaft turn", 1.0);
    if (!gear) return gear.error();
    m.gear_ratio = *gear;
    if (cfg_.contains("motors.encoder_counts_per_motor_rev")) {
      auto c = cfg_.get_int("motors.encoder_counts_per_motor_rev");
      if (!c) return c.error();
      if (*c < 0 || *c > (std::int64_t{1} << 30)) {
        return error_at("motors.encoder_counts_per_motor_rev", Errc::out_of_range,
                        "= " + std::to_string(*c) + " must be in [0, 2^30] (0: no encoder)");
      }
      m.encoder_counts_per_motor_rev = *c;
    }
    return m;
  }

  Result<BandParams> parse_band() const {
    if (auto st = require_table("motors", "pulley radius, gearing, rest angles"); !st) return st.error();
    if (auto st = require_table("band", "the belt's force table and shear stiffness"); !st) return st.error();
    if (auto st = only_keys("motors", {"pulley_radius_m", "gear_ratio", "encoder_counts_per_motor_rev",
                                       "rest_angles_rad", "winding_direction"});
        !st) {
      return st.error();
    }
    if (auto st = only_keys("band", {"shear_stiffness_n_per_m", "force_table"}); !st) return st.error();

    BandParams p;
    auto r = number("motors.pulley_radius_m", 0.0, 0.1, true, "belt pulley radius, m");
    if (!r) return r.error();
    p.pulley_radius_m = *r;
    auto spec = parse_motor_spec();
    if (!spec) return spec.error();
    p.motor = *spec;
    auto rest = numbers<2>("motors.rest_angles_rad", {0.0, 0.0}, "output-shaft angle of each motor at rest, rad");
    if (!rest) return rest.error();
    p.rest_angles_rad = *rest;
    auto wind = numbers<2>("motors.winding_direction", {1.0, -1.0},
                           "+1 or -1: the shaft direction that winds the belt in");
    if (!wind) return wind.error();
    for (std::size_t i = 0; i < 2; ++i) {
      if ((*wind)[i] != 1.0 && (*wind)[i] != -1.0) {
        return error_at("motors.winding_direction", Errc::invalid_argument,
                        "element " + std::to_string(i) + " must be +1 or -1 (the shaft direction that winds the "
                        "belt in), but it is " + text("%g", (*wind)[i]));
      }
      p.winding_direction[i] = (*wind)[i] > 0 ? 1 : -1;
    }
    auto k = number("band.shear_stiffness_n_per_m", 0.0, 1e6, true,
                    "shear force per metre of belt travel along the pad, N/m");
    if (!k) return k.error();
    p.shear_stiffness_n_per_m = *k;

    if (!cfg_.contains("band.force_table")) {
      return make_error(Errc::not_found, cfg_.source_name() +
                                             ": required key 'band.force_table' (the calibration: rows "
                                             "{ takeup_mm = ..., normal_n = ... }) is missing; add it (" +
                                             kDocs + ")");
    }
    auto rows = cfg_.tables("band.force_table");
    if (!rows) return rows.error();
    for (std::size_t i = 0; i < rows->size(); ++i) {
      const Config& row = (*rows)[i];
      const std::string label = "band.force_table[" + std::to_string(i) + "]";
      for (const auto& key : row.keys()) {
        if (key != "takeup_mm" && key != "normal_n") {
          return error_at(label + "." + key, Errc::invalid_argument,
                          "is not a column of the force table; each row is { takeup_mm = ..., normal_n = ... }");
        }
      }
      auto s = row.get_double("takeup_mm");
      if (!s) return s.error();
      auto f = row.get_double("normal_n");
      if (!f) return f.error();
      p.force_table.push_back(BandParams::Row{*s * 1e-3, *f});
    }
    return p;
  }

  Result<PlatformParams> parse_platform() const {
    if (auto st = require_table("motors", "pulley radius, gearing, rest angles"); !st) return st.error();
    if (auto st = require_table("platform", "the wire geometry"); !st) return st.error();
    if (auto st = require_table("fingertip", "the fingertip's stiffness"); !st) return st.error();
    if (auto st = only_keys("motors", {"pulley_radius_m", "gear_ratio", "encoder_counts_per_motor_rev",
                                       "rest_angles_rad"});
        !st) {
      return st.error();
    }
    if (auto st = only_keys("platform", {"plate_radius_m", "anchor_radius_m", "anchor_height_m", "leg_angles_deg"});
        !st) {
      return st.error();
    }
    PlatformParams p;
    auto r = number("motors.pulley_radius_m", 0.0, 0.1, true, "wire pulley radius, m");
    if (!r) return r.error();
    p.pulley_radius_m = *r;
    auto spec = parse_motor_spec();
    if (!spec) return spec.error();
    p.motor = *spec;
    auto rest = numbers<3>("motors.rest_angles_rad", {0.0, 0.0, 0.0}, "output-shaft angle of each motor at rest, rad");
    if (!rest) return rest.error();
    p.rest_angles_rad = *rest;

    auto rb = number("platform.plate_radius_m", 0.0, 0.05, true, "radius of the wire attachments on the plate, m");
    if (!rb) return rb.error();
    auto ra = number("platform.anchor_radius_m", 0.0, 0.1, true, "radius of the wire exits on the static body, m");
    if (!ra) return ra.error();
    auto h = number("platform.anchor_height_m", 0.0, 0.1, true,
                    "height of the wire exits above the plate at rest, along +Y, m");
    if (!h) return h.error();
    auto legs = numbers<3>("platform.leg_angles_deg", {90.0, 210.0, 330.0},
                           "azimuth of each wire, degrees from +X toward +Z");
    if (!legs) return legs.error();
    p.plate_radius_m = *rb;
    p.anchor_radius_m = *ra;
    p.anchor_height_m = *h;
    for (std::size_t i = 0; i < 3; ++i) p.leg_angles_rad[i] = (*legs)[i] * (M_PI / 180.0);

    auto model = cfg_.get_string("fingertip.normal_model");
    if (!model) return with_hint(model.error(), " (\"linear\" or \"exponential\")");
    std::vector<std::string_view> keys = {"normal_model", "shear_stiffness_x_n_per_m", "shear_stiffness_z_n_per_m"};
    if (*model == "linear") {
      p.normal_model = PlatformParams::NormalModel::linear;
      keys.push_back("normal_stiffness_n_per_m");
      if (auto st = only_keys("fingertip", keys); !st) return st.error();
      auto k = number("fingertip.normal_stiffness_n_per_m", 0.0, 1e6, true, "normal force per metre of indentation, N/m");
      if (!k) return k.error();
      p.normal_stiffness_n_per_m = *k;
    } else if (*model == "exponential") {
      p.normal_model = PlatformParams::NormalModel::exponential;
      keys.push_back("exp_initial_stiffness_n_per_m");
      keys.push_back("exp_rate_per_m");
      if (auto st = only_keys("fingertip", keys); !st) return st.error();
      auto b = number("fingertip.exp_initial_stiffness_n_per_m", 0.0, 1e6, true,
                      "b in f = (b/m)(exp(m d) - 1): stiffness at first contact, N/m");
      if (!b) return b.error();
      auto m = number("fingertip.exp_rate_per_m", 0.0, 1e5, true, "m in f = (b/m)(exp(m d) - 1): stiffening rate, 1/m");
      if (!m) return m.error();
      p.exp_initial_stiffness_n_per_m = *b;
      p.exp_rate_per_m = *m;
    } else {
      return error_at("fingertip.normal_model", Errc::invalid_argument,
                      "= \"" + *model + "\" is not a fingertip model; use \"linear\" or \"exponential\"");
    }
    auto kx = number("fingertip.shear_stiffness_x_n_per_m", 0.0, 1e6, true, "shear force per metre of plate travel along X, N/m");
    if (!kx) return kx.error();
    auto kz = number("fingertip.shear_stiffness_z_n_per_m", 0.0, 1e6, true, "shear force per metre of plate travel along Z, N/m");
    if (!kz) return kz.error();
    p.shear_stiffness_x_n_per_m = *kx;
    p.shear_stiffness_z_n_per_m = *kz;
    return p;
  }

  const Config& cfg_;
};

}  // namespace

// --- limits and the common clamp -------------------------------------------

Status DeviceLimits::validate() const {
  auto bad = [this](const char* key, const char* rule) {
    return make_error(Errc::out_of_range,
                      std::string("device limits: '") + key + "' " + rule + " (got " + describe() + ")");
  };
  if (!(max_normal_n > 0.0 && max_normal_n <= 10.0)) return bad("limits.max_normal_n", "must be in (0, 10] N");
  if (!(max_shear_n >= 0.0 && max_shear_n <= 10.0)) return bad("limits.max_shear_n", "must be in [0, 10] N");
  if (!(max_rate_n_per_s > 0.0 && max_rate_n_per_s <= 1e4)) {
    return bad("limits.max_rate_n_per_s", "must be in (0, 10000] N/s");
  }
  if (!(friction_coefficient >= 0.0 && friction_coefficient <= 3.0)) {
    return bad("limits.friction_coefficient", "must be in [0, 3]");
  }
  if (!(ramp_in_s >= 0.0 && ramp_in_s <= 10.0)) return bad("limits.ramp_in_s", "must be in [0, 10] s");
  if (!(watchdog_ns > 0 && watchdog_ns <= kNsPerSecond)) return bad("limits.watchdog_ms", "must be in (0, 1000] ms");
  return {};
}

std::string DeviceLimits::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf, "normal<=%.3g N shear<=%.3g N mu=%.3g rate<=%.4g N/s ramp-in %.3g s watchdog %.4g ms",
                max_normal_n, max_shear_n, friction_coefficient, max_rate_n_per_s, ramp_in_s,
                static_cast<double>(watchdog_ns) * 1e-6);
  return buf;
}

FingertipForce clamp_to_limits(const FingertipForce& desired, const DeviceLimits& limits, ForceAxes axes,
                               std::uint8_t* reasons) noexcept {
  std::uint8_t why = kClampNone;
  FingertipForce f = desired;
  if (!f.is_finite()) {
    if (reasons) *reasons = kClampNonFinite;
    return {};
  }
  if (f.normal_n < 0.0) {
    f.normal_n = 0.0;
    why |= kClampNormalNegative;
  } else if (f.normal_n > limits.max_normal_n) {
    f.normal_n = limits.max_normal_n;
    why |= kClampNormalMax;
  }
  if (!axes.shear_x && f.shear_x_n != 0.0) {
    f.shear_x_n = 0.0;
    why |= kClampAxisDropped;
  }
  if (!axes.shear_z && f.shear_z_n != 0.0) {
    f.shear_z_n = 0.0;
    why |= kClampAxisDropped;
  }
  const double cone = limits.friction_coefficient * f.normal_n;
  const double bound = std::min(limits.max_shear_n, cone);
  const double mag = f.shear_magnitude_n();
  if (mag > bound) {
    if (mag > limits.max_shear_n) why |= kClampShearMax;
    if (mag > cone) why |= kClampFrictionCone;
    // Scaling keeps the direction; hypot of the scaled pair can land an ulp
    // above the bound, and the gate promises "never above", so step down.
    double scale = bound / mag;
    for (int i = 0; i < 4 && std::hypot(f.shear_x_n * scale, f.shear_z_n * scale) > bound; ++i) {
      scale = std::nextafter(scale, 0.0);
    }
    f.shear_x_n *= scale;
    f.shear_z_n *= scale;
  }
  if (reasons) *reasons = why;
  return f;
}

double MotorSpec::output_resolution_rad() const noexcept {
  if (encoder_counts_per_motor_rev <= 0 || !(gear_ratio > 0.0)) return 0.0;
  return 2.0 * M_PI / (static_cast<double>(encoder_counts_per_motor_rev) * gear_ratio);
}

// --- loading -----------------------------------------------------------------

Result<std::unique_ptr<FingertipDeviceModel>> parse_device_model(std::string_view toml_text,
                                                                 std::string_view source_name) {
  auto cfg = Config::parse(toml_text, std::string(source_name));
  if (!cfg) return cfg.error();
  return Parser(*cfg).run();
}

Result<std::unique_ptr<FingertipDeviceModel>> load_device_model(const std::filesystem::path& toml_file) {
  auto text = read_input_file(toml_file, "haptic device file", 16 * kMiB);
  if (!text) {
    if (text.error().code != Errc::not_found) return text.error();
    return make_error(Errc::not_found, text.error().message + "; " "config/haptics/ has band_2dof.toml, platform_3dof.toml and force_vector.toml");
  }
  return parse_device_model(*text, toml_file.string());
}

}  // namespace proprio::haptics
