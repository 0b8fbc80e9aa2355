#include "proprio/core/hand_joint.hpp"

namespace proprio {

namespace {
constexpr std::array<std::string_view, kHandJointCount> kNames = {
    "palm",
    "wrist",
    "thumb_metacarpal",
    "thumb_proximal",
    "thumb_distal",
    "thumb_tip",
    "index_metacarpal",
    "index_proximal",
    "index_intermediate",
    "index_distal",
    "index_tip",
    "middle_metacarpal",
    "middle_proximal",
    "middle_intermediate",
    "middle_distal",
    "middle_tip",
    "ring_metacarpal",
    "ring_proximal",
    "ring_intermediate",
    "ring_distal",
    "ring_tip",
    "little_metacarpal",
    "little_proximal",
    "little_intermediate",
    "little_distal",
    "little_tip",
};
}  // namespace

std::optional<HandJoint> parent_of(HandJoint j) noexcept {
  switch (j) {
    case HandJoint::palm:
    case HandJoint::wrist: return std::nullopt;
    case HandJoint::thumb_metacarpal:
    case HandJoint::index_metacarpal:
    case HandJoint::middle_metacarpal:
    case HandJoint::ring_metacarpal:
    case HandJoint::little_metacarpal: return HandJoint::wrist;
    default: return joint_at(index_of(j) - 1);
  }
}

std::string_view to_string(HandJoint j) noexcept {
  const auto i = index_of(j);
  return i < kNames.size() ? kNames[i] : std::string_view("invalid_joint");
}

std::string_view to_string(Handedness h) noexcept { return h == Handedness::left ? "left" : "right"; }

std::optional<Handedness> parse_handedness(std::string_view s) noexcept {
  if (s == "left") return Handedness::left;
  if (s == "right") return Handedness::right;
  return std::nullopt;
}

namespace {
constexpr std::string_view kFingerNames[kFingerCount] = {"thumb", "index", "middle", "ring", "little"};
}

std::string_view to_string(Finger f) noexcept {
  const auto i = static_cast<std::size_t>(f);
  return i < kFingerCount ? kFingerNames[i] : std::string_view("?");
}

std::optional<Finger> parse_finger(std::string_view s) noexcept {
  for (std::size_t i = 0; i < kFingerCount; ++i) {
    if (s == kFingerNames[i]) return static_cast<Finger>(i);
  }
  return std::nullopt;
}

}  // namespace proprio
