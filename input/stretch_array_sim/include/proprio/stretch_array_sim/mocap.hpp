#pragma once
// What an OptiTrack-like optical system makes of the reflective markers on an
// array (issue 30; Glauser 2019, Sec. 4.4.1): per frame, labelled
// observations. Real systems lose markers behind folds and limbs and give a
// marker a NEW label when it comes back (the thesis: 165 labels for 12
// markers in 1.5 min, over 500 for 21 markers in 3 min), swap the labels of
// two tracks that pass close to each other and now and then report ghosts
// (reflections). The labelling step has to undo all of that; the truth of
// which label was which marker is kept apart (MocapTruth), for scoring it.
//
// Model, per frame:
//  - occlusion: by default each marker is a two-state chain: a visible one is
//    lost with probability p_lose, a lost one comes back with probability
//    1 / mean_occluded_frames, so losses come in stretches. A caller's hook
//    replaces that with its own probability that a marker is visible in a
//    frame (say, from the body's pose), drawn each frame;
//  - a marker that reappears gets a label never used before;
//  - each pair of visible markers closer than swap_distance_m swaps labels
//    with probability p_swap (the tracks keep the swapped labels);
//  - with probability p_ghost a ghost observation appears, within
//    ghost_radius_m of a random marker, with a fresh label for one frame;
//  - positions get isotropic Gaussian noise of noise_std_m per axis.
// Deterministic for a seed and the same sequence of calls.
#include <cstdint>
#include <functional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/mocap_frame.hpp"

namespace proprio::stretch_array_sim {

using stretch_array::MocapFrame;
using stretch_array::MocapObservation;

// Probability that `marker` is visible in frame `frame` at `position_m`.
using VisibilityHook = std::function<double(std::size_t marker, std::uint64_t frame, const Eigen::Vector3d& position_m)>;

struct MocapOptions {
  std::uint64_t seed = 1;
  double noise_std_m = 0.2e-3;  // per axis
  double p_lose = 0.004;        // per visible marker and frame (default occlusion)
  double mean_occluded_frames = 25.0;
  VisibilityHook visibility;    // set: replaces the default occlusion
  double swap_distance_m = 0.015;
  double p_swap = 0.01;         // per close pair and frame
  double p_ghost = 0.02;        // per frame
  double ghost_radius_m = 0.03;

  Status validate() const;
  std::string describe() const;
};

// What the labelling code is never given.
struct MocapTruth {
  // Per frame, per observation (same order): the marker it is, or -1 for a ghost.
  std::vector<std::vector<std::int32_t>> marker_of_observation;
  std::uint32_t labels_issued = 0;  // distinct labels, ghosts included
  std::uint64_t reappearances = 0;  // markers that came back under a new label
  std::uint64_t swaps = 0;          // label swaps between two tracks
  std::uint64_t ghosts = 0;
  std::uint64_t observations = 0;   // real ones
  std::uint64_t missing = 0;        // marker-frames not observed
};

class MocapSimulator {
 public:
  static Result<MocapSimulator> create(std::size_t marker_count, MocapOptions options = {});

  // One frame of true marker positions (marker_count of them, any frame of
  // reference; the body frame in the pipeline). Errors on a size mismatch or
  // a non-finite position.
  Result<MocapFrame> step(double t_s, std::span<const Eigen::Vector3d> markers_m);

  const MocapTruth& truth() const noexcept { return truth_; }
  std::size_t marker_count() const noexcept { return visible_.size(); }

 private:
  MocapSimulator() = default;
  MocapOptions options_;
  std::mt19937_64 rng_;
  std::vector<std::uint8_t> visible_;
  std::vector<std::uint32_t> label_;  // current label per visible marker
  std::uint32_t next_label_ = 1;
  std::uint64_t frame_ = 0;
  MocapTruth truth_;
};

}  // namespace proprio::stretch_array_sim
