#pragma once
// The modules an animator assembles a device from, as data (thesis ch. 3.2.1):
// one joint kind (a Cardan joint between two twist rings, with a shaft on each
// side) and splitter kinds (one inlet, several outlets at fixed rotations).
// A kit says how many of each the animator owns; the thesis's has 18 joints
// and 7 splitters. Kits are TOML (config/rig_device/*.toml); see
// docs/rig-device.md for the format.
#include <cstdint>
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

// The thesis's kit: 18 joints and 7 splitters. The thesis gives no splitter
// geometry beyond "the same splitter geometries as [Jacobson et al. 2014b]",
// whose kit branches a skeleton at hips, shoulders, chest and tails/forks; its
// photos show two-outlet forks and tees and three-outlet tees. Our reading:
//   2 x "Y2": a fork, outlets 30 deg off the inlet axis on either side (tails,
//             antennae, a finger pair);
//   2 x "T2": a tee, outlets at +-90 deg (hips, shoulders: a limb pair across
//             the spine's end);
//   2 x "T3": a tee with a straight-through outlet (chest: neck ahead, arms
//             out at +-90 deg; pelvis: tail ahead, legs);
//   1 x "Y3": a tripod fork, outlets 45 deg off axis, 120 deg apart around it
//             (a many-branch creature's hub, a hand's fingers).
// Joints: 30 mm shafts each side of the Cardan centre; stops at 70 deg per
// hinge and between the shafts (JointKind's 1.4 rad default is looser): the
// Hall sensing of hall_joint.hpp reaches the thesis's accuracy only there.
// config/rig_device/thesis_kit.toml holds the same kit as a file.
Kit default_kit();

// Outlets in TOML are angles a person can read off a drawing: the outlet's
// shaft direction in the inlet frame in spherical angles (tilt from the inlet's
// +z shaft axis, azimuth about it from +x toward +y), then a roll about the
// outlet's own shaft:
//   q_inlet_outlet = Rz(azimuth) * Ry(tilt) * Rz(roll)
// so the outlet shaft points along (sin t cos a, sin t sin a, cos t). At tilt 0
// azimuth and roll turn about the same axis; outlet_angles_for puts it all in
// roll.
struct OutletAngles {
  double azimuth_deg = 0.0;
  double tilt_deg = 0.0;
  double roll_deg = 0.0;
};
Quat outlet_rotation(const OutletAngles& angles);
OutletAngles outlet_angles_for(const Quat& q_inlet_outlet);

// Bounded TOML parsing (origin names the text in messages); load_kit reads a
// file through core's checked file input (FIFOs, /dev/zero and files over
// kMaxKitFileBytes are refused). The format (every key optional but
// [[splitter]]'s name and its outlets):
//   [joint]
//   name = "joint"        count = 18          twist_rings = 2
//   length_in_m = 0.03    length_out_m = 0.03 bend_limit_deg = 70
//   [[splitter]]
//   name = "T2"   count = 2   arm_length_m = 0.02
//   [[splitter.outlet]]
//   azimuth_deg = 0   tilt_deg = 90   roll_deg = 0
// Unknown keys, non-finite numbers, counts above 256, more than 64 splitter
// kinds or 8 outlets are refused with a message naming the key and line.
inline constexpr std::uint64_t kMaxKitFileBytes = 1024 * 1024;
inline constexpr int kMaxSplitterKinds = 64;
Result<Kit> parse_kit_toml(std::string_view text, const std::string& origin);
Result<Kit> load_kit(const std::filesystem::path& file);
std::string kit_to_toml(const Kit& kit);

}  // namespace proprio::rig_device
