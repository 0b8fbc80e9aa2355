#include "proprio/glove_descriptions/imu_glove_description.hpp"


#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio {

namespace {

constexpr std::array<std::string_view, kMarkerHueCount> kHueNames = {"red", "yellow", "green", "blue"};

// Where a segment's bone is in HandShape: finger and bone index (0 = metacarpal).
struct BoneRef {
  std::size_t finger = 0;
  std::size_t bone = 0;
};

std::optional<BoneRef> bone_of(HandJoint j) {
  for (std::size_t f = 0; f < kFingerCount; ++f) {
    const FingerJoints fj = finger_joints(static_cast<Finger>(f));
    // The last valid joint is the tip, which starts no bone.
    for (std::size_t k = 0; k + 1 < fj.count; ++k) {
      if (fj.joints[k] == j) return BoneRef{f, k};
    }
  }
  return std::nullopt;
}

// Mirror through the wrist frame's YZ plane with axes kept right-handed, as
// HandModel does for the left hand: p.x -> -p.x, (w, x, y, z) -> (w, x, -y, -z).
Vec3 mirror_x(Vec3 v) {
  v.x() = -v.x();
  return v;
}
Quat mirror_q(const Quat& q) { return Quat(q.w(), q.x(), -q.y(), -q.z()); }

// Finger-segment surface point and outward normal: `along` of the bone from
// its joint, `around` from dorsal (+Y) toward +X; the skin radius tapers
// linearly between the joint radii at the two ends of the bone.
struct SurfacePoint {
  Vec3 p;
  Vec3 n;
};

SurfacePoint finger_surface(const HandShape& shape, const BoneRef& b, double along, double around_rad) {
  const HandShape::Finger& g = shape.fingers[b.finger];
  const double L = g.bone_length_m[b.bone];
  const double r = (1.0 - along) * g.joint_radius_m[b.bone] + along * g.joint_radius_m[b.bone + 1];
  const Vec3 n(std::sin(around_rad), std::cos(around_rad), 0.0);
  return {Vec3(r * n.x(), r * n.y(), -along * L), n};
}

// The dorsum is modelled as the flat back of the palm, palm_radius above the
// plane of the metacarpals; along is a fraction of hand length from the wrist.
SurfacePoint dorsum_surface(const HandShape& shape, double along, double across) {
  return {Vec3(across * shape.hand_width_m, shape.palm_radius_m, -along * shape.hand_length_m), Vec3::UnitY()};
}

std::string printf_text(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

// Shortest decimal text x such that exact(strtod(x)) holds, starting from the
// candidate value, so that what to_toml() writes parses back bit for bit;
// nothing when no text up to 17 digits does.
template <typename Exact>
std::optional<std::string> shortest_text(double candidate, Exact exact) {
  for (int precision = 1; precision <= 17; ++precision) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*g", precision, candidate);
    // "9e+01" is exact but not how a person writes 90.
    const bool exponent = std::string_view(buf).find('e') != std::string_view::npos;
    if (exponent && std::abs(candidate) >= 1e-4 && std::abs(candidate) < 1e15) continue;
    if (exact(std::strtod(buf, nullptr))) {
      std::string s = buf;
      // "12" would read back as a TOML integer; Config accepts that for a
      // number, but a reader should see that the value is continuous.
      if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
      return s;
    }
  }
  return std::nullopt;
}

std::string num(double v) {
  return shortest_text(v, [v](double x) { return x == v; }).value_or(printf_text("%.17g", v));
}

std::string vec_text(const Vec3& v) { return "[" + num(v.x()) + ", " + num(v.y()) + ", " + num(v.z()) + "]"; }

// A TOML basic string.
std::string toml_string(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    if (static_cast<unsigned char>(ch) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(ch));
      out += buf;
      continue;
    }
    if (ch == '"' || ch == '\\') out += '\\';
    out += ch;
  }
  return out + "\"";
}

std::string segment_text(HandJoint j) { return j == HandJoint::wrist ? "dorsum" : std::string(to_string(j)); }

}  // namespace

// --- names ---------------------------------------------------------------

std::string_view to_string(MarkerHue h) noexcept {
  const auto i = static_cast<std::size_t>(h);
  return i < kHueNames.size() ? kHueNames[i] : std::string_view("invalid_hue");
}

std::optional<MarkerHue> parse_marker_hue(std::string_view s) noexcept {
  for (std::size_t i = 0; i < kHueNames.size(); ++i) {
    if (s == kHueNames[i]) return static_cast<MarkerHue>(i);
  }
  return std::nullopt;
}

int opencv_hue(MarkerHue h) noexcept {
  switch (h) {
    case MarkerHue::red: return 0;
    case MarkerHue::yellow: return 30;
    case MarkerHue::green: return 60;
    case MarkerHue::blue: return 120;
  }
  return 0;
}

bool is_glove_segment(HandJoint j) noexcept { return j == HandJoint::wrist || bone_of(j).has_value(); }

std::optional<HandJoint> parse_glove_segment(std::string_view s) noexcept {
  if (s == "wrist" || s == "dorsum") return HandJoint::wrist;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    if (to_string(joint_at(i)) == s && is_glove_segment(joint_at(i))) return joint_at(i);
  }
  return std::nullopt;
}

// --- rig -----------------------------------------------------------------

PinholeCamera PinholeCamera::from_fov(int width_px, int height_px, double hfov_rad, double vfov_rad) {
  PinholeCamera c;
  c.width_px = width_px;
  c.height_px = height_px;
  // The image edges are W/2 and H/2 from the centre, so tan(fov/2) = (W/2)/f.
  c.fx_px = 0.5 * width_px / std::tan(0.5 * hfov_rad);
  c.fy_px = 0.5 * height_px / std::tan(0.5 * vfov_rad);
  c.cx_px = 0.5 * (width_px - 1);
  c.cy_px = 0.5 * (height_px - 1);
  return c;
}

double PinholeCamera::hfov_rad() const { return 2.0 * std::atan(0.5 * width_px / fx_px); }
double PinholeCamera::vfov_rad() const { return 2.0 * std::atan(0.5 * height_px / fy_px); }

Quat StereoRig::head_camera_rotation(double tilt_down_rad) {
  // OpenXR head: +X right, +Y up, looking along -Z. Camera (OpenCV): x right,
  // y down, looking along +z. A half turn about X maps one onto the other; the
  // tilt then pitches the optical axis toward the camera's +y (down), which is
  // a negative rotation about the camera's x.
  return (Quat(Eigen::AngleAxisd(M_PI, Vec3::UnitX())) * Quat(Eigen::AngleAxisd(-tilt_down_rad, Vec3::UnitX())))
      .normalized();
}

StereoRig StereoRig::zed_mini_like() {
  StereoRig r;
  r.camera = PinholeCamera::from_fov(1280, 720, deg_to_rad(90.0), deg_to_rad(60.0));
  r.baseline_m = 0.063;
  r.rate_hz = 30.0;
  // Mounted on the front of the HMD: the stereo pair is centred on the head, so
  // the left camera is half a baseline to the left; 8 cm in front of the head
  // centre (about the eyes-to-visor-front distance); pitched down 25 deg so a
  // hand held at chest height in front of the body is in view.
  r.T_head_leftcam = {head_camera_rotation(deg_to_rad(25.0)), Vec3(-0.0315, 0.0, -0.08)};
  return r;
}

Pose StereoRig::T_head_rightcam() const {
  return T_head_leftcam * Pose{Quat::Identity(), Vec3(baseline_m, 0.0, 0.0)};
}

namespace {
// The downward tilt of a camera whose orientation is a pure tilt from looking
// straight ahead (the usual head mount); nothing for any other orientation.
std::optional<double> tilt_down_rad(const Quat& q_head_cam) {
  const Quat q_rel = (StereoRig::head_camera_rotation(0.0).conjugate() * q_head_cam).normalized();
  if (std::abs(q_rel.y()) > 1e-12 || std::abs(q_rel.z()) > 1e-12) return std::nullopt;
  return -2.0 * std::atan2(q_rel.x(), q_rel.w());
}
}  // namespace

// --- the default glove -----------------------------------------------------

ImuGloveDescription ImuGloveDescription::vist_default() {
  ImuGloveDescription g;
  g.name = "VIST glove (Lee 2021, ch. 4)";
  g.origin = "ImuGloveDescription::vist_default()";
  g.rig = StereoRig::zed_mini_like();

  // The seven IMUs of Lee 2021, §4.2, on the inner glove, each on the back of
  // its segment: halfway along a phalanx, and at 35 % of hand length on the
  // dorsum (the middle of the metacarpals, clear of the wrist crease).
  auto imu = [&](HandJoint seg, double along) {
    ImuMount m;
    m.name = segment_text(seg);
    m.segment = seg;
    m.along_fraction = along;
    g.imus.push_back(std::move(m));
  };
  imu(HandJoint::wrist, 0.35);
  imu(HandJoint::thumb_metacarpal, 0.5);
  imu(HandJoint::thumb_proximal, 0.5);
  imu(HandJoint::index_proximal, 0.5);
  imu(HandJoint::index_intermediate, 0.5);
  imu(HandJoint::middle_proximal, 0.5);
  imu(HandJoint::middle_intermediate, 0.5);

  // 37 markers of 12 mm. The thesis gives the count, the size and the four
  // hues, but its figure of the layout is not in the text, so this layout is
  // ours. On the default hand (19 x 10 cm, flat) no two markers are closer
  // than one diameter; side markers (+-60 deg around the bone) keep an edge-on
  // hand visible; the facing sides of the index and middle fingers, which touch
  // when the hand is flat, never carry markers at the same place. The hues
  // were assigned (10/9/9/9) by a search that maximised the distance between
  // markers of the same hue: at least 24 mm, two diameters, so each hue's
  // correspondence search sees well separated candidates. A unit test guards
  // both distances; docs/vist-glove.md has the table.
  using H = MarkerHue;
  auto dorsum = [&](double along, double across, H hue) {
    MarkerSpec m;
    m.segment = HandJoint::wrist;
    m.hue = hue;
    m.along_fraction = along;
    m.across_fraction = across;
    g.markers.push_back(m);
  };
  auto finger = [&](HandJoint seg, double along, double around_deg, H hue) {
    MarkerSpec m;
    m.segment = seg;
    m.hue = hue;
    m.along_fraction = along;
    m.around_deg = around_deg;
    g.markers.push_back(m);
  };
  // Dorsum: four rows from the wrist toward the knuckles (11).
  dorsum(0.10, -0.10, H::blue);
  dorsum(0.10, 0.05, H::red);
  dorsum(0.10, 0.18, H::blue);
  dorsum(0.20, -0.16, H::red);
  dorsum(0.20, -0.02, H::green);
  dorsum(0.20, 0.12, H::yellow);
  dorsum(0.20, 0.26, H::green);
  dorsum(0.31, -0.17, H::green);
  dorsum(0.31, 0.15, H::red);
  dorsum(0.31, 0.28, H::blue);
  dorsum(0.40, -0.02, H::yellow);
  // Thumb metacarpal (4) and proximal phalanx (4).
  finger(HandJoint::thumb_metacarpal, 0.20, 0.0, H::yellow);
  finger(HandJoint::thumb_metacarpal, 0.50, -60.0, H::green);
  finger(HandJoint::thumb_metacarpal, 0.50, 60.0, H::blue);
  finger(HandJoint::thumb_metacarpal, 0.80, 0.0, H::yellow);
  finger(HandJoint::thumb_proximal, 0.15, -60.0, H::red);
  finger(HandJoint::thumb_proximal, 0.15, 60.0, H::green);
  finger(HandJoint::thumb_proximal, 0.55, 0.0, H::yellow);
  finger(HandJoint::thumb_proximal, 0.90, 0.0, H::blue);
  // Index proximal (5) and intermediate (4) phalanges. Side markers favour the
  // radial side (-X for a right hand), which faces the thumb and the camera.
  finger(HandJoint::index_proximal, 0.12, 0.0, H::red);
  finger(HandJoint::index_proximal, 0.40, -60.0, H::green);
  finger(HandJoint::index_proximal, 0.40, 60.0, H::yellow);
  finger(HandJoint::index_proximal, 0.68, 0.0, H::red);
  finger(HandJoint::index_proximal, 0.88, -60.0, H::yellow);
  finger(HandJoint::index_intermediate, 0.10, 0.0, H::green);
  finger(HandJoint::index_intermediate, 0.50, -60.0, H::red);
  finger(HandJoint::index_intermediate, 0.50, 60.0, H::yellow);
  finger(HandJoint::index_intermediate, 0.90, 0.0, H::blue);
  // Middle proximal (5) and intermediate (4): side markers favour the ulnar side.
  finger(HandJoint::middle_proximal, 0.12, 0.0, H::blue);
  finger(HandJoint::middle_proximal, 0.42, 60.0, H::red);
  finger(HandJoint::middle_proximal, 0.62, 0.0, H::green);
  finger(HandJoint::middle_proximal, 0.85, -60.0, H::blue);
  finger(HandJoint::middle_proximal, 0.85, 60.0, H::yellow);
  finger(HandJoint::middle_intermediate, 0.08, 0.0, H::red);
  finger(HandJoint::middle_intermediate, 0.40, 60.0, H::blue);
  finger(HandJoint::middle_intermediate, 0.68, 0.0, H::green);
  finger(HandJoint::middle_intermediate, 0.98, -60.0, H::red);
  return g;
}

// --- placement -------------------------------------------------------------

std::vector<HandJoint> ImuGloveDescription::segments() const {
  std::vector<HandJoint> out;
  auto add = [&](HandJoint j) {
    if (std::find(out.begin(), out.end(), j) == out.end()) out.push_back(j);
  };
  for (const auto& m : imus) add(m.segment);
  for (const auto& m : markers) add(m.segment);
  return out;
}

std::vector<PlacedMarker> ImuGloveDescription::place_markers(const HandShape& shape) const {
  return place_markers(shape, Handedness::right);
}

std::vector<PlacedImu> ImuGloveDescription::place_imus(const HandShape& shape) const {
  return place_imus(shape, Handedness::right);
}

std::vector<PlacedMarker> ImuGloveDescription::place_markers(const HandShape& shape, Handedness hand) const {
  std::vector<PlacedMarker> out;
  out.reserve(markers.size());
  for (std::size_t i = 0; i < markers.size(); ++i) {
    const MarkerSpec& m = markers[i];
    SurfacePoint s;
    if (m.segment == HandJoint::wrist) {
      s = dorsum_surface(shape, m.along_fraction, m.across_fraction);
    } else if (auto b = bone_of(m.segment)) {
      s = finger_surface(shape, *b, m.along_fraction, deg_to_rad(m.around_deg));
    } else {
      continue;  // parse() rejects these; a hand-built description may still hold one
    }
    if (hand == Handedness::left) {
      s.p = mirror_x(s.p);
      s.n = mirror_x(s.n);
    }
    out.push_back({i, m.segment, m.hue, s.p, s.n, m.diameter_m});
  }
  return out;
}

std::vector<PlacedImu> ImuGloveDescription::place_imus(const HandShape& shape, Handedness hand) const {
  std::vector<PlacedImu> out;
  out.reserve(imus.size());
  for (std::size_t i = 0; i < imus.size(); ++i) {
    const ImuMount& m = imus[i];
    SurfacePoint s;
    if (m.segment == HandJoint::wrist) {
      s = dorsum_surface(shape, m.along_fraction, m.across_fraction);
    } else if (auto b = bone_of(m.segment)) {
      s = finger_surface(shape, *b, m.along_fraction, 0.0);
    } else {
      continue;
    }
    Pose T{m.q_segment_imu.normalized(), s.p};
    if (hand == Handedness::left) T = {mirror_q(T.q), mirror_x(T.p)};
    out.push_back({i, m.segment, T});
  }
  return out;
}

// --- text ------------------------------------------------------------------

std::string ImuGloveDescription::describe() const {
  std::ostringstream s;
  s << (name.empty() ? std::string("unnamed glove") : name) << ": " << imus.size() << " IMU"
    << (imus.size() == 1 ? "" : "s") << " (";
  for (std::size_t i = 0; i < imus.size(); ++i) s << (i ? ", " : "") << imus[i].name;
  s << "); " << markers.size() << " markers";
  std::map<std::size_t, std::size_t> per_segment;
  std::array<std::size_t, kMarkerHueCount> per_hue{};
  double dmin = 1e9, dmax = 0.0;
  for (const auto& m : markers) {
    ++per_segment[index_of(m.segment)];
    ++per_hue[static_cast<std::size_t>(m.hue)];
    dmin = std::min(dmin, m.diameter_m);
    dmax = std::max(dmax, m.diameter_m);
  }
  if (!markers.empty()) {
    s << " of " << printf_text("%.1f", dmin * 1e3);
    if (dmax > dmin) s << "-" << printf_text("%.1f", dmax * 1e3);
    s << " mm";
  }
  s << " (";
  bool first = true;
  for (const auto j : segments()) {
    const auto it = per_segment.find(index_of(j));
    if (it == per_segment.end()) continue;
    s << (first ? "" : ", ") << segment_text(j) << " " << it->second;
    first = false;
  }
  s << "; ";
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) s << (h ? ", " : "") << kHueNames[h] << " " << per_hue[h];
  const PinholeCamera& c = rig.camera;
  const Vec3& p = rig.T_head_leftcam.p;
  s << "); stereo rig " << c.width_px << "x" << c.height_px << " px, fx " << printf_text("%.1f", c.fx_px)
    << " fy " << printf_text("%.1f", c.fy_px) << " px (" << printf_text("%.1f", rad_to_deg(c.hfov_rad()))
    << " x " << printf_text("%.1f", rad_to_deg(c.vfov_rad())) << " deg), baseline "
    << printf_text("%.1f", rig.baseline_m * 1e3) << " mm, " << printf_text("%g", rig.rate_hz)
    << " Hz, left camera at (" << printf_text("%.1f", p.x() * 1e3) << ", " << printf_text("%.1f", p.y() * 1e3)
    << ", " << printf_text("%.1f", p.z() * 1e3) << ") mm in the head frame";
  if (const auto tilt = tilt_down_rad(rig.T_head_leftcam.q)) {
    s << ", tilted " << printf_text("%.1f", rad_to_deg(*tilt)) << " deg down";
  }
  return s.str();
}

// --- file format -------------------------------------------------------------

namespace {

constexpr const char* kSegmentChoices =
    "dorsum (or wrist), or a joint that starts a bone: thumb_metacarpal, thumb_proximal, thumb_distal, "
    "index_metacarpal, index_proximal, index_intermediate, index_distal, and the same for middle, ring and little";

std::string join(const std::vector<std::string_view>& items) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? ", " : "") + std::string(items[i]);
  return out;
}

class Parser {
 public:
  explicit Parser(const Config& cfg) : cfg_(cfg) {}

  Result<ImuGloveDescription> run() {
    ImuGloveDescription g;
    if (auto st = only_keys(cfg_, "", {"name", "rig", "imu", "marker"}); !st) return st.error();
    auto name = cfg_.get_string_or("name", "");
    if (!name) return name.error();
    g.name = *name;
    g.origin = cfg_.source_name();

    if (!cfg_.contains("imu")) {
      return make_error(Errc::not_found, cfg_.source_name() +
                                             ": the glove has no IMU; add at least one [[imu]] table "
                                             "(segment, along_fraction), see docs/vist-glove.md");
    }
    auto imus = cfg_.tables("imu");
    if (!imus) return imus.error();
    for (std::size_t i = 0; i < imus->size(); ++i) {
      auto m = parse_imu((*imus)[i], "imu[" + std::to_string(i) + "]");
      if (!m) return m.error();
      for (const auto& other : g.imus) {
        if (other.name == m->name) {
          return make_error(Errc::invalid_argument,
                            cfg_.where("imu[" + std::to_string(i) + "]") + ": two IMUs are named '" + m->name +
                                "'; IMU names identify sensor streams, so give each a distinct 'name'");
        }
      }
      g.imus.push_back(std::move(*m));
    }

    if (cfg_.contains("marker")) {
      auto markers = cfg_.tables("marker");
      if (!markers) return markers.error();
      for (std::size_t i = 0; i < markers->size(); ++i) {
        auto m = parse_marker((*markers)[i], "marker[" + std::to_string(i) + "]");
        if (!m) return m.error();
        g.markers.push_back(*m);
      }
    }

    auto rig = parse_rig();
    if (!rig) return rig.error();
    g.rig = *rig;
    return g;
  }

 private:
  // "[rig]" for a table, "marker[3]" for an entry of an array of tables.
  static std::string label(const std::string& prefix) {
    return !prefix.empty() && prefix.back() == ']' ? prefix : "[" + prefix + "]";
  }

  Error error_at(const std::string& key, Errc code, const std::string& what) const {
    return make_error(code, cfg_.where(key) + ": '" + key + "' " + what);
  }

  // A key that is not part of the format is an error: a typo ("along_fraction"
  // spelt "along_frac") must not silently fall back to a default.
  Status only_keys(const Config& t, const std::string& prefix, const std::vector<std::string_view>& allowed) const {
    return t.check_keys(prefix.empty() ? "top level" : prefix, {allowed.begin(), allowed.end()}, "docs/vist-glove.md");
  }

  Result<double> required_in(const Config& t, const std::string& prefix, std::string_view key, double min,
                             double max, const char* what) const {
    if (!t.contains(key)) {
      return make_error(Errc::not_found, cfg_.where(prefix) + ": " + label(prefix) + " has no '" + std::string(key) +
                                             "' (" + what + "); add it, see docs/vist-glove.md");
    }
    return t.get_double_or(key, 0.0, min, max);
  }

  Result<double> positive(const Config& t, const std::string& prefix, std::string_view key, double max,
                          const char* what, std::optional<double> fallback = std::nullopt) const {
    Result<double> v = (fallback && !t.contains(key)) ? Result<double>(*fallback)
                                                       : required_in(t, prefix, key, 0.0, max, what);
    if (!v) return v;
    if (!(*v > 0.0)) {
      return error_at(prefix + "." + std::string(key), Errc::out_of_range,
                      "must be greater than zero (" + std::string(what) + ")");
    }
    return v;
  }

  Result<Vec3> vec3(const Config& t, const std::string& prefix, std::string_view key) const {
    auto v = t.get_doubles(key);
    if (!v) return v.error();
    if (v->size() != 3) {
      return error_at(prefix + "." + std::string(key), Errc::invalid_argument,
                      "must have 3 numbers [x, y, z], but it has " + std::to_string(v->size()));
    }
    return Vec3((*v)[0], (*v)[1], (*v)[2]);
  }

  Result<StereoRig> parse_rig() const {
    if (!cfg_.contains("rig")) {
      return make_error(Errc::not_found, cfg_.source_name() +
                                             ": the file has no [rig] table (the stereo camera that sees the "
                                             "markers); add one, see docs/vist-glove.md");
    }
    auto t = cfg_.table("rig");
    if (!t) return t.error();
    const std::string P = "rig";
    if (auto st = only_keys(*t, P,
                            {"width_px", "height_px", "hfov_deg", "vfov_deg", "fx_px", "fy_px", "cx_px", "cy_px",
                             "baseline_mm", "rate_hz", "left_camera_position_in_head_m", "left_camera_tilt_down_deg",
                             "left_camera_rotation_in_head_deg"});
        !st) {
      return st.error();
    }
    StereoRig rig;
    auto w = required_in(*t, P, "width_px", 1, 100000, "image width in pixels");
    if (!w) return w.error();
    auto h = required_in(*t, P, "height_px", 1, 100000, "image height in pixels");
    if (!h) return h.error();
    for (const char* k : {"width_px", "height_px"}) {
      if (!t->get_int(k)) return error_at(P + "." + k, Errc::invalid_argument, "must be a whole number of pixels");
    }
    const int W = static_cast<int>(*t->get_int("width_px"));
    const int H = static_cast<int>(*t->get_int("height_px"));

    const bool has_fov = t->contains("hfov_deg") || t->contains("vfov_deg");
    const bool has_f = t->contains("fx_px") || t->contains("fy_px");
    if (has_fov && has_f) {
      return error_at(P + (t->contains("fx_px") ? ".fx_px" : ".fy_px"), Errc::invalid_argument,
                      "conflicts with hfov_deg/vfov_deg; give either the field of view or the focal lengths");
    }
    if (has_f) {
      auto fx = positive(*t, P, "fx_px", 1e6, "horizontal focal length in pixels");
      if (!fx) return fx.error();
      auto fy = positive(*t, P, "fy_px", 1e6, "vertical focal length in pixels");
      if (!fy) return fy.error();
      rig.camera.width_px = W;
      rig.camera.height_px = H;
      rig.camera.fx_px = *fx;
      rig.camera.fy_px = *fy;
    } else {
      auto hf = required_in(*t, P, "hfov_deg", 1e-3, 179.0,
                            "horizontal field of view in degrees, or give fx_px and fy_px instead");
      if (!hf) return hf.error();
      auto vf = required_in(*t, P, "vfov_deg", 1e-3, 179.0,
                            "vertical field of view in degrees, or give fx_px and fy_px instead");
      if (!vf) return vf.error();
      rig.camera = PinholeCamera::from_fov(W, H, deg_to_rad(*hf), deg_to_rad(*vf));
    }
    auto cx = t->get_double_or("cx_px", 0.5 * (W - 1), 0.0, W);
    if (!cx) return cx.error();
    auto cy = t->get_double_or("cy_px", 0.5 * (H - 1), 0.0, H);
    if (!cy) return cy.error();
    rig.camera.cx_px = *cx;
    rig.camera.cy_px = *cy;

    auto b = positive(*t, P, "baseline_mm", 10000.0, "distance between the two cameras in millimetres");
    if (!b) return b.error();
    rig.baseline_m = *b / 1000.0;
    auto rate = positive(*t, P, "rate_hz", 10000.0, "frame rate in hertz");
    if (!rate) return rate.error();
    rig.rate_hz = *rate;

    if (!t->contains("left_camera_position_in_head_m")) {
      return make_error(Errc::not_found,
                        cfg_.where(P) + ": [rig] has no 'left_camera_position_in_head_m' (the left camera's "
                                        "position in the OpenXR head frame, metres, e.g. [-0.0315, 0.0, -0.08]); "
                                        "add it");
    }
    auto p = vec3(*t, P, "left_camera_position_in_head_m");
    if (!p) return p.error();
    if (p->norm() > 1.0) {
      return error_at(P + ".left_camera_position_in_head_m", Errc::out_of_range,
                      "is more than 1 m from the head centre; it is in metres, not millimetres");
    }
    const bool has_tilt = t->contains("left_camera_tilt_down_deg");
    const bool has_rot = t->contains("left_camera_rotation_in_head_deg");
    if (has_tilt == has_rot) {
      return make_error(Errc::invalid_argument,
                        cfg_.where(P) + ": [rig] needs exactly one of 'left_camera_tilt_down_deg' (degrees the "
                                        "camera is pitched down from looking straight ahead) or "
                                        "'left_camera_rotation_in_head_deg' (rotation vector of the camera in the "
                                        "head frame, degrees)");
    }
    Quat q;
    if (has_tilt) {
      auto tilt = t->get_double_or("left_camera_tilt_down_deg", 0.0, -90.0, 90.0);
      if (!tilt) return tilt.error();
      q = StereoRig::head_camera_rotation(deg_to_rad(*tilt));
    } else {
      auto r = vec3(*t, P, "left_camera_rotation_in_head_deg");
      if (!r) return r.error();
      q = so3_exp(*r * deg_to_rad(1.0));
    }
    rig.T_head_leftcam = {q, *p};
    return rig;
  }

  Result<HandJoint> segment(const Config& t, const std::string& prefix) const {
    auto s = t.get_string("segment");
    if (!s) {
      if (s.error().code == Errc::not_found) {
        return make_error(Errc::not_found, cfg_.where(prefix) + ": " + label(prefix) +
                                               " has no 'segment'; name the bone it sits on: " + kSegmentChoices);
      }
      return s.error();
    }
    auto j = parse_glove_segment(*s);
    if (!j) {
      return error_at(prefix + ".segment", Errc::invalid_argument,
                      "= \"" + *s + "\" is not a segment a glove item can sit on; use " + kSegmentChoices);
    }
    return *j;
  }

  Result<ImuMount> parse_imu(const Config& t, const std::string& P) const {
    if (auto st = only_keys(t, P, {"name", "segment", "along_fraction", "across_fraction", "rotation_deg"}); !st) {
      return st.error();
    }
    ImuMount m;
    auto seg = segment(t, P);
    if (!seg) return seg.error();
    m.segment = *seg;
    auto name = t.get_string_or("name", segment_text(m.segment));
    if (!name) return name.error();
    if (name->empty()) return error_at(P + ".name", Errc::invalid_argument, "must not be empty");
    m.name = *name;
    auto along = required_in(t, P, "along_fraction", 0.0, 1.0,
                             "fraction of the bone length from its joint, or of hand length on the dorsum, 0-1");
    if (!along) return along.error();
    m.along_fraction = *along;
    auto across = place_across(t, P, m.segment);
    if (!across) return across.error();
    m.across_fraction = *across;
    if (t.contains("rotation_deg")) {
      auto r = vec3(t, P, "rotation_deg");
      if (!r) return r.error();
      m.q_segment_imu = so3_exp(*r * deg_to_rad(1.0));
    }
    return m;
  }

  Result<double> place_across(const Config& t, const std::string& P, HandJoint seg) const {
    if (seg != HandJoint::wrist && t.contains("across_fraction")) {
      return error_at(P + ".across_fraction", Errc::invalid_argument,
                      "only applies on the dorsum; on a finger segment use around_deg (markers) or leave it out");
    }
    return t.get_double_or("across_fraction", 0.0, -0.5, 0.5);
  }

  Result<MarkerSpec> parse_marker(const Config& t, const std::string& P) const {
    if (auto st = only_keys(t, P, {"segment", "hue", "along_fraction", "around_deg", "across_fraction", "diameter_mm"});
        !st) {
      return st.error();
    }
    MarkerSpec m;
    auto seg = segment(t, P);
    if (!seg) return seg.error();
    m.segment = *seg;
    auto hue = t.get_string("hue");
    if (!hue) {
      if (hue.error().code == Errc::not_found) {
        return make_error(Errc::not_found, cfg_.where(P) + ": " + label(P) + " has no 'hue'; use one of " +
                                               join({kHueNames.begin(), kHueNames.end()}));
      }
      return hue.error();
    }
    auto h = parse_marker_hue(*hue);
    if (!h) {
      return error_at(P + ".hue", Errc::invalid_argument,
                      "= \"" + *hue + "\" is not a marker hue; use one of " +
                          join({kHueNames.begin(), kHueNames.end()}));
    }
    m.hue = *h;
    auto along = required_in(t, P, "along_fraction", 0.0, 1.0,
                             "fraction of the bone length from its joint, or of hand length on the dorsum, 0-1");
    if (!along) return along.error();
    m.along_fraction = *along;
    auto across = place_across(t, P, m.segment);
    if (!across) return across.error();
    m.across_fraction = *across;
    if (m.segment == HandJoint::wrist && t.contains("around_deg")) {
      return error_at(P + ".around_deg", Errc::invalid_argument,
                      "only applies on finger segments; on the dorsum use across_fraction");
    }
    auto around = t.get_double_or("around_deg", 0.0, -180.0, 180.0);
    if (!around) return around.error();
    m.around_deg = *around;
    auto d = positive(t, P, "diameter_mm", 100.0, "marker diameter in millimetres", 12.0);
    if (!d) return d.error();
    m.diameter_m = *d / 1000.0;
    return m;
  }

  const Config& cfg_;
};

std::string mm_text(double metres) {
  return shortest_text(metres * 1000.0, [metres](double mm) { return mm / 1000.0 == metres; })
      .value_or(num(metres * 1000.0));
}

std::string deg_vec_text(const Quat& q) {
  const Vec3 r = so3_log(q) * rad_to_deg(1.0);
  return "[" + num(r.x()) + ", " + num(r.y()) + ", " + num(r.z()) + "]";
}

}  // namespace

Result<ImuGloveDescription> ImuGloveDescription::parse(std::string_view toml_text, const std::string& source_name) {
  auto cfg = Config::parse(toml_text, source_name);
  if (!cfg) return cfg.error();
  return Parser(*cfg).run();
}

Result<ImuGloveDescription> ImuGloveDescription::load(const std::filesystem::path& path) {
  auto text = read_input_file(path, "glove description", 16 * kMiB);
  if (!text) {
    if (text.error().code != Errc::not_found) return text.error();
    return make_error(Errc::not_found, text.error().message + "; " "config/vist_glove.toml is the thesis's glove");
  }
  return parse(*text, path.string());
}

std::string ImuGloveDescription::to_toml() const {
  std::ostringstream s;
  s << "# Glove description: IMUs, markers and the stereo rig that sees them.\n"
       "# Format and frames: docs/vist-glove.md. Units are in the key names.\n\n";
  s << "name = " << toml_string(name) << "\n";

  // One inline table per line: a glove is easier to check as a table than as
  // dozens of [[marker]] blocks. They come before [rig] because a bare key
  // after a table header would belong to that table.
  auto padded = [](std::string text, std::size_t width) {
    text += ",";
    if (text.size() < width + 1) text.append(width + 1 - text.size(), ' ');
    return text;
  };
  std::size_t seg_w = 0, name_w = 0;
  for (const auto& m : imus) {
    seg_w = std::max(seg_w, toml_string(segment_text(m.segment)).size());
    name_w = std::max(name_w, toml_string(m.name).size());
  }
  for (const auto& m : markers) seg_w = std::max(seg_w, toml_string(segment_text(m.segment)).size());

  s << "\n# segment: \"dorsum\" or the XR joint that starts the bone; along_fraction: of the bone from that\n"
       "# joint (dorsum: of hand length from the wrist); across_fraction (dorsum): of hand width, + toward\n"
       "# the little finger; rotation_deg: IMU axes in the segment frame (rotation vector), default none.\n";
  s << "imu = [\n";
  for (const auto& m : imus) {
    s << "  { name = " << padded(toml_string(m.name), name_w) << " segment = "
      << padded(toml_string(segment_text(m.segment)), seg_w) << " along_fraction = " << num(m.along_fraction);
    if (m.segment == HandJoint::wrist) s << ", across_fraction = " << num(m.across_fraction);
    if (angle_between(m.q_segment_imu, Quat::Identity()) > 0.0) {
      s << ", rotation_deg = " << deg_vec_text(m.q_segment_imu);
    }
    s << " },\n";
  }
  s << "]\n";

  s << "\n# around_deg (finger segments): around the bone from the back of the finger, + toward the little\n"
       "# finger; across_fraction (dorsum) as for the IMUs.\n";
  s << "marker = [\n";
  for (const auto& m : markers) {
    s << "  { segment = " << padded(toml_string(segment_text(m.segment)), seg_w)
      << " hue = " << padded(toml_string(to_string(m.hue)), 8) << " along_fraction = " << num(m.along_fraction);
    if (m.segment == HandJoint::wrist) {
      s << ", across_fraction = " << num(m.across_fraction);
    } else {
      s << ", around_deg = " << num(m.around_deg);
    }
    s << ", diameter_mm = " << mm_text(m.diameter_m) << " },\n";
  }
  s << "]\n";

  const PinholeCamera& c = rig.camera;
  s << "\n[rig]\n";
  s << "width_px = " << c.width_px << "\n";
  s << "height_px = " << c.height_px << "\n";
  // The field of view reads better than focal lengths; write it when it
  // reproduces the focal lengths exactly (it does for any rig parsed from one).
  const auto hfov = shortest_text(rad_to_deg(c.hfov_rad()), [&](double d) {
    return PinholeCamera::from_fov(c.width_px, c.height_px, deg_to_rad(d), 1.0).fx_px == c.fx_px;
  });
  const auto vfov = shortest_text(rad_to_deg(c.vfov_rad()), [&](double d) {
    return PinholeCamera::from_fov(c.width_px, c.height_px, 1.0, deg_to_rad(d)).fy_px == c.fy_px;
  });
  if (hfov && vfov) {
    s << "hfov_deg = " << *hfov << "\nvfov_deg = " << *vfov << "\n";
  } else {
    s << "fx_px = " << num(c.fx_px) << "\nfy_px = " << num(c.fy_px) << "\n";
  }
  if (c.cx_px != 0.5 * (c.width_px - 1)) s << "cx_px = " << num(c.cx_px) << "\n";
  if (c.cy_px != 0.5 * (c.height_px - 1)) s << "cy_px = " << num(c.cy_px) << "\n";
  s << "baseline_mm = " << mm_text(rig.baseline_m) << "\n";
  s << "rate_hz = " << num(rig.rate_hz) << "\n";
  s << "left_camera_position_in_head_m = " << vec_text(rig.T_head_leftcam.p) << "\n";
  // A pure downward tilt is written as such; anything else as a rotation vector.
  if (const auto tilt = tilt_down_rad(rig.T_head_leftcam.q)) {
    const double t = *tilt;
    s << "left_camera_tilt_down_deg = "
      << shortest_text(rad_to_deg(t), [t](double d) { return std::abs(deg_to_rad(d) - t) < 1e-12; })
             .value_or(num(rad_to_deg(t)))
      << "\n";
  } else {
    s << "left_camera_rotation_in_head_deg = " << deg_vec_text(rig.T_head_leftcam.q) << "\n";
  }
  return s.str();
}

}  // namespace proprio
