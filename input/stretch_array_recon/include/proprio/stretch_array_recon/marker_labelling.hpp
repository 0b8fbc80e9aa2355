#pragma once
// Semi-automatic marker labelling (Glauser 2019, Sec. 4.4.1): from optical
// tracks whose labels change whenever a marker is lost and found again, to
// the positions of the sheet's marker vertices in every frame.
//
// Initialization. Three labels are matched by hand to marker vertices in the
// first frame; the rest shape is moved onto them by Procrustes and every
// other marker vertex takes the nearest label of the first frame (greedily,
// closest pairs first, each label and vertex once, only under tau).
//
// Labeling. The remaining labels, in order of first appearance: for each
// frame t where label j* is visible (subsampled, below), the rest shape is
// deformed (ARAP) with the marker vertices already matched and visible in t as
// constraints; j* goes to the free marker vertex with the smallest mean
// distance over those proxies, when that is under tau (25 mm), else j* is an
// outlier. Each accepted label's observations constrain later proxies.
//
// Cost. A label is judged from at most max_proxy_frames proxies spread
// evenly over the frames it is visible in (all of them when fewer), and only
// frames with >= 3 matched markers. The thesis does not subsample; with a
// few hundred labels of hundreds of frames each, deforming every frame is
// 10^5 ARAP solves. A proxy starts from the last proxy of the same frame
// (the same pose with fewer constraints) or the nearest solved frame within
// warm_start_frames, else from the rest shape moved rigidly onto the
// constraints. Each proxy solved is kept for those warm starts (n x 3
// doubles: ~14 kB for prototype_92, ~30 MB for the 2300 proxies of the
// 3000-frame benchmark).
//
// A marker vertex is one physical marker, so a candidate vertex that another
// accepted label occupies in a frame where j* is also visible is not free
// (exclude_occupied): a duplicate ghost track becomes an outlier instead of
// a second track of the same marker.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/mocap_frame.hpp"
#include "proprio/stretch_array_recon/arap.hpp"
#include "proprio/stretch_array_recon/recon_mesh.hpp"

namespace proprio::stretch_array_recon {

using stretch_array::MocapFrame;
using stretch_array::MocapObservation;

// A manual match in the first frame: `label` is marker `marker` (an index
// into the marker vertex list, not a mesh vertex).
struct InitialMatch {
  std::uint32_t label;
  std::size_t marker;
};

struct LabellingOptions {
  double tau_m = 0.025;                // the thesis's acceptance threshold
  // Gap filling before the proxies: a track starting at most this many
  // frames after a free marker was last seen, within tau of that position,
  // continues it (0: off, the thesis's procedure alone).
  std::size_t continuity_frames = 16;
  std::size_t max_proxy_frames = 12;   // per label (see the top of this file)
  std::size_t warm_start_frames = 30;  // how far a proxy may borrow another frame's solution
  bool exclude_occupied = true;
  ArapOptions arap{/*max_iterations=*/12, /*tolerance_m=*/1e-4, /*factor_cache_size=*/32};
  Status validate() const;
  std::string describe() const;
};

struct LabellingResult {
  // Per frame, M x 3 marker positions in the mocap frame (NaN: no label).
  std::vector<Eigen::MatrixX3d> markers_m;
  std::vector<bool> complete;  // per frame: every marker has a position
  // Per label seen: its marker index, or -1 for an outlier.
  std::map<std::uint32_t, int> marker_of_label;
  Eigen::Isometry3d T_mocap_rest = Eigen::Isometry3d::Identity();  // the initial Procrustes fit
  std::size_t labels_seen = 0, labels_assigned = 0, labels_outlier = 0;
  std::size_t frames_complete = 0, frames_dropped = 0;  // dropped: incomplete
  std::size_t proxies_solved = 0;
  std::size_t labels_by_continuity = 0;  // assigned by gap filling, not by proxies
  std::string describe() const;
};

Result<LabellingResult> label_markers(const Eigen::MatrixX3d& rest_m, const std::vector<Triangle>& triangles,
                                      const std::vector<std::uint32_t>& marker_vertices,
                                      const std::vector<MocapFrame>& frames, const std::vector<InitialMatch>& initial,
                                      const LabellingOptions& options = {});

}  // namespace proprio::stretch_array_recon
