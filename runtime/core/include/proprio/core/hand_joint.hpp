#pragma once
// The 26 hand joints of XR_EXT_hand_tracking, in XrHandJointEXT order, so a
// joint's index is its OpenXR enum value.
#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

namespace proprio {

inline constexpr std::size_t kHandJointCount = 26;

enum class HandJoint : std::uint8_t {
  palm = 0,
  wrist,
  thumb_metacarpal,
  thumb_proximal,
  thumb_distal,
  thumb_tip,
  index_metacarpal,
  index_proximal,
  index_intermediate,
  index_distal,
  index_tip,
  middle_metacarpal,
  middle_proximal,
  middle_intermediate,
  middle_distal,
  middle_tip,
  ring_metacarpal,
  ring_proximal,
  ring_intermediate,
  ring_distal,
  ring_tip,
  little_metacarpal,
  little_proximal,
  little_intermediate,
  little_distal,
  little_tip,
};

enum class Handedness : std::uint8_t { left = 0, right = 1 };

enum class Finger : std::uint8_t { thumb = 0, index, middle, ring, little };
inline constexpr std::size_t kFingerCount = 5;

constexpr std::size_t index_of(HandJoint j) noexcept { return static_cast<std::size_t>(j); }
constexpr HandJoint joint_at(std::size_t i) noexcept { return static_cast<HandJoint>(i); }

// Joints of a finger from base to tip. The thumb has no intermediate joint, so
// its list has 4 entries and the 5th is unused (count says how many are valid).
struct FingerJoints {
  std::array<HandJoint, 5> joints;
  std::size_t count;
};
constexpr FingerJoints finger_joints(Finger f) noexcept {
  if (f == Finger::thumb) {
    return {{HandJoint::thumb_metacarpal, HandJoint::thumb_proximal, HandJoint::thumb_distal,
             HandJoint::thumb_tip, HandJoint::thumb_tip},
            4};
  }
  const auto base = static_cast<std::uint8_t>(6 + 5 * (static_cast<int>(f) - 1));
  return {{static_cast<HandJoint>(base), static_cast<HandJoint>(base + 1), static_cast<HandJoint>(base + 2),
           static_cast<HandJoint>(base + 3), static_cast<HandJoint>(base + 4)},
          5};
}

constexpr HandJoint tip_of(Finger f) noexcept {
  const auto fj = finger_joints(f);
  return fj.joints[fj.count - 1];
}

// Skeleton parent (toward the wrist). The wrist and palm have none.
std::optional<HandJoint> parent_of(HandJoint j) noexcept;

// "index_proximal", matching the XR_HAND_JOINT_*_EXT names in lower case.
std::string_view to_string(HandJoint j) noexcept;
std::string_view to_string(Handedness h) noexcept;
std::optional<Handedness> parse_handedness(std::string_view s) noexcept;
// "thumb", "index", "middle", "ring", "little".
std::string_view to_string(Finger f) noexcept;
std::optional<Finger> parse_finger(std::string_view s) noexcept;

}  // namespace proprio
