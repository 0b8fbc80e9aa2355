#pragma once
// Device plans as JSON files (nlohmann-json), so a plan computed once is
// assembled, bound and retargeted later. The format:
//   { "format": "proprio.rig_plan", "version": 1,
//     "character": "horse",
//     "kit": { "joint": { "name", "count", "length_in_m", "length_out_m",
//                         "bend_limit_rad", "twist_rings" },
//              "splitters": [ { "name", "count", "arm_length_m",
//                               "outlets": [[w, x, y, z], ...] } ] },
//     "modules": [ { "type": "joint" | "splitter", "kind", "rig_node",
//                    "parent_module", "parent_outlet",
//                    "q_parent_inlet": [w, x, y, z], "q_in_out_rest": [w, x, y, z],
//                    "outlet_rig_child": [...], "angular_error_rad" } ],
//     "error_rigid", "error_after_joint": [...], "error_final",
//     "device_poses": [ [[w, x, y, z] per module] per sample ] }
// Quaternions are Hamilton, [w, x, y, z]; doubles are written so they read
// back bit for bit.
//
// Loading is bounded (file size, nesting depth, counts) and validated
// (validate_plan) before a plan is returned; messages name the field.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "proprio/core/result.hpp"
#include "proprio/rig_plan/plan.hpp"

namespace proprio::rig_plan {

inline constexpr const char* kPlanFormatName = "proprio.rig_plan";
inline constexpr int kPlanFormatVersion = 1;
inline constexpr std::uint64_t kMaxPlanFileBytes = 16ull * 1024 * 1024;
// Far above a kit's 256-per-kind bound times a handful of kinds in practice.
inline constexpr std::size_t kMaxPlanModules = 4096;
inline constexpr std::size_t kMaxPlanSamples = 4096;

// A plan is usable with a rig of `skeleton_nodes` nodes when: the kit
// validates; modules are parents first (parent_module -1 or earlier); joints
// hang off outlet 0 of a joint or an existing outlet of a splitter, one module
// per outlet; joints drive distinct nodes in range; splitters name a kit kind
// with one outlet_rig_child entry (-1 or a node) per outlet and sit on a node
// in range; no more modules of a kind than the kit has; rotations are finite
// unit quaternions; errors finite and >= 0; device_poses empty or one
// rotation per module per sample. Messages name the module.
Status validate_plan(const Plan& plan, std::size_t skeleton_nodes);

std::string plan_to_json(const Plan& plan);
// origin names the text in messages (a file name).
Result<Plan> parse_plan_json(std::string_view text, std::size_t skeleton_nodes, const std::string& origin);

// Writes atomically (core's write_file_atomic) after validate_plan.
Status save_plan(const std::filesystem::path& file, const Plan& plan, std::size_t skeleton_nodes);
// Reads through core's checked file input (at most kMaxPlanFileBytes).
Result<Plan> load_plan(const std::filesystem::path& file, std::size_t skeleton_nodes);

// "module 3 (splitter T2)", "module 1 (joint)": modules are numbered from 1 in
// plan order, which is also the build order of the assembly instructions.
std::string module_label(const Plan& plan, int module);

}  // namespace proprio::rig_plan
