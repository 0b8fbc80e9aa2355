#pragma once
// Binding a live device to a plan: which physical component is which plan
// module. The device reports its topology (thesis App. A.1: every component
// has a global id, knows its parent and the parent's outlet it is plugged
// into); the plan is a tree of modules. Both trees are walked together from
// the base: a plan module binds to the component plugged into the same outlet
// of the component bound to its parent, when the kinds agree (any joint for a
// joint; a splitter of the same kind's name for a splitter). All joints are
// alike, so two joints exchanged on the device bind wherever they sit.
//
// What does not match is reported, with what to do (problems), and the rest
// still binds: a missing module (and what hangs below it, named in the same
// message), a component of the wrong kind in a module's place, an extra
// component where the plan has nothing, two branches of a splitter plugged
// into each other's outlets, a component whose parent is not connected.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan {

struct ObservedModule {
  std::uint32_t id = 0;          // the component's global id; non-zero
  bool is_splitter = false;
  std::string kind;              // splitters: the kit kind's name ("Y2"); joints: ignored
  std::uint32_t parent_id = 0;   // 0: plugged into the base
  int parent_outlet = 0;         // outlet of the parent (0 on a joint or the base's only port)
};

struct BindingProblem {
  enum class Kind { missing, wrong_kind, extra, swapped_branches, disconnected };
  Kind kind = Kind::missing;
  int plan_module = -1;          // -1: about a component only
  std::uint32_t observed_id = 0; // 0: about a plan module only
  std::string message;           // says what to plug, unplug or swap
};

struct Binding {
  std::vector<int> observed_index;  // per plan module: index into the observed list, -1 unbound
  std::vector<std::uint32_t> observed_id;  // per plan module: the component's id, 0 unbound
  std::vector<BindingProblem> problems;
  int bound_count() const;
  bool complete() const { return problems.empty() && bound_count() == static_cast<int>(observed_index.size()); }
  // Every problem's message, one per line.
  std::string describe() const;
  // Per-component readings (index as in the observed list given to
  // bind_device) into per-module readings for Retargeter::retarget: unbound
  // modules get std::nullopt. per_module must hold one entry per plan module;
  // no allocation (per frame).
  void plan_readings(std::span<const std::optional<Quat>> observed_readings,
                     std::span<std::optional<Quat>> per_module) const;
};

inline constexpr std::size_t kMaxObservedModules = 4096;

// Errors only for a malformed observation (an id of 0, an id listed twice,
// more than kMaxObservedModules components); a device that differs from the
// plan is a Binding with problems. The plan must validate (validate_plan).
Result<Binding> bind_device(const Plan& plan, std::span<const ObservedModule> observed);

}  // namespace proprio::rig_plan
