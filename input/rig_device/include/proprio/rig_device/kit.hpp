#pragma once
// The modules an animator assembles a device from, as data (thesis ch. 3.2.1):
// one joint kind (a Cardan joint between two twist rings, with a shaft on each
// side) and splitter kinds (one inlet, several outlets at fixed rotations).
// A kit says how many of each the animator owns; the thesis's has 18 joints
// and 7 splitters. Kits are TOML (config/rig_device/*.toml); see
// docs/rig-device.md for the format.
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/math.hpp"
#include "proprio/core/result.hpp"

namespace proprio::rig_device {

struct JointKind {
  std::string name = "joint";
  double length_in_m = 0.03;    // inlet face to the Cardan centre
  double length_out_m = 0.03;   // Cardan centre to the outlet face
  double bend_limit_rad = 1.4;  // per hinge, symmetric
  int twist_rings = 2;
};

struct SplitterKind {
  std::string name;                     // unique within a kit, e.g. "Y2"
  std::vector<Quat> q_inlet_outlet;     // one per outlet: inlet frame -> outlet frame (shaft along +z)
  double arm_length_m = 0.02;           // centre to each outlet face
  std::size_t valence() const { return q_inlet_outlet.size(); }
};

struct Kit {
  JointKind joint;
  int joint_count = 18;
  std::vector<SplitterKind> splitter_kinds;
  std::vector<int> splitter_counts;  // one per kind

  // Counts >= 0 and bounded (<= 256 each); positive finite lengths; bend
  // limit in (0, pi/2]; 1..2 twist rings; splitter names unique and
  // non-empty; 2..8 outlets each with unit rotations. Messages name the field.
  Status validate() const;
  std::string describe() const;  // one line per module kind with its count
  int total_splitters() const;
};

// The thesis's kit: 18 joints and 7 splitters (kinds and geometry chosen as
// documented in docs/rig-device.md; the thesis shows them only in photos).
Kit default_kit();

// Bounded TOML parsing (origin names the text in messages); load_kit reads a
// file through core's checked file input (FIFOs, /dev/zero and huge files are
// refused).
Result<Kit> parse_kit_toml(std::string_view text, const std::string& origin);
Result<Kit> load_kit(const std::filesystem::path& file);
std::string kit_to_toml(const Kit& kit);

}  // namespace proprio::rig_device
