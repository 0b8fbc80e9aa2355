#include "proprio/openxr_layer/layer_config.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <algorithm>
#include <set>
#include <utility>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::openxr_layer {

std::string_view to_string(SourceType t) noexcept {
  switch (t) {
    case SourceType::sim: return "sim";
    case SourceType::replay: return "replay";
    case SourceType::vist: return "vist";
    case SourceType::glove: return "glove";
    case SourceType::ftm: return "ftm";
  }
  return "unknown";
}

std::string_view to_string(ReferenceSpace s) noexcept {
  switch (s) {
    case ReferenceSpace::view: return "view";
    case ReferenceSpace::local: return "local";
    case ReferenceSpace::stage: return "stage";
  }
  return "?";
}

std::string_view to_string(RuntimeHandTracking m) noexcept {
  switch (m) {
    case RuntimeHandTracking::automatic: return "auto";
    case RuntimeHandTracking::override_it: return "override";
    case RuntimeHandTracking::pass_through: return "passthrough";
  }
  return "?";
}

std::string_view to_string(WristSource w) noexcept {
  switch (w) {
    case WristSource::source: return "source";
    case WristSource::controller: return "controller";
    case WristSource::tracker: return "tracker";
    case WristSource::runtime_hand: return "runtime_hand";
  }
  return "?";
}

std::string SourceConfig::describe() const {
  std::string hand_list;
  for (auto h : hands) hand_list += (hand_list.empty() ? "" : "+") + std::string(proprio::to_string(h));
  char buf[512];
  const Vec3 rv = so3_log(T_space_source.q);
  std::snprintf(buf, sizeof buf, "%s source for %s hand(s), bound to %s space at offset (%.3f, %.3f, %.3f) m, rotation (%.1f, %.1f, %.1f) deg",
                std::string(to_string(type)).c_str(), hand_list.c_str(), std::string(to_string(space)).c_str(),
                T_space_source.p.x(), T_space_source.p.y(), T_space_source.p.z(), rv.x() * 57.2958,
                rv.y() * 57.2958, rv.z() * 57.2958);
  std::string s = buf;
  if (type == SourceType::glove) {
    std::snprintf(buf, sizeof buf, "; input %s, subject %d, seed %llu, model %s", input.c_str(), subject,
                  static_cast<unsigned long long>(seed), model.empty() ? "(shipped)" : model.c_str());
  } else if (type == SourceType::ftm) {
    std::snprintf(buf, sizeof buf, "; input %s, subject %d, seed %llu, calibration %s, abduction %s", input.c_str(),
                  subject, static_cast<unsigned long long>(seed),
                  calibration.empty() ? "(from the wearer's calibration phases)" : calibration.c_str(),
                  track_abduction ? "tracked" : "held at 0");
  } else if (type == SourceType::vist && input == "device") {
    std::snprintf(buf, sizeof buf, "; input device, camera %s%s%s, glove %s", camera.c_str(),
                  camera_right.empty() ? "" : " + ", camera_right.c_str(),
                  glove_description.empty() ? "(thesis glove)" : glove_description.c_str());
  } else if (type == SourceType::vist && input == "emulated") {
    std::snprintf(buf, sizeof buf, "; input emulated, subject %d, seed %llu", subject,
                  static_cast<unsigned long long>(seed));
  } else if (type == SourceType::sim) {
    std::snprintf(buf, sizeof buf, "; protocol %s, subject %d, seed %llu, %.1f Hz",
                  std::string(sim::to_string(protocol)).c_str(), subject, static_cast<unsigned long long>(seed),
                  rate_hz);
  } else {
    std::snprintf(buf, sizeof buf, "; file %s%s", path.c_str(), loop ? ", looped" : "");
  }
  s += buf;
  if (wrist != WristSource::source) {
    const Vec3 wr = so3_log(T_device_wrist.q);
    std::snprintf(buf, sizeof buf, "; wrist from the runtime's %s%s%s", std::string(to_string(wrist)).c_str(),
                  wrist == WristSource::runtime_hand ? "" : ", device-to-wrist ",
                  wrist == WristSource::runtime_hand ? ""
                  : !wrist_calibration.empty()       ? wrist_calibration.c_str()
                                                     : "");
    s += buf;
    if (wrist != WristSource::runtime_hand && wrist_calibration.empty()) {
      std::snprintf(buf, sizeof buf, "(%.3f, %.3f, %.3f) m, (%.1f, %.1f, %.1f) deg", T_device_wrist.p.x(),
                    T_device_wrist.p.y(), T_device_wrist.p.z(), wr.x() * 57.2958, wr.y() * 57.2958, wr.z() * 57.2958);
      s += buf;
    }
  }
  return s;
}

std::string LayerConfig::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf, "%s: runtime_hand_tracking=%s max_prediction=%.1fms stale_timeout=%.1fms, %zu source(s)",
                origin.c_str(), std::string(to_string(runtime_hand_tracking)).c_str(),
                static_cast<double>(max_prediction_ns) * 1e-6, static_cast<double>(stale_timeout_ns) * 1e-6,
                sources.size());
  std::string s = buf;
  for (std::size_t i = 0; i < sources.size(); ++i) s += "\n  [" + std::to_string(i) + "] " + sources[i].describe();
  if (haptics.enabled) s += "\n  " + haptics.describe();
  return s;
}

std::filesystem::path default_layer_config_path() {
  if (const char* p = std::getenv("PROPRIO_LAYER_CONFIG"); p && *p) return p;
  if (const char* x = std::getenv("XDG_CONFIG_HOME"); x && *x) return std::filesystem::path(x) / "proprio" / "layer.toml";
  if (const char* h = std::getenv("HOME"); h && *h) return std::filesystem::path(h) / ".config" / "proprio" / "layer.toml";
  return "layer.toml";
}

namespace {

template <typename T>
Result<T> choose(const Config& c, std::string_view key, std::string fallback,
                 std::initializer_list<std::pair<const char*, T>> options) {
  auto v = c.get_string_or(key, std::move(fallback));
  if (!v) return v.error();
  std::string allowed;
  for (const auto& [name, value] : options) {
    if (*v == name) return value;
    allowed += (allowed.empty() ? "" : ", ") + std::string(name);
  }
  return make_error(Errc::invalid_argument, c.source_name() + ": '" + std::string(key) + "' = \"" + printable(*v, 80) +
                                                "\" is not one of: " + allowed);
}

// Offsets beyond `limit` are typos, and huge ones turn into invalid poses
// downstream (the runtime refuses the reference space, so hand tracking that
// the layer advertised would fail at tracker creation).
Result<Vec3> vec3(const Config& c, std::string_view key, double limit) {
  if (!c.contains(key)) return Vec3(Vec3::Zero());
  auto v = c.get_doubles(key);
  if (!v) return v.error();
  if (v->size() != 3) {
    return make_error(Errc::invalid_argument,
                      c.where(key) + ": '" + std::string(key) + "' needs 3 numbers, got " + std::to_string(v->size()));
  }
  for (double x : *v) {
    if (!std::isfinite(x) || std::fabs(x) > limit) {
      return make_error(Errc::invalid_argument, c.where(key) + ": '" + std::string(key) + "' has " +
                                                    std::to_string(x) + "; each component must be within +-" +
                                                    std::to_string(static_cast<int>(limit)));
    }
  }
  return Vec3((*v)[0], (*v)[1], (*v)[2]);
}

// The keys each kind of [[source]] reads; anything else is a typo that
// would otherwise be ignored silently.
std::set<std::string> source_keys(SourceType type) {
  std::set<std::string> k{"type",  "space", "hands", "offset_position_m", "offset_rotation_deg",
                          "wrist", "wrist_offset_position_m", "wrist_offset_rotation_deg", "wrist_calibration",
                          "tracker_role_left", "tracker_role_right"};
  switch (type) {
    case SourceType::glove:
      k.insert({"input", "calibration", "hand_length_m", "hand_width_m", "subject", "seed", "model", "layout",
                "truth_path", "unplug_s"});
      break;
    case SourceType::ftm:
      k.insert({"input", "calibration", "subject", "seed", "truth_path", "unplug_s", "abduction"});
      break;
    case SourceType::sim: k.insert({"protocol", "subject", "seed", "rate_hz"}); break;
    case SourceType::replay: k.insert({"path", "loop"}); break;
    case SourceType::vist:
      k.insert({"input", "path", "loop", "camera", "camera_right", "stereo_calibration", "glove", "imu_path",
                "imu_serial", "subject", "seed", "truth_path", "unplug_s"});
      break;
  }
  return k;
}

// A tracker role is one path segment of XR_HTCX_vive_tracker_interaction.
Status check_role(const Config& c, std::string_view key, const std::string& role) {
  const bool ok = !role.empty() && role.size() <= 32 &&
                  role.find_first_not_of("abcdefghijklmnopqrstuvwxyz_0123456789") == std::string::npos;
  if (ok) return {};
  return make_error(Errc::invalid_argument, c.where(key) + ": '" + std::string(key) + "' = \"" + printable(role, 40) +
                                                "\" is not a tracker role (lower-case letters, digits and '_', "
                                                "e.g. \"left_wrist\")");
}

Status parse_wrist(const Config& c, SourceConfig& s) {
  auto wrist = choose<WristSource>(c, "wrist", "source",
                                   {{"source", WristSource::source},
                                    {"controller", WristSource::controller},
                                    {"tracker", WristSource::tracker},
                                    {"runtime_hand", WristSource::runtime_hand}});
  if (!wrist) return wrist.error();
  s.wrist = *wrist;
  const bool device = s.wrist == WristSource::controller || s.wrist == WristSource::tracker;
  for (const char* key : {"wrist_offset_position_m", "wrist_offset_rotation_deg", "wrist_calibration"}) {
    if (c.contains(key) && !device) {
      return make_error(Errc::invalid_argument, c.where(key) + ": '" + std::string(key) +
                                                    "' applies only to wrist = \"controller\" or \"tracker\"");
    }
  }
  if (s.wrist != WristSource::tracker) {
    for (const char* key : {"tracker_role_left", "tracker_role_right"}) {
      if (c.contains(key)) {
        return make_error(Errc::invalid_argument,
                          c.where(key) + ": '" + std::string(key) + "' applies only to wrist = \"tracker\"");
      }
    }
  }
  if (!device) return {};
  if (s.wrist == WristSource::tracker) {
    const char* keys[2] = {"tracker_role_left", "tracker_role_right"};
    for (int h = 0; h < 2; ++h) {
      auto role = c.get_string_or(keys[h], s.tracker_role[h]);
      if (!role) return role.error();
      if (auto st = check_role(c, keys[h], *role); !st) return st;
      s.tracker_role[h] = *role;
    }
  }
  if (c.contains("wrist_calibration") &&
      (c.contains("wrist_offset_position_m") || c.contains("wrist_offset_rotation_deg"))) {
    return make_error(Errc::invalid_argument, c.where("wrist_calibration") +
                                                  ": give either 'wrist_calibration' or the inline wrist offset, "
                                                  "not both");
  }
  auto cal = c.get_string_or("wrist_calibration", "");
  if (!cal) return cal.error();
  s.wrist_calibration = *cal;
  if (!s.wrist_calibration.empty()) return {};  // loaded when the layer starts the source
  // Without a calibration: the wrist 8 cm behind a controller's grip point
  // (a hand holding it), on a wrist tracker's own origin. Rough: calibrate.
  const Vec3 fallback = s.wrist == WristSource::controller ? Vec3(0.0, 0.0, 0.08) : Vec3(Vec3::Zero());
  auto p = vec3(c, "wrist_offset_position_m", 1.0);
  if (!p) return p.error();
  auto r = vec3(c, "wrist_offset_rotation_deg", 360.0);
  if (!r) return r.error();
  s.T_device_wrist = {so3_exp(*r * (M_PI / 180.0)), c.contains("wrist_offset_position_m") ? *p : fallback};
  return {};
}

// unplug_s = [at, duration, at, duration, ...], seconds.
Status parse_unplugs(const Config& c, SourceConfig& s) {
  if (!c.contains("unplug_s")) return {};
  auto v = c.get_doubles("unplug_s");
  if (!v) return v.error();
  if (v->size() % 2 != 0 || v->empty() || v->size() > 16) {
    return make_error(Errc::invalid_argument, c.where("unplug_s") +
                                                  ": 'unplug_s' takes pairs [at, duration, ...] in seconds (1 to 8 "
                                                  "pairs), got " + std::to_string(v->size()) + " numbers");
  }
  for (std::size_t i = 0; i < v->size(); i += 2) {
    const double at = (*v)[i], duration = (*v)[i + 1];
    if (!std::isfinite(at) || !std::isfinite(duration) || at < 0.0 || at > 86400.0 || duration <= 0.0 ||
        duration > 3600.0) {
      return make_error(Errc::invalid_argument, c.where("unplug_s") + ": 'unplug_s' pair " +
                                                    std::to_string(i / 2 + 1) +
                                                    " needs 0 <= at <= 86400 and 0 < duration <= 3600 seconds");
    }
    s.unplugs.push_back({at, duration});
  }
  return {};
}

// The keys each vist input reads (the rest of source_keys(vist) is refused
// with the input that would read it named).
Status parse_vist(const Config& c, SourceConfig& s) {
  auto input = choose<std::string>(c, "input", "replay",
                                   {{"replay", std::string("replay")},
                                    {"device", std::string("device")},
                                    {"emulated", std::string("emulated")}});
  if (!input) return input.error();
  s.input = *input;
  const std::set<std::string> replay{"path", "loop"};
  const std::set<std::string> device{"camera", "camera_right", "stereo_calibration", "imu_path", "imu_serial"};
  const std::set<std::string> emulated{"subject", "seed", "truth_path", "unplug_s"};
  const std::set<std::string>& mine = s.input == "replay" ? replay : s.input == "device" ? device : emulated;
  for (const auto* group : {&replay, &device, &emulated}) {
    if (group == &mine) continue;
    for (const auto& key : *group) {
      if (c.contains(key) && !mine.count(key)) {
        return make_error(Errc::invalid_argument, c.where(key) + ": '" + key + "' does not apply to input = \"" +
                                                      s.input + "\"");
      }
    }
  }
  if (s.space == ReferenceSpace::view && s.input != "replay") {
    return make_error(Errc::invalid_argument,
                      c.source_name() + ": a live vist source tracks in a world that stays still while the head "
                                        "moves: set space = \"local\" or \"stage\", not \"view\"");
  }
  if (s.input == "replay" && c.contains("glove")) {  // the recording names its glove; this one would go unused
    return make_error(Errc::invalid_argument, c.where("glove") +
                                                  ": 'glove' does not apply to input = \"replay\" (the recording "
                                                  "holds the glove it was made with)");
  }
  auto glove = c.get_string_or("glove", "");
  if (!glove) return glove.error();
  s.glove_description = *glove;
  if (s.input == "replay") {
    auto path = c.get_string("path");
    if (!path) return path.error().with_context("a vist source with input \"replay\" needs a VIST session recording's path");
    s.path = *path;
    auto loop = c.get_bool_or("loop", true);
    if (!loop) return loop.error();
    s.loop = *loop;
  } else if (s.input == "device") {
    for (auto [key, field] : {std::pair{"camera", &s.camera}, std::pair{"camera_right", &s.camera_right},
                              std::pair{"stereo_calibration", &s.stereo_calibration},
                              std::pair{"imu_path", &s.imu_path}, std::pair{"imu_serial", &s.imu_serial}}) {
      auto v = c.get_string_or(key, *field);
      if (!v) return v.error();
      *field = *v;
    }
    if (s.camera.empty()) return make_error(Errc::invalid_argument, c.where("camera") + ": 'camera' is empty");
  } else {
    auto subject = c.get_int_or("subject", 3, 0, 14);
    if (!subject) return subject.error();
    s.subject = static_cast<int>(*subject);
    auto seed = c.get_int_or("seed", 1, 0, INT64_MAX);
    if (!seed) return seed.error();
    s.seed = static_cast<std::uint64_t>(*seed);
  }
  auto truth = c.get_string_or("truth_path", "");
  if (!truth) return truth.error();
  s.truth_path = *truth;
  return parse_unplugs(c, s);
}

// ftm: one glove on one hand; a board needs its calibration file, the
// simulated wearer calibrates itself unless given one.
Status parse_ftm(const Config& c, SourceConfig& s) {
  auto input = choose<std::string>(
      c, "input", "sim",
      {{"sim", std::string("sim")}, {"emulated", std::string("emulated")}, {"device", std::string("device")}});
  if (!input) return input.error();
  s.input = *input;
  if (c.contains("hands")) {
    if (s.hands.size() != 1) {
      return make_error(Errc::invalid_argument, c.where("hands") +
                                                    ": an ftm source is one glove: give one hand (\"left\" or "
                                                    "\"right\"), and a second [[source]] for the other glove");
    }
  } else {
    s.hands = {Handedness::right};
  }
  if (c.contains("truth_path") && s.input == "device") {
    return make_error(Errc::invalid_argument,
                      c.where("truth_path") + ": 'truth_path' applies only to input = \"sim\" or \"emulated\"");
  }
  auto truth = c.get_string_or("truth_path", "");
  if (!truth) return truth.error();
  s.truth_path = *truth;
  if (c.contains("unplug_s") && s.input != "emulated") {
    return make_error(Errc::invalid_argument, c.where("unplug_s") + ": 'unplug_s' applies only to input = \"emulated\"");
  }
  if (auto st = parse_unplugs(c, s); !st) return st;
  for (const char* key : {"subject", "seed"}) {
    if (c.contains(key) && s.input == "device") {
      return make_error(Errc::invalid_argument, c.where(key) + ": '" + key +
                                                    "' applies only to a simulated wearer (input = \"sim\" or "
                                                    "\"emulated\")");
    }
  }
  if (s.input == "device") {
    auto cal = c.get_string("calibration");
    if (!cal) {
      return cal.error().with_context("an FTM board needs the wearer's calibration: run 'proprio calibrate ftm' and "
                                      "name its file in 'calibration'");
    }
    if (cal->empty()) return make_error(Errc::invalid_argument, c.where("calibration") + ": 'calibration' is empty");
    s.calibration = *cal;
  } else {
    auto cal = c.get_string_or("calibration", "");
    if (!cal) return cal.error();
    s.calibration = *cal;
  }
  auto subject = c.get_int_or("subject", 3, 0, 14);
  if (!subject) return subject.error();
  s.subject = static_cast<int>(*subject);
  auto seed = c.get_int_or("seed", 1, 0, INT64_MAX);
  if (!seed) return seed.error();
  s.seed = static_cast<std::uint64_t>(*seed);
  auto abduction = c.get_bool_or("abduction", true);
  if (!abduction) return abduction.error();
  s.track_abduction = *abduction;
  return {};
}

Result<SourceConfig> parse_source(const Config& c, std::size_t index) {
  const std::string where = c.source_name() + ": [[source]] #" + std::to_string(index + 1);
  SourceConfig s;
  auto type = choose<SourceType>(c, "type", "",
                                 {{"sim", SourceType::sim},
                                  {"replay", SourceType::replay},
                                  {"vist", SourceType::vist},
                                  {"glove", SourceType::glove},
                                  {"ftm", SourceType::ftm}});
  if (!type) return type.error().with_context(where);
  s.type = *type;
  if (auto k = c.check_keys("source", source_keys(s.type)); !k) {
    return k.error().with_context(where + " (type \"" + std::string(to_string(s.type)) + "\")");
  }
  const bool head_relative = s.type == SourceType::sim || s.type == SourceType::glove || s.type == SourceType::ftm;
  auto space = choose<ReferenceSpace>(c, "space", head_relative ? "view" : "local",
                                      {{"view", ReferenceSpace::view}, {"local", ReferenceSpace::local},
                                       {"stage", ReferenceSpace::stage}});
  if (!space) return space.error().with_context(where);
  s.space = *space;

  if (c.contains("hands")) {
    auto names = c.get_strings("hands");
    if (!names) return names.error().with_context(where);
    s.hands.clear();
    for (const auto& n : *names) {
      auto h = parse_handedness(n);
      if (!h) return make_error(Errc::invalid_argument, where + ": hands entry \"" + n + "\" is not \"left\" or \"right\"");
      s.hands.push_back(*h);
    }
    if (s.hands.empty()) return make_error(Errc::invalid_argument, where + ": 'hands' is empty");
  }
  auto p = vec3(c, "offset_position_m", 1000.0);
  if (!p) return p.error().with_context(where);
  auto r = vec3(c, "offset_rotation_deg", 360.0);
  if (!r) return r.error().with_context(where);
  s.T_space_source = {so3_exp(*r * (M_PI / 180.0)), *p};
  if (auto w = parse_wrist(c, s); !w) return w.error().with_context(where);

  if (s.type == SourceType::glove) {
    auto input = choose<std::string>(
        c, "input", "sim",
        {{"sim", std::string("sim")}, {"emulated", std::string("emulated")}, {"device", std::string("device")}});
    if (!input) return input.error().with_context(where);
    s.input = *input;
    if (c.contains("truth_path") && s.input != "emulated") {
      return make_error(Errc::invalid_argument,
                        c.where("truth_path") + ": 'truth_path' applies only to input = \"emulated\"");
    }
    auto truth = c.get_string_or("truth_path", "");
    if (!truth) return truth.error().with_context(where);
    s.truth_path = *truth;
    if (c.contains("unplug_s") && s.input != "emulated") {
      return make_error(Errc::invalid_argument,
                        c.where("unplug_s") + ": 'unplug_s' applies only to input = \"emulated\"");
    }
    if (auto st = parse_unplugs(c, s); !st) return st.error().with_context(where);
    if (s.input == "device") {
      auto cal = c.get_string("calibration");
      if (!cal) {
        return cal.error().with_context(where + " (a glove read-out board needs the wearer's calibration: run "
                                                "'proprio calibrate glove --out FILE' and name FILE here)");
      }
      s.calibration = *cal;
      auto length = c.get_double_or("hand_length_m", 0.19, 0.12, 0.26);
      if (!length) return length.error().with_context(where);
      s.hand_length_m = *length;
      auto width = c.get_double_or("hand_width_m", 0.10, 0.06, 0.14);
      if (!width) return width.error().with_context(where);
      s.hand_width_m = *width;
    }
    auto subject = c.get_int_or("subject", 3, 0, 14);
    if (!subject) return subject.error().with_context(where);
    s.subject = static_cast<int>(*subject);
    auto seed = c.get_int_or("seed", 1, 0, INT64_MAX);
    if (!seed) return seed.error().with_context(where);
    s.seed = static_cast<std::uint64_t>(*seed);
    auto model = c.get_string_or("model", "");
    if (!model) return model.error().with_context(where);
    s.model = *model;
    auto layout = c.get_string_or("layout", "");
    if (!layout) return layout.error().with_context(where);
    s.layout = *layout;
    if (!c.contains("hands")) s.hands = {Handedness::right};
  } else if (s.type == SourceType::ftm) {
    if (auto st = parse_ftm(c, s); !st) return st.error().with_context(where);
  } else if (s.type == SourceType::sim) {
    auto protocol = c.get_string_or("protocol", "free-motion");
    if (!protocol) return protocol.error().with_context(where);
    auto parsed = sim::parse_motion_protocol(*protocol);
    if (!parsed) {
      std::string allowed;
      for (const std::string& name : sim::motion_protocol_names()) allowed += (allowed.empty() ? "" : ", ") + name;
      return make_error(Errc::invalid_argument,
                        where + ": protocol \"" + printable(*protocol, 80) + "\" is not one of: " + allowed);
    }
    s.protocol = *parsed;
    auto subject = c.get_int_or("subject", 3, 0, 14);
    if (!subject) return subject.error().with_context(where);
    s.subject = static_cast<int>(*subject);
    auto seed = c.get_int_or("seed", 1, 0, INT64_MAX);
    if (!seed) return seed.error().with_context(where);
    s.seed = static_cast<std::uint64_t>(*seed);
    auto rate = c.get_double_or("rate_hz", 90.0, 1.0, 1000.0);
    if (!rate) return rate.error().with_context(where);
    s.rate_hz = *rate;
  } else if (s.type == SourceType::vist) {
    if (auto st = parse_vist(c, s); !st) return st.error().with_context(where);
    if (!c.contains("hands")) s.hands = {Handedness::right};
  } else {
    auto path = c.get_string("path");
    if (!path) return path.error().with_context(where + " (a replay source needs the recording's path)");
    s.path = *path;
    auto loop = c.get_bool_or("loop", true);
    if (!loop) return loop.error().with_context(where);
    s.loop = *loop;
  }
  return s;
}

}  // namespace

std::string_view to_string(HapticDevices d) noexcept { return d == HapticDevices::hid ? "hid" : "emulated"; }

std::string HapticsConfig::describe() const {
  if (!enabled) return "haptics: none";
  std::string s = "haptics: " + std::string(to_string(devices)) + " devices, model " + (model.empty() ? "(by kind)" : model);
  for (std::size_t h = 0; h < 2; ++h) {
    s += h == 0 ? "; left: " : "; right: ";
    if (fingers[h].empty()) s += "none";
    for (std::size_t i = 0; i < fingers[h].size(); ++i) s += (i ? "," : "") + std::string(to_string(fingers[h][i]));
  }
  char buf[160];
  std::snprintf(buf, sizeof buf, "; contact simulation %s, force scale %.3g, vibration gain %.3g", contact ? "allowed" : "off",
                force_scale, vibration_gain);
  return s + buf;
}

namespace {

Result<HapticsConfig> parse_haptics(const Config& c) {
  if (auto k = c.check_keys("haptics", {"devices", "model", "left", "right", "bind_left", "bind_right", "force_scale",
                                        "contact", "vibration_gain"});
      !k) {
    return k.error();
  }
  HapticsConfig h;
  h.enabled = true;
  auto devices = choose<HapticDevices>(c, "devices", "emulated",
                                       {{"emulated", HapticDevices::emulated}, {"hid", HapticDevices::hid}});
  if (!devices) return devices.error();
  h.devices = *devices;
  auto model = c.get_string_or("model", h.devices == HapticDevices::hid ? "" : "platform_3dof");
  if (!model) return model.error();
  h.model = *model;
  if (h.devices == HapticDevices::emulated && h.model.empty()) {
    return make_error(Errc::invalid_argument, "model: emulated devices need a device model (e.g. \"platform_3dof\")");
  }
  const char* const keys[2] = {"left", "right"};
  for (std::size_t side = 0; side < 2; ++side) {
    if (!c.contains(keys[side])) continue;
    auto names = c.get_strings(keys[side]);
    if (!names) return names.error();
    for (const auto& n : *names) {
      auto f = parse_finger(n);
      if (!f) {
        return make_error(Errc::invalid_argument, std::string(keys[side]) + ": unknown finger '" + printable(n, 40) +
                                                      "' (thumb, index, middle, ring, little)");
      }
      if (std::find(h.fingers[side].begin(), h.fingers[side].end(), *f) != h.fingers[side].end()) {
        return make_error(Errc::invalid_argument, std::string(keys[side]) + ": finger '" + n + "' listed twice");
      }
      h.fingers[side].push_back(*f);
    }
    const std::string bind_key = std::string("bind_") + keys[side];
    if (c.contains(bind_key)) {
      auto binds = c.get_strings(bind_key);
      if (!binds) return binds.error();
      h.bindings[side] = *binds;
    }
  }
  if (h.device_count() == 0) {
    return make_error(Errc::invalid_argument, "lists no fingers: give left = [...] and/or right = [...], e.g. right = [\"index\"]");
  }
  auto scale = c.get_double_or("force_scale", 1.0, 1e-3, 10.0);
  if (!scale) return scale.error();
  h.force_scale = *scale;
  auto contact = c.get_bool_or("contact", true);
  if (!contact) return contact.error();
  h.contact = *contact;
  auto gain = c.get_double_or("vibration_gain", 0.5, 0.0, 1.0);
  if (!gain) return gain.error();
  h.vibration_gain = *gain;
  return h;
}

}  // namespace

Result<LayerConfig> parse_layer_config(std::string_view toml_text, const std::string& source_name) {
  auto c = Config::parse(toml_text, source_name);
  if (!c) return c.error();
  LayerConfig cfg;
  cfg.origin = source_name;
  if (auto k = c->check_keys("top level", {"layer", "source", "haptics"}); !k) return k.error();
  if (c->contains("layer")) {
    auto layer = c->table("layer");
    if (!layer) return layer.error();
    if (auto k = layer->check_keys("layer", {"runtime_hand_tracking", "max_prediction_ms", "stale_timeout_ms"}); !k) {
      return k.error();
    }
    auto mode = choose<RuntimeHandTracking>(*layer, "runtime_hand_tracking", "auto",
                                            {{"auto", RuntimeHandTracking::automatic},
                                             {"override", RuntimeHandTracking::override_it},
                                             {"passthrough", RuntimeHandTracking::pass_through}});
    if (!mode) return mode.error();
    cfg.runtime_hand_tracking = *mode;
    auto pred = layer->get_double_or("max_prediction_ms", 50.0, 0.0, 500.0);
    if (!pred) return pred.error();
    cfg.max_prediction_ns = seconds_to_ns(*pred * 1e-3);
    auto stale = layer->get_double_or("stale_timeout_ms", 500.0, 0.0, 10000.0);
    if (!stale) return stale.error();
    cfg.stale_timeout_ns = seconds_to_ns(*stale * 1e-3);
  }
  if (c->contains("haptics")) {
    auto h = c->table("haptics");
    if (!h) return h.error();
    auto parsed = parse_haptics(*h);
    if (!parsed) return parsed.error().with_context(source_name + ": [haptics]");
    cfg.haptics = std::move(*parsed);
  }
  if (c->contains("source")) {
    auto sources = c->tables("source");
    if (!sources) return sources.error();
    for (std::size_t i = 0; i < sources->size(); ++i) {
      auto s = parse_source((*sources)[i], i);
      if (!s) return s.error();
      cfg.sources.push_back(std::move(*s));
    }
  }
  return cfg;
}

Result<LayerConfig> load_layer_config(const std::filesystem::path& path) {
  // The layer reads this inside someone else's app: never a FIFO (it would
  // block instance creation) or a device, and never more than a config's worth.
  auto text = read_input_file(path, "layer config", kMaxLayerConfigBytes);
  if (!text) return text.error();
  return parse_layer_config(*text, path.string());
}

Result<Pose> load_wrist_calibration(const std::filesystem::path& path) {
  auto text = read_input_file(path, "wrist calibration", 64 * 1024);
  if (!text) return text.error();
  auto c = Config::parse(*text, path.string());
  if (!c) return c.error();
  if (auto k = c->check_keys("top level", {"wrist"}); !k) return k.error();
  auto w = c->table("wrist");
  if (!w) return w.error();
  if (auto k = w->check_keys("wrist", {"position_m", "rotation_deg"}); !k) return k.error();
  for (const char* key : {"position_m", "rotation_deg"}) {
    if (!w->contains(key)) {
      return make_error(Errc::invalid_argument, path.string() + ": [wrist] needs '" + std::string(key) + "'");
    }
  }
  auto p = vec3(*w, "position_m", 1.0);
  if (!p) return p.error();
  auto r = vec3(*w, "rotation_deg", 360.0);
  if (!r) return r.error();
  return Pose{so3_exp(*r * (M_PI / 180.0)), *p};
}

std::string format_wrist_calibration(const Pose& T_device_wrist, std::string_view comment) {
  const Vec3 r = so3_log(T_device_wrist.q) * (180.0 / M_PI);
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "# The wrist in the tracked device's grip frame (proprio calibrate wrist).\n# %.*s\n[wrist]\n"
                "position_m = [%.5f, %.5f, %.5f]\nrotation_deg = [%.3f, %.3f, %.3f]   # rotation vector, degrees\n",
                static_cast<int>(std::min<std::size_t>(comment.size(), 300)), comment.data(), T_device_wrist.p.x(),
                T_device_wrist.p.y(), T_device_wrist.p.z(), r.x(), r.y(), r.z());
  return buf;
}

std::string example_layer_config(const std::string& recording_path) {
  std::string s = R"(# Proprio OpenXR layer configuration (docs/openxr-layer.md).
# Units: metres, degrees, milliseconds, Hz, as each key's name says.

[layer]
# When the runtime has its own hand tracking: "auto" (use Proprio's hands when a
# source below is configured), "override" (always Proprio) or "passthrough" (always the runtime).
runtime_hand_tracking = "auto"
# Furthest the layer extrapolates a hand past its newest pose.
max_prediction_ms = 50
# Past the prediction horizon the newest pose is reported as valid but not
# tracked for this long; after that the hand is inactive.
stale_timeout_ms = 500

)";
  if (recording_path.empty()) {
    s += R"([[source]]
# The procedural hand: a simulated subject performing a motion protocol.
type = "sim"
hands = ["left", "right"]
# The reference space the source's origin is bound to: "view" (head-mounted
# camera), "local" or "stage" (fixed setups), plus a calibrated offset.
space = "view"
offset_position_m = [0.0, 0.0, 0.0]
offset_rotation_deg = [0.0, 0.0, 0.0]   # rotation vector (axis * angle), degrees
protocol = "free-motion"                # free-motion | pinch-grasp | wrist-sweep | natural | tapping | pinch-grasp-contact
subject = 3                             # 0-14
seed = 1
rate_hz = 90
)";
  } else {
    s += R"([[source]]
# A recorded session (proprio sim-hand, or a tracker's recording), played in a loop.
type = "replay"
hands = ["left", "right"]
# sim-hand recordings are in the simulation's world frame: floor at y = 0,
# the head 1.6 m above it, so STAGE (floor-level origin) puts them right.
space = "stage"
offset_position_m = [0.0, 0.0, 0.0]
offset_rotation_deg = [0.0, 0.0, 0.0]
path = ")" + recording_path + R"("
loop = true
)";
  }
  return s;
}

}  // namespace proprio::openxr_layer
