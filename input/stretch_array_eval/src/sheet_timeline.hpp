#pragma once
// A simulated sheet seen at any time: its mechanics stepped at a fixed rate,
// its electrical state (stretch_array_sim::SheetState) and vertices linearly
// interpolated between steps, because the board's rows fall between them.
// Internal to stretch_array_eval (sim-array and bench array).
#include <algorithm>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array_sim/array_sheet.hpp"

namespace proprio::stretch_array_eval {

class SheetTimeline {
 public:
  // The sheet's vertices at time t (the caller's mechanics, stepped forward).
  using Stepper = std::function<Result<std::vector<Eigen::Vector3d>>(double t_s)>;

  SheetTimeline(Stepper stepper, const stretch_array_sim::ArraySheet& array, double dt_s)
      : stepper_(std::move(stepper)), array_(array), dt_s_(dt_s) {}

  Status start() {
    if (auto st = advance_to(0.0, prev_); !st) return st;
    next_ = prev_;
    return {};
  }
  // Nondecreasing t only.
  Result<stretch_array_sim::SheetState> state_at(double t_s) {
    if (auto st = cover(t_s); !st) return st.error();
    const double w = weight(t_s);
    stretch_array_sim::SheetState s = prev_.state;
    auto lerp = [w](std::vector<double>& a, const std::vector<double>& b) {
      for (std::size_t i = 0; i < a.size(); ++i) a[i] += w * (b[i] - a[i]);
    };
    lerp(s.cell_f, next_.state.cell_f);
    lerp(s.cell_max_stretch, next_.state.cell_max_stretch);
    lerp(s.top_squares, next_.state.top_squares);
    lerp(s.bottom_squares, next_.state.bottom_squares);
    return s;
  }
  Result<std::vector<Eigen::Vector3d>> vertices_at(double t_s) {
    if (auto st = cover(t_s); !st) return st.error();
    const double w = weight(t_s);
    std::vector<Eigen::Vector3d> v = prev_.vertices;
    for (std::size_t i = 0; i < v.size(); ++i) v[i] += w * (next_.vertices[i] - v[i]);
    return v;
  }
  // The largest cell C/C0 (ideal) of any step so far.
  double max_cell_ratio() const { return max_ratio_; }

 private:
  struct Sample {
    double t_s = 0.0;
    stretch_array_sim::SheetState state;
    std::vector<Eigen::Vector3d> vertices;
  };
  double weight(double t_s) const {
    return next_.t_s > prev_.t_s ? std::clamp((t_s - prev_.t_s) / (next_.t_s - prev_.t_s), 0.0, 1.0) : 0.0;
  }
  Status cover(double t_s) {
    while (next_.t_s < t_s) {
      prev_ = std::move(next_);
      if (auto st = advance_to(prev_.t_s + dt_s_, next_); !st) return st;
    }
    return {};
  }
  Status advance_to(double t_s, Sample& out) {
    auto x = stepper_(t_s);
    if (!x) return x.error();
    out.t_s = t_s;
    out.vertices = std::move(*x);
    auto state = array_.evaluate(out.vertices);
    if (!state) return state.error();
    out.state = std::move(*state);
    const auto& rest = array_.rest_state().cell_f;
    for (std::size_t c = 0; c < rest.size(); ++c) max_ratio_ = std::max(max_ratio_, out.state.cell_f[c] / rest[c]);
    return {};
  }
  Stepper stepper_;
  const stretch_array_sim::ArraySheet& array_;
  double dt_s_;
  Sample prev_, next_;
  double max_ratio_ = 0.0;
};

}  // namespace proprio::stretch_array_eval
