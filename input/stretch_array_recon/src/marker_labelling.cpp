#include "proprio/stretch_array_recon/marker_labelling.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>
#include <unordered_map>

namespace proprio::stretch_array_recon {

Status LabellingOptions::validate() const {
  if (!(tau_m > 0) || !std::isfinite(tau_m))
    return make_error(Errc::invalid_argument, "tau_m must be a positive distance in metres");
  if (max_proxy_frames < 1) return make_error(Errc::invalid_argument, "max_proxy_frames must be >= 1");
  return arap.validate();
}

std::string LabellingOptions::describe() const {
  std::ostringstream s;
  s << "tau_m=" << tau_m << " continuity_frames=" << continuity_frames << " max_proxy_frames=" << max_proxy_frames << " warm_start_frames=" << warm_start_frames
    << " exclude_occupied=" << (exclude_occupied ? "yes" : "no") << " arap: " << arap.describe();
  return s.str();
}

std::string LabellingResult::describe() const {
  std::ostringstream s;
  s << labels_seen << " labels: " << labels_assigned << " assigned, " << labels_outlier << " outliers; "
    << frames_complete << " complete frames, " << frames_dropped << " dropped; " << proxies_solved << " proxies";
  return s.str();
}

Result<LabellingResult> label_markers(const Eigen::MatrixX3d& rest_m, const std::vector<Triangle>& triangles,
                                      const std::vector<std::uint32_t>& marker_vertices,
                                      const std::vector<MocapFrame>& frames, const std::vector<InitialMatch>& initial,
                                      const LabellingOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  const std::size_t M = marker_vertices.size();
  const std::size_t F = frames.size();
  if (M < 3) return make_error(Errc::invalid_argument, "labelling needs >= 3 marker vertices");
  if (F == 0) return make_error(Errc::invalid_argument, "labelling needs at least one mocap frame");
  for (std::uint32_t v : marker_vertices) {
    if (v >= rest_m.rows())
      return make_error(Errc::invalid_argument, "marker vertex " + std::to_string(v) + " is not a mesh vertex");
  }
  if (initial.size() != 3) {
    return make_error(Errc::invalid_argument, "labelling needs exactly 3 manual matches in the first frame (got " +
                                                  std::to_string(initial.size()) + ")");
  }
  auto arap = ArapDeformer::create(rest_m, triangles, options.arap);
  if (!arap) return arap.error();

  // Labels: their frames and positions, in order of first appearance.
  struct Track {
    std::uint32_t label;
    std::size_t first;
    std::vector<std::pair<std::size_t, Eigen::Vector3d>> seen;
  };
  std::vector<Track> tracks;
  std::unordered_map<std::uint32_t, std::size_t> track_of;
  for (std::size_t t = 0; t < F; ++t) {
    for (const MocapObservation& o : frames[t].observations) {
      if (!o.position_m.allFinite()) continue;  // a mocap gap written as NaN
      auto [it, fresh] = track_of.emplace(o.label, tracks.size());
      if (fresh) tracks.push_back({o.label, t, {}});
      Track& tr = tracks[it->second];
      if (!tr.seen.empty() && tr.seen.back().first == t) {
        return make_error(Errc::invalid_argument,
                          "frame " + std::to_string(t) + " has label " + std::to_string(o.label) + " twice");
      }
      tr.seen.emplace_back(t, o.position_m);
    }
  }

  LabellingResult R;
  R.labels_seen = tracks.size();
  R.markers_m.assign(
      F, Eigen::MatrixX3d::Constant(static_cast<Eigen::Index>(M), 3, std::numeric_limits<double>::quiet_NaN()));
  std::vector<std::vector<std::int64_t>> occupant(F, std::vector<std::int64_t>(M, -1));  // track index
  std::vector<int> marker_of_track(tracks.size(), -2);                                   // -2 undecided, -1 outlier

  auto accept = [&](std::size_t tr, std::size_t m) {
    marker_of_track[tr] = static_cast<int>(m);
    for (const auto& [t, p] : tracks[tr].seen) {
      if (occupant[t][m] >= 0) continue;  // two labels on one marker in one frame: the first stays
      occupant[t][m] = static_cast<std::int64_t>(tr);
      R.markers_m[t].row(static_cast<Eigen::Index>(m)) = p.transpose();
    }
  };

  // Initialization: three manual matches, Procrustes, nearest in frame 0.
  Eigen::MatrixX3d from(3, 3), to(3, 3);
  std::set<std::size_t> used_markers;
  for (std::size_t k = 0; k < 3; ++k) {
    const InitialMatch& im = initial[k];
    if (im.marker >= M)
      return make_error(Errc::invalid_argument, "initial match " + std::to_string(k) + ": marker " +
                                                    std::to_string(im.marker) + " of " + std::to_string(M));
    auto it = track_of.find(im.label);
    if (it == track_of.end() || tracks[it->second].first != 0) {
      return make_error(Errc::invalid_argument, "initial match " + std::to_string(k) + ": label " +
                                                    std::to_string(im.label) +
                                                    " is not visible in the first frame; pick three labels it shows");
    }
    if (!used_markers.insert(im.marker).second || marker_of_track[it->second] != -2) {
      return make_error(Errc::invalid_argument, "the initial matches repeat a label or a marker");
    }
    from.row(static_cast<Eigen::Index>(k)) = rest_m.row(marker_vertices[im.marker]);
    to.row(static_cast<Eigen::Index>(k)) = tracks[it->second].seen.front().second.transpose();
    accept(it->second, im.marker);
  }
  auto T = fit_rigid(from, to);
  if (!T) return T.error().with_context("initial matches");
  R.T_mocap_rest = *T;
  {
    struct Pair {
      double d;
      std::size_t tr, m;
    };
    std::vector<Pair> pairs;
    for (const MocapObservation& o : frames[0].observations) {
      auto it = track_of.find(o.label);
      if (it == track_of.end() || marker_of_track[it->second] != -2) continue;
      for (std::size_t m = 0; m < M; ++m) {
        if (used_markers.count(m)) continue;
        const Eigen::Vector3d p = *T * rest_m.row(marker_vertices[m]).transpose();
        pairs.push_back({(p - o.position_m).norm(), it->second, m});
      }
    }
    std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.d < b.d; });
    for (const Pair& p : pairs) {
      if (p.d >= options.tau_m) break;
      if (marker_of_track[p.tr] != -2 || used_markers.count(p.m)) continue;
      used_markers.insert(p.m);
      accept(p.tr, p.m);
    }
  }

  // Labeling, in order of first appearance (tracks are in that order).
  std::map<std::size_t, Eigen::MatrixX3d> solved;  // frame -> its last proxy
  std::vector<std::uint32_t> cons;
  Eigen::MatrixX3d targets, V;
  for (std::size_t tr = 0; tr < tracks.size(); ++tr) {
    if (marker_of_track[tr] != -2) continue;
    const Track& track = tracks[tr];
    std::vector<bool> free(M, true);
    if (options.exclude_occupied) {
      for (const auto& [t, p] : track.seen) {
        for (std::size_t m = 0; m < M; ++m) {
          if (occupant[t][m] >= 0) free[m] = false;
        }
      }
    }
    // Continuity first (gap filling; the thesis goes straight to the proxies):
    // a track that starts shortly after a free marker was last seen, within
    // tau of where it was, is that marker coming back into view. Proxies
    // are least reliable exactly where markers get lost, at the sheet's
    // moving extremities, where this needs none.
    if (options.continuity_frames > 0 && track.seen.size() >= 2) {  // a one-frame ghost continues nothing
      const std::size_t t0 = track.first;
      const Eigen::Vector3d& p0 = track.seen.front().second;
      double best_d = options.tau_m;
      int best_m = -1;
      for (std::size_t m = 0; m < M; ++m) {
        if (!free[m]) continue;
        for (std::size_t back = 1; back <= options.continuity_frames && back <= t0; ++back) {
          if (occupant[t0 - back][m] < 0) continue;
          const double d = (R.markers_m[t0 - back].row(static_cast<Eigen::Index>(m)).transpose() - p0).norm();
          if (d < best_d) best_d = d, best_m = static_cast<int>(m);
          break;
        }
      }
      if (best_m >= 0) {
        accept(tr, static_cast<std::size_t>(best_m));
        ++R.labels_by_continuity;
        continue;
      }
    }
    std::vector<std::size_t> usable;  // indices into track.seen
    for (std::size_t k = 0; k < track.seen.size(); ++k) {
      const std::size_t t = track.seen[k].first;
      std::size_t n = 0;
      for (std::size_t m = 0; m < M; ++m) n += occupant[t][m] >= 0;
      if (n >= 3) usable.push_back(k);
    }
    if (usable.empty() || std::none_of(free.begin(), free.end(), [](bool f) { return f; })) {
      marker_of_track[tr] = -1;
      continue;
    }
    std::vector<std::size_t> picks;
    const std::size_t P = std::min(options.max_proxy_frames, usable.size());
    for (std::size_t i = 0; i < P; ++i) picks.push_back(usable[(i * usable.size() + usable.size() / (2 * P)) / P]);
    Eigen::VectorXd sum = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(M));
    for (std::size_t k : picks) {
      const auto& [t, pos] = track.seen[k];
      cons.clear();
      std::vector<Eigen::Index> rows;
      for (std::size_t m = 0; m < M; ++m) {
        if (occupant[t][m] >= 0) cons.push_back(marker_vertices[m]), rows.push_back(static_cast<Eigen::Index>(m));
      }
      targets.resize(static_cast<Eigen::Index>(cons.size()), 3);
      for (std::size_t i = 0; i < rows.size(); ++i)
        targets.row(static_cast<Eigen::Index>(i)) = R.markers_m[t].row(rows[i]);
      V.resize(0, 3);
      auto near = solved.lower_bound(t > options.warm_start_frames ? t - options.warm_start_frames : 0);
      std::size_t best = std::numeric_limits<std::size_t>::max();
      for (auto it = near; it != solved.end() && it->first <= t + options.warm_start_frames; ++it) {
        const std::size_t d = it->first > t ? it->first - t : t - it->first;
        if (d < best) best = d, V = it->second;
      }
      if (Status s = arap->solve(cons, targets, V); !s)
        return s.error().with_context("proxy for frame " + std::to_string(t));
      ++R.proxies_solved;
      solved[t] = V;
      for (std::size_t m = 0; m < M; ++m)
        sum(static_cast<Eigen::Index>(m)) += (V.row(marker_vertices[m]).transpose() - pos).norm();
    }
    double best = std::numeric_limits<double>::infinity();
    std::size_t best_m = 0;
    for (std::size_t m = 0; m < M; ++m) {
      const double mean = sum(static_cast<Eigen::Index>(m)) / static_cast<double>(picks.size());
      if (free[m] && mean < best) best = mean, best_m = m;
    }
    if (best < options.tau_m) {
      accept(tr, best_m);
    } else {
      marker_of_track[tr] = -1;
    }
  }

  for (std::size_t tr = 0; tr < tracks.size(); ++tr) {
    R.marker_of_label[tracks[tr].label] = marker_of_track[tr] < 0 ? -1 : marker_of_track[tr];
    (marker_of_track[tr] >= 0 ? R.labels_assigned : R.labels_outlier) += 1;
  }
  R.complete.resize(F);
  for (std::size_t t = 0; t < F; ++t) {
    R.complete[t] = R.markers_m[t].allFinite();
    (R.complete[t] ? R.frames_complete : R.frames_dropped) += 1;
  }
  return R;
}

}  // namespace proprio::stretch_array_recon
