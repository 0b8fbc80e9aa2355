#pragma once
// Stereo-camera helpers shared by the VIST and image-simulation tests.
#include <algorithm>
#include <cstdlib>

#include "proprio/glove_descriptions/imu_glove_description.hpp"

namespace proprio::testing_support {

// The default pinhole camera (1280x720, fx 640, fy 623.5, cx 639.5, cy 359.5),
// a 63 mm baseline and the left camera at the head's origin.
inline StereoRig test_rig() {
  StereoRig rig;
  rig.camera = PinholeCamera{};
  rig.baseline_m = 0.063;
  rig.T_head_leftcam = Pose::identity();
  return rig;
}

// Distance between two 8-bit hue codes on their circle of 256.
inline int hue_distance(int a, int b) {
  const int d = std::abs(a - b) % 256;
  return std::min(d, 256 - d);
}

}  // namespace proprio::testing_support
