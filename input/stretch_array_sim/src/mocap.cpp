#include "proprio/stretch_array_sim/mocap.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

namespace proprio::stretch_array_sim {

namespace {
Error mocap_error(const std::string& what) { return make_error(Errc::invalid_argument, "mocap simulator: " + what); }
bool probability(double p) { return std::isfinite(p) && p >= 0.0 && p <= 1.0; }
}  // namespace

Status MocapOptions::validate() const {
  if (!(std::isfinite(noise_std_m) && noise_std_m >= 0.0 && noise_std_m < 0.1)) return mocap_error("noise_std_m must be in [0, 0.1) m");
  if (!probability(p_lose) || !probability(p_swap) || !probability(p_ghost)) return mocap_error("p_lose, p_swap and p_ghost must be in [0, 1]");
  if (!(std::isfinite(mean_occluded_frames) && mean_occluded_frames >= 1.0)) return mocap_error("mean_occluded_frames must be >= 1");
  if (!(std::isfinite(swap_distance_m) && swap_distance_m >= 0.0)) return mocap_error("swap_distance_m must be >= 0");
  if (!(std::isfinite(ghost_radius_m) && ghost_radius_m >= 0.0)) return mocap_error("ghost_radius_m must be >= 0");
  return {};
}

std::string MocapOptions::describe() const {
  std::ostringstream o;
  o << "noise " << noise_std_m * 1e3 << " mm; occlusion "
    << (visibility ? std::string("by the caller's hook") : "") ;
  if (!visibility) o << "p_lose " << p_lose << " per frame, " << mean_occluded_frames << " frames on average";
  o
    << "; swaps within " << swap_distance_m * 1e3 << " mm at " << p_swap << " per pair-frame; ghosts " << p_ghost << " per frame within "
    << ghost_radius_m * 1e3 << " mm; seed " << seed;
  return o.str();
}

Result<MocapSimulator> MocapSimulator::create(std::size_t marker_count, MocapOptions options) {
  if (auto v = options.validate(); !v) return v.error();
  if (marker_count == 0) return mocap_error("needs at least one marker");
  MocapSimulator s;
  s.options_ = std::move(options);
  s.rng_.seed(s.options_.seed);
  // Everything is visible at the start (the rest pose the labelling
  // initialises from), each marker with its own label.
  s.visible_.assign(marker_count, 1);
  s.label_.resize(marker_count);
  for (std::size_t m = 0; m < marker_count; ++m) s.label_[m] = s.next_label_++;
  s.truth_.labels_issued = static_cast<std::uint32_t>(marker_count);
  return s;
}

Result<MocapFrame> MocapSimulator::step(double t_s, std::span<const Eigen::Vector3d> markers_m) {
  const std::size_t n = visible_.size();
  if (markers_m.size() != n) return mocap_error("got " + std::to_string(markers_m.size()) + " markers, expected " + std::to_string(n));
  for (const auto& p : markers_m) {
    if (!p.allFinite()) return mocap_error("a marker position is not finite");
  }
  std::uniform_real_distribution<double> U(0.0, 1.0);
  std::normal_distribution<double> N(0.0, 1.0);
  const std::uint64_t frame = frame_++;

  // Occlusion (the first frame shows everything).
  if (frame > 0) {
    for (std::size_t m = 0; m < n; ++m) {
      bool vis;
      if (options_.visibility) {
        vis = U(rng_) < std::clamp(options_.visibility(m, frame, markers_m[m]), 0.0, 1.0);
      } else {
        vis = visible_[m] ? U(rng_) >= options_.p_lose : U(rng_) < 1.0 / options_.mean_occluded_frames;
      }
      if (vis && !visible_[m]) {
        label_[m] = next_label_++;  // a track picked up again is a new track
        ++truth_.labels_issued;
        ++truth_.reappearances;
      }
      visible_[m] = vis ? 1 : 0;
    }
  }
  // Label swaps between close tracks.
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t b = a + 1; b < n; ++b) {
      if (!visible_[a] || !visible_[b]) continue;
      if ((markers_m[a] - markers_m[b]).norm() >= options_.swap_distance_m) continue;
      if (U(rng_) < options_.p_swap) {
        std::swap(label_[a], label_[b]);
        ++truth_.swaps;
      }
    }
  }
  MocapFrame out{t_s, {}};
  std::vector<std::int32_t> who;
  for (std::size_t m = 0; m < n; ++m) {
    if (!visible_[m]) {
      ++truth_.missing;
      continue;
    }
    const Eigen::Vector3d noise(N(rng_), N(rng_), N(rng_));
    out.observations.push_back({label_[m], markers_m[m] + options_.noise_std_m * noise});
    who.push_back(static_cast<std::int32_t>(m));
    ++truth_.observations;
  }
  if (U(rng_) < options_.p_ghost) {
    const auto m = static_cast<std::size_t>(U(rng_) * static_cast<double>(n)) % n;
    Eigen::Vector3d d(N(rng_), N(rng_), N(rng_));
    d *= options_.ghost_radius_m * std::cbrt(U(rng_)) / std::max(d.norm(), 1e-12);  // uniform in the ball
    out.observations.push_back({next_label_++, markers_m[m] + d});
    who.push_back(-1);
    ++truth_.labels_issued;
    ++truth_.ghosts;
  }
  // Systems report in label order, not in marker order.
  std::vector<std::size_t> order(out.observations.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) { return out.observations[i].label < out.observations[j].label; });
  MocapFrame sorted{t_s, {}};
  std::vector<std::int32_t> sorted_who;
  for (std::size_t i : order) {
    sorted.observations.push_back(out.observations[i]);
    sorted_who.push_back(who[i]);
  }
  truth_.marker_of_observation.push_back(std::move(sorted_who));
  return sorted;
}

}  // namespace proprio::stretch_array_sim
