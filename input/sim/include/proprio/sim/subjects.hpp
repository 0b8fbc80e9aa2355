#pragma once
// Simulated participants. The pool spans the hand sizes of the seeds' subject
// pools (Lee 2021, Fig. 4.7; Glauser 2019): hand length 17-20.5 cm (wrist to
// middle fingertip), width 9-11 cm (thumb MCP to the ulnar edge).
#include <cstddef>
#include <string>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"

namespace proprio::sim {

struct SimSubject {
  int id = 0;
  double hand_length_m = 0.19;
  double hand_width_m = 0.10;
  Handedness dominant_hand = Handedness::right;

  Result<HandShape> shape() const { return HandShape::from_measurements(hand_length_m, hand_width_m); }
  std::string describe() const;
};

inline constexpr int kSimSubjectCount = 15;  // as in Lee 2021, §4.6

// Subject 0..14: lengths evenly spread over the range, widths on a
// low-discrepancy permutation of theirs so size and shape are not locked together.
Result<SimSubject> sim_subject(int id);

}  // namespace proprio::sim
