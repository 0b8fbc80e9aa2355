#include "proprio/rig_plan/plan.hpp"

#include <cmath>
#include <string>
#include <unordered_set>

namespace proprio::rig_plan {

namespace plan_detail {
// Sample sets come from files: bound what a plan is asked to fit (the thesis's
// largest set has 25 poses).
constexpr std::size_t kMaxSamples = 4096;
}  // namespace plan_detail

Status RigInput::validate() const {
  const std::string who = name.empty() ? std::string("the character") : "character '" + name + "'";
  if (Status s = skeleton.validate(); !s) return s.error().with_context(who);
  if (samples.empty())
    return make_error(Errc::invalid_argument, who + " has no sample poses; planning needs at least one");
  if (samples.size() > plan_detail::kMaxSamples)
    return make_error(Errc::invalid_argument, who + " has " + std::to_string(samples.size()) +
                                                  " sample poses; at most " + std::to_string(plan_detail::kMaxSamples) +
                                                  " are supported");
  if (sample_names.size() != samples.size())
    return make_error(Errc::invalid_argument, who + " has " + std::to_string(samples.size()) + " sample poses but " +
                                                  std::to_string(sample_names.size()) + " sample names");
  std::unordered_set<std::string> seen;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (sample_names[i].empty())
      return make_error(Errc::invalid_argument, who + ": sample pose " + std::to_string(i) + " has no name");
    if (!seen.insert(sample_names[i]).second)
      return make_error(Errc::invalid_argument, who + ": two sample poses are named '" + sample_names[i] + "'");
    if (Status s = validate_pose(skeleton, samples[i]); !s)
      return s.error().with_context(who + ", sample pose '" + sample_names[i] + "'");
  }
  if (area_m2.size() != skeleton.size())
    return make_error(Errc::invalid_argument, who + " has " + std::to_string(area_m2.size()) +
                                                  " skin areas for " + std::to_string(skeleton.size()) + " nodes");
  for (std::size_t i = 0; i < area_m2.size(); ++i)
    if (!std::isfinite(area_m2[i]) || area_m2[i] < 0.0)
      return make_error(Errc::invalid_argument,
                        who + ": the skin area of node '" + skeleton.names[i] + "' is not a finite value >= 0");
  return {};
}

int Plan::joint_count() const {
  int n = 0;
  for (const DeviceModule& m : modules) n += m.type == DeviceModule::Type::joint ? 1 : 0;
  return n;
}

int Plan::splitter_count() const {
  int n = 0;
  for (const DeviceModule& m : modules) n += m.type == DeviceModule::Type::splitter ? 1 : 0;
  return n;
}

}  // namespace proprio::rig_plan
