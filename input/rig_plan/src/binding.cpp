#include "proprio/rig_plan/binding.hpp"

#include <cstdio>
#include <functional>
#include <map>
#include <unordered_map>
#include <utility>

#include "proprio/core/file_io.hpp"
#include "proprio/rig_plan/plan_io.hpp"

namespace proprio::rig_plan {

namespace binding_detail {
namespace {

std::string hex_id(std::uint32_t id) {
  char buffer[16];
  std::snprintf(buffer, sizeof buffer, "0x%08x", static_cast<unsigned>(id));
  return buffer;
}

std::string component(const ObservedModule& o) {
  return (o.is_splitter ? "a " + printable(o.kind, 40) + " splitter" : std::string("a joint")) + " (id " +
         hex_id(o.id) + ")";
}

std::string plan_piece(const DeviceModule& m) {
  return m.type == DeviceModule::Type::joint ? std::string("a joint") : "a " + m.kind + " splitter";
}

// Where a module plugs in, in the plan's words.
std::string place(const Plan& plan, int parent, int outlet) {
  if (parent < 0) return outlet == 0 ? std::string("the base") : "port " + std::to_string(outlet) + " of the base";
  const DeviceModule& p = plan.modules[static_cast<std::size_t>(parent)];
  if (p.type == DeviceModule::Type::joint) return "the outlet of " + module_label(plan, parent);
  return "outlet " + std::to_string(outlet) + " of " + module_label(plan, parent);
}

}  // namespace
}  // namespace binding_detail

int Binding::bound_count() const {
  int n = 0;
  for (int i : observed_index) n += i >= 0 ? 1 : 0;
  return n;
}

std::string Binding::describe() const {
  std::string out;
  for (const BindingProblem& p : problems) out += p.message + "\n";
  return out;
}

void Binding::plan_readings(std::span<const std::optional<Quat>> observed_readings,
                            std::span<std::optional<Quat>> per_module) const {
  for (std::size_t i = 0; i < per_module.size(); ++i) {
    const int index = i < observed_index.size() ? observed_index[i] : -1;
    per_module[i] = index >= 0 && static_cast<std::size_t>(index) < observed_readings.size()
                        ? observed_readings[static_cast<std::size_t>(index)]
                        : std::nullopt;
  }
}

Result<Binding> bind_device(const Plan& plan, std::span<const ObservedModule> observed) {
  using binding_detail::component;
  using binding_detail::hex_id;
  using binding_detail::place;
  using binding_detail::plan_piece;
  if (Status s = validate_plan(plan, kMaxSkeletonNodes); !s) return s.error().with_context("binding a device");
  if (observed.size() > kMaxObservedModules)
    return make_error(Errc::invalid_argument, "the device reports " + std::to_string(observed.size()) +
                                                  " components; at most " + std::to_string(kMaxObservedModules));
  std::unordered_map<std::uint32_t, int> by_id;
  for (std::size_t i = 0; i < observed.size(); ++i) {
    if (observed[i].id == 0)
      return make_error(Errc::invalid_argument, "component " + std::to_string(i) + " of the device reports id 0");
    if (!by_id.emplace(observed[i].id, static_cast<int>(i)).second)
      return make_error(Errc::invalid_argument, "two components of the device report id " + hex_id(observed[i].id));
  }
  // A joint has one outlet whatever number its child reports.
  const auto outlet_of = [&](const ObservedModule& o) {
    if (o.parent_id == 0) return o.parent_outlet;
    auto it = by_id.find(o.parent_id);
    return it != by_id.end() && !observed[static_cast<std::size_t>(it->second)].is_splitter ? 0 : o.parent_outlet;
  };
  std::map<std::pair<std::uint32_t, int>, std::vector<int>> observed_at;
  for (std::size_t i = 0; i < observed.size(); ++i)
    if (observed[i].parent_id != observed[i].id)
      observed_at[{observed[i].parent_id, outlet_of(observed[i])}].push_back(static_cast<int>(i));
  const std::size_t n = plan.modules.size();
  std::map<std::pair<int, int>, int> plan_at;
  std::vector<int> subtree(n, 1);
  for (std::size_t i = n; i-- > 0;) {
    const DeviceModule& m = plan.modules[i];
    plan_at[{m.parent_module, m.parent_outlet}] = static_cast<int>(i);
    if (m.parent_module >= 0) subtree[static_cast<std::size_t>(m.parent_module)] += subtree[i];
  }

  Binding binding;
  binding.observed_index.assign(n, -1);
  binding.observed_id.assign(n, 0);
  std::vector<char> consumed(observed.size(), 0);  // bound, or reported in a module's place
  const auto compatible = [&](const DeviceModule& m, const ObservedModule& o) {
    return m.type == DeviceModule::Type::joint ? !o.is_splitter : (o.is_splitter && o.kind == m.kind);
  };

  // Two branches of a bound splitter plugged into each other's outlets: the
  // shapes (kinds, depth first) of the plan's and the device's branches.
  std::function<std::string(int)> plan_shape = [&](int module) -> std::string {
    if (module < 0) return "-";
    const DeviceModule& m = plan.modules[static_cast<std::size_t>(module)];
    std::string s = m.type == DeviceModule::Type::joint ? "J(" : "S" + m.kind + "(";
    const int outlets = m.type == DeviceModule::Type::joint ? 1 : static_cast<int>(m.outlet_rig_child.size());
    for (int o = 0; o < outlets; ++o) {
      auto it = plan_at.find({module, o});
      s += plan_shape(it == plan_at.end() ? -1 : it->second) + ",";
    }
    return s + ")";
  };
  std::function<std::string(int, int)> observed_shape = [&](int index, int depth) -> std::string {
    if (index < 0) return "-";
    if (depth > static_cast<int>(observed.size())) return "?";
    const ObservedModule& o = observed[static_cast<std::size_t>(index)];
    std::string s = o.is_splitter ? "S" + o.kind + "(" : "J(";
    int outlets = 1;
    if (o.is_splitter)
      for (const auto& [key, list] : observed_at)
        if (key.first == o.id) outlets = std::max(outlets, key.second + 1);
    if (o.is_splitter)
      for (std::size_t k = 0; k < plan.kit.splitter_kinds.size(); ++k)
        if (plan.kit.splitter_kinds[k].name == o.kind)
          outlets = std::max(outlets, static_cast<int>(plan.kit.splitter_kinds[k].valence()));
    for (int out = 0; out < outlets && out < 64; ++out) {
      auto it = observed_at.find({o.id, out});
      s += observed_shape(it == observed_at.end() ? -1 : it->second.front(), depth + 1) + ",";
    }
    return s + ")";
  };

  for (std::size_t i = 0; i < n; ++i) {
    const DeviceModule& m = plan.modules[i];
    std::uint32_t parent_id = 0;
    if (m.parent_module >= 0) {
      const int parent_index = binding.observed_index[static_cast<std::size_t>(m.parent_module)];
      if (parent_index < 0) continue;  // told with its ancestor's problem
      parent_id = observed[static_cast<std::size_t>(parent_index)].id;
    }
    const std::string where = place(plan, m.parent_module, m.parent_outlet);
    const std::string below =
        subtree[i] > 1 ? " (and the " + std::to_string(subtree[i] - 1) + " module(s) below it)" : std::string();
    int candidate = -1;
    if (auto it = observed_at.find({parent_id, m.parent_outlet}); it != observed_at.end())
      for (int c : it->second)
        if (!consumed[static_cast<std::size_t>(c)]) {
          candidate = c;
          break;
        }
    if (candidate < 0) {
      binding.problems.push_back({BindingProblem::Kind::missing, static_cast<int>(i), 0,
                                  "plan " + module_label(plan, static_cast<int>(i)) + " on " + where +
                                      " is missing" + below + ": plug " + plan_piece(m) + " into " + where});
      continue;
    }
    const ObservedModule& o = observed[static_cast<std::size_t>(candidate)];
    consumed[static_cast<std::size_t>(candidate)] = 1;
    if (!compatible(m, o)) {
      binding.problems.push_back({BindingProblem::Kind::wrong_kind, static_cast<int>(i), o.id,
                                  component(o) + " is plugged into " + where + ", where the plan has " +
                                      module_label(plan, static_cast<int>(i)) + below + ": replace it with " +
                                      plan_piece(m)});
      continue;
    }
    binding.observed_index[i] = candidate;
    binding.observed_id[i] = o.id;
  }

  // Swapped branches: only a hint next to the missing/extra problems they cause.
  for (std::size_t i = 0; i < n; ++i) {
    const DeviceModule& m = plan.modules[i];
    if (m.type != DeviceModule::Type::splitter || binding.observed_index[i] < 0) continue;
    const std::uint32_t id = binding.observed_id[i];
    const int outlets = static_cast<int>(m.outlet_rig_child.size());
    std::vector<std::string> want(static_cast<std::size_t>(outlets)), have(static_cast<std::size_t>(outlets));
    for (int o = 0; o < outlets; ++o) {
      auto p = plan_at.find({static_cast<int>(i), o});
      want[static_cast<std::size_t>(o)] = plan_shape(p == plan_at.end() ? -1 : p->second);
      auto q = observed_at.find({id, o});
      have[static_cast<std::size_t>(o)] = observed_shape(q == observed_at.end() ? -1 : q->second.front(), 0);
    }
    for (int a = 0; a < outlets; ++a)
      for (int b = a + 1; b < outlets; ++b) {
        const auto ua = static_cast<std::size_t>(a), ub = static_cast<std::size_t>(b);
        if (want[ua] != have[ua] && want[ua] == have[ub] && want[ub] == have[ua])
          binding.problems.push_back(
              {BindingProblem::Kind::swapped_branches, static_cast<int>(i), id,
               "the branches on outlets " + std::to_string(a) + " and " + std::to_string(b) + " of " +
                   module_label(plan, static_cast<int>(i)) + " are plugged into each other's outlets: swap them"});
      }
  }

  // Components the plan has no place for: report the top of each such subtree.
  std::vector<char> bound(observed.size(), 0);
  for (int index : binding.observed_index)
    if (index >= 0) bound[static_cast<std::size_t>(index)] = 1;
  std::vector<std::uint32_t> in_loop;
  for (std::size_t i = 0; i < observed.size(); ++i) {
    if (bound[i] || consumed[i]) continue;
    const ObservedModule& o = observed[i];
    if (o.parent_id == 0 ||
        (by_id.count(o.parent_id) && bound[static_cast<std::size_t>(by_id.at(o.parent_id))])) {
      int plan_parent = -1;
      if (o.parent_id != 0)
        for (std::size_t k = 0; k < n; ++k)
          if (binding.observed_id[k] == o.parent_id) plan_parent = static_cast<int>(k);
      binding.problems.push_back({BindingProblem::Kind::extra, -1, o.id,
                                  component(o) + " is plugged into " + place(plan, plan_parent, outlet_of(o)) +
                                      ", where the plan has nothing: unplug it"});
      continue;
    }
    if (!by_id.count(o.parent_id)) {
      binding.problems.push_back({BindingProblem::Kind::disconnected, -1, o.id,
                                  component(o) + " reports parent " + hex_id(o.parent_id) +
                                      ", which the device does not list: check the plug above it"});
      continue;
    }
    // Parent listed but unbound: below a reported problem, or in a loop.
    std::size_t at = i;
    bool loops = false;
    for (std::size_t steps = 0; steps <= observed.size(); ++steps) {
      const ObservedModule& cur = observed[at];
      if (cur.parent_id == 0 || !by_id.count(cur.parent_id)) break;
      at = static_cast<std::size_t>(by_id.at(cur.parent_id));
      if (steps == observed.size()) loops = true;
    }
    if (loops) in_loop.push_back(o.id);
  }
  if (!in_loop.empty()) {
    std::string ids;
    for (std::size_t k = 0; k < in_loop.size() && k < 8; ++k) ids += (k ? ", " : "") + hex_id(in_loop[k]);
    binding.problems.push_back({BindingProblem::Kind::disconnected, -1, in_loop.front(),
                                "components " + ids + (in_loop.size() > 8 ? ", ..." : "") +
                                    " report parents in a loop, never reaching the base: unplug and replug them"});
  }
  return binding;
}

}  // namespace proprio::rig_plan
