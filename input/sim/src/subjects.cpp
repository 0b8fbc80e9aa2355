#include "proprio/sim/subjects.hpp"

#include <cstdio>

namespace proprio::sim {

std::string SimSubject::describe() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, "subject %d: hand length %.1f cm, width %.1f cm, %s-handed", id,
                hand_length_m * 100, hand_width_m * 100, std::string(to_string(dominant_hand)).c_str());
  return buf;
}

Result<SimSubject> sim_subject(int id) {
  if (id < 0 || id >= kSimSubjectCount) {
    return make_error(Errc::out_of_range, "simulated subject " + std::to_string(id) + " does not exist (use 0-" +
                                              std::to_string(kSimSubjectCount - 1) + ")");
  }
  const double n = kSimSubjectCount - 1;
  SimSubject s;
  s.id = id;
  s.hand_length_m = 0.170 + 0.035 * (id / n);
  s.hand_width_m = 0.090 + 0.020 * (((id * 7) % kSimSubjectCount) / n);
  return s;
}

}  // namespace proprio::sim
