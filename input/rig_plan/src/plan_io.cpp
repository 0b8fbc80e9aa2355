#include "proprio/rig_plan/plan_io.hpp"

#include <cmath>
#include <map>
#include <set>
#include <utility>

#include <nlohmann/json.hpp>

#include "proprio/core/file_io.hpp"

namespace proprio::rig_plan {

namespace plan_io_detail {
namespace {

using nlohmann::json;

constexpr double kUnitTolerance = 1e-6;
// The format nests at most 4 deep (device_poses); refuse deep nesting before
// nlohmann's parser sees it, so hostile text cannot build a deep tree.
constexpr int kMaxDepth = 16;
constexpr std::size_t kMaxNameChars = 256;

bool unit_quat(const Quat& q) { return q.coeffs().allFinite() && std::abs(q.norm() - 1.0) <= kUnitTolerance; }

// Bracket depth outside strings; -1 when above the limit.
bool nesting_within(std::string_view text, int limit) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (char c : text) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') in_string = true;
    else if (c == '[' || c == '{') {
      if (++depth > limit) return false;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return true;
}

json quat_json(const Quat& q) { return json::array({q.w(), q.x(), q.y(), q.z()}); }

// Thrown inside the parser only (caught in parse_plan_json): a field that is
// missing or of the wrong type, with its path.
struct FieldError {
  std::string message;
};

const json& field(const json& object, const char* key, const std::string& path) {
  if (!object.is_object()) throw FieldError{path + " must be an object"};
  auto it = object.find(key);
  if (it == object.end()) throw FieldError{path + "." + key + " is missing"};
  return *it;
}

double number(const json& value, const std::string& path) {
  if (!value.is_number()) throw FieldError{path + " must be a number"};
  const double v = value.get<double>();
  if (!std::isfinite(v)) throw FieldError{path + " must be finite"};
  return v;
}

int integer(const json& value, const std::string& path, long long lo, long long hi) {
  if (!value.is_number_integer()) throw FieldError{path + " must be an integer"};
  const long long v = value.is_number_unsigned() ? static_cast<long long>(std::min<std::uint64_t>(
                                                       value.get<std::uint64_t>(), std::uint64_t{1} << 62))
                                                 : value.get<long long>();
  if (v < lo || v > hi)
    throw FieldError{path + " is " + std::to_string(v) + "; it must lie in [" + std::to_string(lo) + ", " +
                     std::to_string(hi) + "]"};
  return static_cast<int>(v);
}

std::string text(const json& value, const std::string& path) {
  if (!value.is_string()) throw FieldError{path + " must be a string"};
  std::string s = value.get<std::string>();
  if (s.size() > kMaxNameChars) throw FieldError{path + " is longer than " + std::to_string(kMaxNameChars) + " characters"};
  return s;
}

const json& array(const json& value, const std::string& path, std::size_t max_size) {
  if (!value.is_array()) throw FieldError{path + " must be an array"};
  if (value.size() > max_size)
    throw FieldError{path + " has " + std::to_string(value.size()) + " entries; at most " + std::to_string(max_size)};
  return value;
}

Quat quat(const json& value, const std::string& path) {
  const json& a = array(value, path, 4);
  if (a.size() != 4) throw FieldError{path + " must be [w, x, y, z]"};
  Quat q(number(a[0], path + "[0]"), number(a[1], path + "[1]"), number(a[2], path + "[2]"), number(a[3], path + "[3]"));
  if (!unit_quat(q)) throw FieldError{path + " is not a unit quaternion"};
  return q;
}

rig_device::Kit kit_from(const json& j, const std::string& path) {
  rig_device::Kit kit;
  const json& joint = field(j, "joint", path);
  const std::string jp = path + ".joint";
  kit.joint.name = text(field(joint, "name", jp), jp + ".name");
  kit.joint_count = integer(field(joint, "count", jp), jp + ".count", 0, 1 << 20);
  kit.joint.length_in_m = number(field(joint, "length_in_m", jp), jp + ".length_in_m");
  kit.joint.length_out_m = number(field(joint, "length_out_m", jp), jp + ".length_out_m");
  kit.joint.bend_limit_rad = number(field(joint, "bend_limit_rad", jp), jp + ".bend_limit_rad");
  kit.joint.twist_rings = integer(field(joint, "twist_rings", jp), jp + ".twist_rings", 0, 16);
  const json& splitters = array(field(j, "splitters", path), path + ".splitters", 256);
  for (std::size_t i = 0; i < splitters.size(); ++i) {
    const std::string sp = path + ".splitters[" + std::to_string(i) + "]";
    rig_device::SplitterKind kind;
    kind.name = text(field(splitters[i], "name", sp), sp + ".name");
    kind.arm_length_m = number(field(splitters[i], "arm_length_m", sp), sp + ".arm_length_m");
    const json& outlets = array(field(splitters[i], "outlets", sp), sp + ".outlets", 64);
    for (std::size_t o = 0; o < outlets.size(); ++o)
      kind.q_inlet_outlet.push_back(quat(outlets[o], sp + ".outlets[" + std::to_string(o) + "]"));
    kit.splitter_kinds.push_back(std::move(kind));
    kit.splitter_counts.push_back(integer(field(splitters[i], "count", sp), sp + ".count", 0, 1 << 20));
  }
  return kit;
}

json kit_json(const rig_device::Kit& kit) {
  json splitters = json::array();
  for (std::size_t i = 0; i < kit.splitter_kinds.size(); ++i) {
    const auto& k = kit.splitter_kinds[i];
    json outlets = json::array();
    for (const Quat& q : k.q_inlet_outlet) outlets.push_back(quat_json(q));
    splitters.push_back({{"name", k.name},
                         {"count", i < kit.splitter_counts.size() ? kit.splitter_counts[i] : 0},
                         {"arm_length_m", k.arm_length_m},
                         {"outlets", std::move(outlets)}});
  }
  return {{"joint",
           {{"name", kit.joint.name},
            {"count", kit.joint_count},
            {"length_in_m", kit.joint.length_in_m},
            {"length_out_m", kit.joint.length_out_m},
            {"bend_limit_rad", kit.joint.bend_limit_rad},
            {"twist_rings", kit.joint.twist_rings}}},
          {"splitters", std::move(splitters)}};
}

Plan plan_from(const json& j, std::size_t skeleton_nodes) {
  if (!j.is_object()) throw FieldError{"the plan must be a JSON object"};
  const std::string format = text(field(j, "format", "plan"), "plan.format");
  if (format != kPlanFormatName)
    throw FieldError{"plan.format is '" + printable(format, 60) + "', not '" + kPlanFormatName +
                     "': this is not a rig device plan"};
  const int version = integer(field(j, "version", "plan"), "plan.version", 0, 1 << 20);
  if (version != kPlanFormatVersion)
    throw FieldError{"plan.version is " + std::to_string(version) + "; this build reads version " +
                     std::to_string(kPlanFormatVersion) + " (recompute the plan or update Proprio)"};
  Plan plan;
  plan.character = text(field(j, "character", "plan"), "plan.character");
  plan.kit = kit_from(field(j, "kit", "plan"), "plan.kit");
  const long long node_max = static_cast<long long>(skeleton_nodes) - 1;
  const json& modules = array(field(j, "modules", "plan"), "plan.modules", kMaxPlanModules);
  for (std::size_t i = 0; i < modules.size(); ++i) {
    const std::string mp = "plan.modules[" + std::to_string(i) + "]";
    const json& m = modules[i];
    DeviceModule module;
    const std::string type = text(field(m, "type", mp), mp + ".type");
    if (type == "joint") module.type = DeviceModule::Type::joint;
    else if (type == "splitter") module.type = DeviceModule::Type::splitter;
    else throw FieldError{mp + ".type is '" + printable(type, 40) + "'; it must be \"joint\" or \"splitter\""};
    module.kind = text(field(m, "kind", mp), mp + ".kind");
    module.rig_node = integer(field(m, "rig_node", mp), mp + ".rig_node", -1, node_max);
    module.parent_module = integer(field(m, "parent_module", mp), mp + ".parent_module", -1,
                                   static_cast<long long>(kMaxPlanModules));
    module.parent_outlet = integer(field(m, "parent_outlet", mp), mp + ".parent_outlet", 0, 64);
    module.q_parent_inlet = quat(field(m, "q_parent_inlet", mp), mp + ".q_parent_inlet");
    module.q_in_out_rest = quat(field(m, "q_in_out_rest", mp), mp + ".q_in_out_rest");
    const json& outlets = array(field(m, "outlet_rig_child", mp), mp + ".outlet_rig_child", 64);
    for (std::size_t o = 0; o < outlets.size(); ++o)
      module.outlet_rig_child.push_back(
          integer(outlets[o], mp + ".outlet_rig_child[" + std::to_string(o) + "]", -1, node_max));
    module.angular_error_rad = number(field(m, "angular_error_rad", mp), mp + ".angular_error_rad");
    plan.modules.push_back(std::move(module));
  }
  plan.error_rigid = number(field(j, "error_rigid", "plan"), "plan.error_rigid");
  const json& curve = array(field(j, "error_after_joint", "plan"), "plan.error_after_joint", kMaxPlanModules);
  for (std::size_t i = 0; i < curve.size(); ++i)
    plan.error_after_joint.push_back(number(curve[i], "plan.error_after_joint[" + std::to_string(i) + "]"));
  plan.error_final = number(field(j, "error_final", "plan"), "plan.error_final");
  const json& poses = array(field(j, "device_poses", "plan"), "plan.device_poses", kMaxPlanSamples);
  // Bounded in total too: samples x modules rotations.
  if (poses.size() * std::max<std::size_t>(plan.modules.size(), 1) > 4u * 1024u * 1024u)
    throw FieldError{"plan.device_poses holds more rotations than a plan can (samples x modules above 4M)"};
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const std::string pp = "plan.device_poses[" + std::to_string(i) + "]";
    const json& pose = array(poses[i], pp, kMaxPlanModules);
    std::vector<Quat> qs;
    qs.reserve(pose.size());
    for (std::size_t m = 0; m < pose.size(); ++m) qs.push_back(quat(pose[m], pp + "[" + std::to_string(m) + "]"));
    plan.device_poses.push_back(std::move(qs));
  }
  return plan;
}

}  // namespace
}  // namespace plan_io_detail

std::string module_label(const Plan& plan, int module) {
  if (module < 0 || static_cast<std::size_t>(module) >= plan.modules.size()) return "the base";
  const DeviceModule& m = plan.modules[static_cast<std::size_t>(module)];
  const std::string what = m.type == DeviceModule::Type::joint ? std::string("joint") : "splitter " + m.kind;
  return "module " + std::to_string(module + 1) + " (" + what + ")";
}

Status validate_plan(const Plan& plan, std::size_t skeleton_nodes) {
  using plan_io_detail::unit_quat;
  if (Status s = plan.kit.validate(); !s) return s.error().with_context("the plan's kit");
  if (plan.modules.size() > kMaxPlanModules)
    return make_error(Errc::invalid_argument, "the plan has " + std::to_string(plan.modules.size()) +
                                                  " modules; at most " + std::to_string(kMaxPlanModules));
  const int nodes = static_cast<int>(std::min<std::size_t>(skeleton_nodes, kMaxSkeletonNodes));
  std::set<std::pair<int, int>> used_outlets;
  std::set<int> driven;
  int joints = 0;
  std::vector<int> per_kind(plan.kit.splitter_kinds.size(), 0);
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    const std::string who = module_label(plan, static_cast<int>(i));
    if (m.parent_module < -1 || m.parent_module >= static_cast<int>(i))
      return make_error(Errc::invalid_argument, who + ": its parent module " + std::to_string(m.parent_module + 1) +
                                                    " does not come before it (plans list parents first)");
    if (m.parent_module >= 0) {
      const DeviceModule& p = plan.modules[static_cast<std::size_t>(m.parent_module)];
      const int outlets = p.type == DeviceModule::Type::joint ? 1 : static_cast<int>(p.outlet_rig_child.size());
      if (m.parent_outlet < 0 || m.parent_outlet >= outlets)
        return make_error(Errc::invalid_argument, who + " hangs off outlet " + std::to_string(m.parent_outlet) + " of " +
                                                      module_label(plan, m.parent_module) + ", which has " +
                                                      std::to_string(outlets) + " outlet(s)");
    } else if (m.parent_outlet < 0) {
      return make_error(Errc::invalid_argument, who + ": a negative base outlet");
    }
    if (!used_outlets.insert({m.parent_module, m.parent_outlet}).second)
      return make_error(Errc::invalid_argument, who + " shares outlet " + std::to_string(m.parent_outlet) + " of " +
                                                    module_label(plan, m.parent_module) + " with another module");
    if (!unit_quat(m.q_parent_inlet) || !unit_quat(m.q_in_out_rest))
      return make_error(Errc::invalid_argument, who + ": its rotations must be finite unit quaternions");
    if (!std::isfinite(m.angular_error_rad) || m.angular_error_rad < 0.0)
      return make_error(Errc::invalid_argument, who + ": angular_error_rad must be finite and >= 0");
    if (m.rig_node < 0 || m.rig_node >= nodes)
      return make_error(Errc::invalid_argument, who + " sits on rig node " + std::to_string(m.rig_node) +
                                                    "; the rig has nodes 0.." + std::to_string(nodes - 1) +
                                                    " (is this plan for another character?)");
    if (m.type == DeviceModule::Type::joint) {
      ++joints;
      if (m.kind != "joint" && m.kind != plan.kit.joint.name)
        return make_error(Errc::invalid_argument, who + " is of kind '" + printable(m.kind, 60) +
                                                      "'; the kit's joint is '" + plan.kit.joint.name + "'");
      if (!m.outlet_rig_child.empty())
        return make_error(Errc::invalid_argument, who + ": a joint has no splitter outlets");
      if (!driven.insert(m.rig_node).second)
        return make_error(Errc::invalid_argument,
                          who + " drives rig node " + std::to_string(m.rig_node) + ", which another joint drives");
    } else {
      std::size_t kind = plan.kit.splitter_kinds.size();
      for (std::size_t k = 0; k < plan.kit.splitter_kinds.size(); ++k)
        if (plan.kit.splitter_kinds[k].name == m.kind) kind = k;
      if (kind == plan.kit.splitter_kinds.size())
        return make_error(Errc::invalid_argument,
                          who + ": the kit has no splitter kind '" + printable(m.kind, 60) + "'");
      ++per_kind[kind];
      if (m.outlet_rig_child.size() != plan.kit.splitter_kinds[kind].valence())
        return make_error(Errc::invalid_argument, who + " lists " + std::to_string(m.outlet_rig_child.size()) +
                                                      " outlet branches; a " + m.kind + " has " +
                                                      std::to_string(plan.kit.splitter_kinds[kind].valence()));
      for (int c : m.outlet_rig_child)
        if (c < -1 || c >= nodes)
          return make_error(Errc::invalid_argument, who + ": an outlet follows rig node " + std::to_string(c) +
                                                        ", which the rig does not have");
    }
  }
  if (joints > plan.kit.joint_count)
    return make_error(Errc::invalid_argument, "the plan uses " + std::to_string(joints) + " joints; the kit has " +
                                                  std::to_string(plan.kit.joint_count));
  for (std::size_t k = 0; k < per_kind.size(); ++k)
    if (per_kind[k] > plan.kit.splitter_counts[k])
      return make_error(Errc::invalid_argument, "the plan uses " + std::to_string(per_kind[k]) + " " +
                                                    plan.kit.splitter_kinds[k].name + " splitters; the kit has " +
                                                    std::to_string(plan.kit.splitter_counts[k]));
  const auto bad = [](double v) { return !std::isfinite(v) || v < 0.0; };
  if (bad(plan.error_rigid) || bad(plan.error_final))
    return make_error(Errc::invalid_argument, "the plan's pose errors must be finite and >= 0");
  for (double e : plan.error_after_joint)
    if (bad(e)) return make_error(Errc::invalid_argument, "the plan's error curve holds a negative or non-finite value");
  if (plan.device_poses.size() > kMaxPlanSamples)
    return make_error(Errc::invalid_argument, "the plan has more than " + std::to_string(kMaxPlanSamples) +
                                                  " device poses");
  for (std::size_t i = 0; i < plan.device_poses.size(); ++i) {
    if (plan.device_poses[i].size() != plan.modules.size())
      return make_error(Errc::invalid_argument, "device pose " + std::to_string(i) + " has " +
                                                    std::to_string(plan.device_poses[i].size()) +
                                                    " rotations for " + std::to_string(plan.modules.size()) +
                                                    " modules");
    for (const Quat& q : plan.device_poses[i])
      if (!unit_quat(q))
        return make_error(Errc::invalid_argument,
                          "device pose " + std::to_string(i) + " holds a rotation that is not a unit quaternion");
  }
  return {};
}

std::string plan_to_json(const Plan& plan) {
  using nlohmann::json;
  using plan_io_detail::kit_json;
  using plan_io_detail::quat_json;
  json modules = json::array();
  for (const DeviceModule& m : plan.modules) {
    modules.push_back({{"type", m.type == DeviceModule::Type::joint ? "joint" : "splitter"},
                       {"kind", m.kind},
                       {"rig_node", m.rig_node},
                       {"parent_module", m.parent_module},
                       {"parent_outlet", m.parent_outlet},
                       {"q_parent_inlet", quat_json(m.q_parent_inlet)},
                       {"q_in_out_rest", quat_json(m.q_in_out_rest)},
                       {"outlet_rig_child", m.outlet_rig_child},
                       {"angular_error_rad", m.angular_error_rad}});
  }
  json poses = json::array();
  for (const auto& pose : plan.device_poses) {
    json p = json::array();
    for (const Quat& q : pose) p.push_back(quat_json(q));
    poses.push_back(std::move(p));
  }
  json j = {{"format", kPlanFormatName},
            {"version", kPlanFormatVersion},
            {"character", plan.character},
            {"kit", kit_json(plan.kit)},
            {"modules", std::move(modules)},
            {"error_rigid", plan.error_rigid},
            {"error_after_joint", plan.error_after_joint},
            {"error_final", plan.error_final},
            {"device_poses", std::move(poses)}};
  // Replace: names are UTF-8 from files; a stray byte must not make saving throw.
  return j.dump(1, ' ', false, json::error_handler_t::replace) + "\n";
}

Result<Plan> parse_plan_json(std::string_view text, std::size_t skeleton_nodes, const std::string& origin) {
  using nlohmann::json;
  using plan_io_detail::FieldError;
  using plan_io_detail::kMaxDepth;
  using plan_io_detail::nesting_within;
  using plan_io_detail::plan_from;
  const std::string where = printable(origin, 200);
  if (text.size() > kMaxPlanFileBytes)
    return make_error(Errc::invalid_argument, where + ": " + std::to_string(text.size()) +
                                                  " bytes; a plan is at most " + std::to_string(kMaxPlanFileBytes));
  if (skeleton_nodes == 0 || skeleton_nodes > kMaxSkeletonNodes)
    return make_error(Errc::invalid_argument, where + ": the rig to check the plan against has " +
                                                  std::to_string(skeleton_nodes) + " nodes");
  if (!nesting_within(text, kMaxDepth))
    return make_error(Errc::parse_error, where + ": the JSON nests deeper than a plan does (" +
                                             std::to_string(kMaxDepth) + " levels)");
  Plan plan;
  try {
    const json j = json::parse(text.begin(), text.end());
    plan = plan_from(j, skeleton_nodes);
  } catch (const FieldError& e) {
    return make_error(Errc::parse_error, where + ": " + e.message);
  } catch (const json::exception& e) {
    return make_error(Errc::parse_error, where + ": not valid JSON (" + printable(e.what(), 200) + ")");
  } catch (const std::exception& e) {
    return make_error(Errc::parse_error, where + ": " + printable(e.what(), 200));
  }
  if (Status s = validate_plan(plan, skeleton_nodes); !s) return s.error().with_context(where);
  return plan;
}

Status save_plan(const std::filesystem::path& file, const Plan& plan, std::size_t skeleton_nodes) {
  if (Status s = validate_plan(plan, skeleton_nodes); !s) return s.error().with_context("not saving the plan");
  std::string text;
  try {
    text = plan_to_json(plan);
  } catch (const std::exception& e) {
    return make_error(Errc::invalid_argument, "could not write the plan as JSON: " + printable(e.what(), 200));
  }
  return write_file_atomic(file, text, "device plan");
}

Result<Plan> load_plan(const std::filesystem::path& file, std::size_t skeleton_nodes) {
  auto text = read_input_file(file, "device plan", kMaxPlanFileBytes);
  if (!text) return text.error();
  return parse_plan_json(*text, skeleton_nodes, file.string());
}

}  // namespace proprio::rig_plan
