#include "proprio/stretch_glove/glove_tracker.hpp"

#include <cmath>
#include <cstdio>

namespace proprio::stretch_glove {
namespace {

std::optional<Finger> finger_owning(HandJoint j) {
  const std::size_t i = index_of(j);
  if (i < index_of(HandJoint::thumb_metacarpal)) return std::nullopt;
  if (i <= index_of(HandJoint::thumb_tip)) return Finger::thumb;
  return static_cast<Finger>(1 + (i - index_of(HandJoint::index_metacarpal)) / 5);
}

std::uint8_t bit(Finger f) { return static_cast<std::uint8_t>(1u << static_cast<unsigned>(f)); }

// Which fingers' DoFs a cell informs, for the TRACKED flags.
std::uint8_t fingers_informed_by(const StretchCell& c) {
  if (auto f = finger_owning(c.segment)) {
    std::uint8_t m = bit(*f);
    // A web cell spans its finger and the next one toward the little finger.
    if (c.category == StretchCellCategory::abduction && *f != Finger::little) {
      m |= bit(static_cast<Finger>(static_cast<int>(*f) + 1));
    }
    return m;
  }
  // Dorsum: the finger whose metacarpal runs under it (across_fraction: -0.5
  // thumb side to +0.5 little-finger side); the thumb's cells are on the thumb.
  const double x = std::clamp(c.across_fraction, -0.5, 0.5);
  const int k = std::clamp(static_cast<int>(std::floor((x + 0.5) * 4.0)), 0, 3);
  return bit(static_cast<Finger>(1 + k));
}

bool finite(const float* v, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(v[i])) return false;
  }
  return true;
}

}  // namespace

Status GloveTrackerOptions::validate() const {
  if (auto s = one_euro.validate(); !s) return s;
  if (!(max_invalid_fraction >= 0.0 && max_invalid_fraction <= 1.0)) {
    return make_error(Errc::invalid_argument, "glove tracker: max_invalid_fraction must be in [0, 1]");
  }
  if (!T_world_wrist_fixed.p.allFinite() || std::abs(T_world_wrist_fixed.q.norm() - 1.0) > 1e-6) {
    return make_error(Errc::invalid_argument, "glove tracker: the fixed wrist pose must be finite with a unit quaternion");
  }
  return {};
}

std::string GloveTrackerOptions::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf, "glove tracker: %s hand %.3f x %.3f m, 1€ %s (%s), hold above %.0f%% invalid cells",
                std::string(to_string(hand)).c_str(), hand_length_m, hand_width_m,
                filter_output ? "on" : "off", one_euro.describe().c_str(), 100 * max_invalid_fraction);
  return buf;
}

std::string GloveTrackerStats::describe() const {
  char buf[192];
  std::snprintf(buf, sizeof buf, "frames %llu, degraded %llu, held %llu, inference failures %llu",
                static_cast<unsigned long long>(frames), static_cast<unsigned long long>(frames_degraded),
                static_cast<unsigned long long>(frames_held), static_cast<unsigned long long>(inference_failures));
  return buf;
}

Result<GloveTracker> GloveTracker::create(const StretchGloveLayout& layout, MinMaxCalibration calibration,
                                          OnnxPoseModel model, GloveTrackerOptions options) {
  if (auto s = options.validate(); !s) return s.error();
  if (auto s = calibration.check_layout(layout); !s) return s.error();
  if (const auto& sc = model.sidecar(); sc) {
    if (auto s = sc->check_against(layout, model.path().string()); !s) return s.error();
  }
  auto shape = HandShape::from_measurements(options.hand_length_m, options.hand_width_m);
  if (!shape) return shape.error().with_context("glove tracker");
  return GloveTracker(layout, std::move(calibration), std::move(model), options, HandModel(*shape));
}

GloveTracker::GloveTracker(const StretchGloveLayout& layout, MinMaxCalibration calibration, OnnxPoseModel model,
                           GloveTrackerOptions options, HandModel hand)
    : layout_(layout),
      calibration_(std::move(calibration)),
      model_(std::move(model)),
      options_(options),
      hand_model_(std::move(hand)),
      grid_(layout_),
      filter_(kHandDofCount, options.one_euro),
      last_wrist_(options.T_world_wrist_fixed),
      normalized_(layout_.cell_count()),
      input_(kPoseInputSize) {
  for (const auto& c : layout_.cells) cell_fingers_.push_back(fingers_informed_by(c));
}

void GloveTracker::set_calibration(MinMaxCalibration calibration) {
  calibration_ = std::move(calibration);
  filter_.reset();
}

bool GloveTracker::process(const CellFrame& frame, HandPose& out) {
  ++stats_.frames;
  const std::size_t n = layout_.cell_count();
  calibration_.normalize(frame.cells_pf, normalized_);
  std::uint8_t degraded_fingers = 0;
  std::size_t invalid = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (frame.valid(i) && std::isfinite(normalized_[i])) continue;
    normalized_[i] = 0.0f;
    degraded_fingers |= cell_fingers_[i];
    ++invalid;
  }
  if (invalid > 0) ++stats_.frames_degraded;
  bool held = static_cast<double>(invalid) > options_.max_invalid_fraction * static_cast<double>(n);
  if (!held) {
    grid_.fill(normalized_, input_);
    if (!model_.infer(input_.data(), output_.data()) || !finite(output_.data(), output_.size())) {
      ++stats_.inference_failures;
      held = true;
    }
  }
  if (held) {
    ++stats_.frames_held;
  } else {
    HandAngles raw = angles_;
    for (std::size_t k = 0; k < kPoseOutputSize; ++k) {
      if (const auto& dof = layout_.output_grid[k]) raw[index_of(*dof)] = output_[k];
    }
    raw = hand_model_.limits().clamp(raw);
    if (options_.filter_output) filter_.filter(frame.time_ns, raw.data());
    angles_ = raw;
    have_angles_ = true;
  }
  for (std::size_t d = 0; d < kHandDofCount; ++d) {
    const auto f = static_cast<unsigned>(d / 4);
    dof_tracked_[d] = !held && have_angles_ && !(degraded_fingers & (1u << f));
  }

  bool wrist_tracked = true;
  if (wrist_provider_) {
    if (auto w = wrist_provider_(frame.time_ns)) {
      last_wrist_ = *w;
    } else {
      wrist_tracked = false;
    }
  }
  out = hand_model_.forward(options_.hand, angles_, last_wrist_, frame.time_ns);
  // Latency is measured from the newest capacitance measurement behind the
  // pose (the frame's time), not from the wrist or the 5-frame mean's centre.
  out.data_time_ns = frame.time_ns;
  if (!have_angles_) {
    out.active = false;
    return false;
  }
  for (std::size_t j = 0; j < kHandJointCount; ++j) {
    const auto f = finger_owning(joint_at(j));
    bool tracked = wrist_tracked && !held;
    if (f) {
      const std::size_t first = first_dof_of(*f);
      for (std::size_t d = first; d < first + 4; ++d) tracked = tracked && dof_tracked_[d];
    }
    out.flags[j] = tracked ? kJointFullyTracked : static_cast<std::uint8_t>(kOrientationValid | kPositionValid);
  }
  return !held;
}

}  // namespace proprio::stretch_glove
