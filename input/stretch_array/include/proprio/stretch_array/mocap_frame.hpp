#pragma once
// What an optical motion-capture system gives for the reflective markers on
// an array, per frame (Glauser 2019, Sec. 4.4.1): labelled observations, a
// label standing for one continuous track. The mocap simulator
// (stretch_array_sim) writes these and the labelling (stretch_array_recon)
// reads them; a recorded capture is read into them too.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace proprio::stretch_array {

struct MocapObservation {
  std::uint32_t label;
  Eigen::Vector3d position_m;
};

struct MocapFrame {
  double t_s;
  std::vector<MocapObservation> observations;
};

}  // namespace proprio::stretch_array
