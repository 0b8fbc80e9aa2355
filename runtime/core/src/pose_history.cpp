#include "proprio/core/pose_history.hpp"

#include <algorithm>
#include <cassert>
#include <cstdio>

namespace proprio {

namespace {

std::string ms(DurationNs ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1fms", static_cast<double>(ns) * 1e-6);
  return buf;
}

// Linear and angular velocity of every joint between two samples (world frame).
void finite_difference(const HandPose& a, const HandPose& b, std::array<Vec3, kHandJointCount>& v,
                       std::array<Vec3, kHandJointCount>& w) {
  const double dt = ns_to_seconds(b.time_ns - a.time_ns);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    v[i] = (b.T_world_joint[i].p - a.T_world_joint[i].p) / dt;
    // World-frame angular velocity: q_b = exp(w dt) q_a.
    w[i] = so3_log(b.T_world_joint[i].q * a.T_world_joint[i].q.conjugate()) / dt;
  }
}

}  // namespace

std::string PoseHistoryOptions::describe() const {
  return "capacity=" + std::to_string(capacity) + " max_prediction=" + ms(max_prediction_ns) +
         " max_gap=" + ms(max_interpolation_gap_ns);
}

const char* to_string(PoseQueryKind k) noexcept {
  switch (k) {
    case PoseQueryKind::exact: return "exact";
    case PoseQueryKind::interpolated: return "interpolated";
    case PoseQueryKind::predicted: return "predicted";
  }
  return "?";
}

PoseHistory::PoseHistory(PoseHistoryOptions options) : options_(options) {
  options_.capacity = std::max<std::size_t>(options_.capacity, 2);
  ring_.resize(options_.capacity);
}

const HandPose& PoseHistory::at(std::size_t i) const { return ring_[(head_ + i) % ring_.size()]; }
TimeNs PoseHistory::oldest_time_ns() const { assert(size_ > 0); return at(0).time_ns; }
TimeNs PoseHistory::newest_time_ns() const { assert(size_ > 0); return at(size_ - 1).time_ns; }
const HandPose& PoseHistory::newest() const { assert(size_ > 0); return at(size_ - 1); }

Status PoseHistory::push(const HandPose& sample) {
  if (size_ > 0 && sample.time_ns <= newest_time_ns()) {
    return make_error(Errc::invalid_argument, "pose sample at t=" + std::to_string(sample.time_ns) +
                                                  " ns is not newer than the newest one (t=" +
                                                  std::to_string(newest_time_ns()) + " ns)");
  }
  HandPose* slot;
  if (size_ < ring_.size()) {
    slot = &ring_[(head_ + size_) % ring_.size()];
    ++size_;
  } else {
    slot = &ring_[head_];  // overwrite the oldest
    head_ = (head_ + 1) % ring_.size();
  }
  *slot = sample;
  if (slot->data_time_ns == 0) slot->data_time_ns = sample.time_ns;
  if (slot->ready_time_ns == 0) slot->ready_time_ns = MonotonicClock::instance().now_ns();
  return {};
}

PoseLookup PoseHistory::lookup(TimeNs t, HandPose& out) const noexcept {
  if (size_ == 0) return PoseLookup::empty;
  if (t < oldest_time_ns()) return PoseLookup::too_old;
  const TimeNs newest_t = newest_time_ns();

  if (t >= newest_t) {
    const HandPose& last = newest();
    out = last;
    if (t == newest_t) return PoseLookup::exact;
    const DurationNs ahead = t - newest_t;
    if (ahead > options_.max_prediction_ns) return PoseLookup::stale;
    std::array<Vec3, kHandJointCount> v, w;
    if (last.has_velocity) {
      v = last.linear_velocity_in_world;
      w = last.angular_velocity_in_world;
    } else if (size_ >= 2) {
      finite_difference(at(size_ - 2), last, v, w);
    } else {
      v.fill(Vec3::Zero());
      w.fill(Vec3::Zero());
    }
    const double dt = ns_to_seconds(ahead);
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      Pose& T = out.T_world_joint[i];
      T.p += v[i] * dt;
      T.q = (so3_exp(w[i] * dt) * T.q).normalized();
    }
    out.time_ns = t;
    out.has_velocity = true;
    out.linear_velocity_in_world = v;
    out.angular_velocity_in_world = w;
    return PoseLookup::predicted;
  }

  // Binary search for the first sample newer than t; the ring is time-sorted.
  std::size_t lo = 0, hi = size_ - 1;
  while (hi - lo > 1) {
    const std::size_t mid = (lo + hi) / 2;
    (at(mid).time_ns <= t ? lo : hi) = mid;
  }
  const HandPose& a = at(lo);
  const HandPose& b = at(hi);
  if (a.time_ns == t) {
    out = a;
    return PoseLookup::exact;
  }
  if (b.time_ns - a.time_ns > options_.max_interpolation_gap_ns) return PoseLookup::gap;
  if (a.active != b.active || a.hand != b.hand) {
    // Interpolating into or out of an inactive pose would invent data; the nearer one wins.
    out = (t - a.time_ns <= b.time_ns - t) ? a : b;
    out.time_ns = t;
    out.data_time_ns = b.data_time_ns;
    out.ready_time_ns = b.ready_time_ns;
    return PoseLookup::interpolated;
  }
  const double s = static_cast<double>(t - a.time_ns) / static_cast<double>(b.time_ns - a.time_ns);
  out = a;
  out.time_ns = t;
  out.data_time_ns = b.data_time_ns;
  out.ready_time_ns = b.ready_time_ns;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    out.T_world_joint[i] = interpolate(a.T_world_joint[i], b.T_world_joint[i], s);
    out.radius_m[i] = a.radius_m[i] + s * (b.radius_m[i] - a.radius_m[i]);
    out.flags[i] = a.flags[i] & b.flags[i];
  }
  if (a.has_velocity && b.has_velocity) {
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      out.linear_velocity_in_world[i] =
          a.linear_velocity_in_world[i] + s * (b.linear_velocity_in_world[i] - a.linear_velocity_in_world[i]);
      out.angular_velocity_in_world[i] =
          a.angular_velocity_in_world[i] + s * (b.angular_velocity_in_world[i] - a.angular_velocity_in_world[i]);
    }
  } else {
    finite_difference(a, b, out.linear_velocity_in_world, out.angular_velocity_in_world);
    out.has_velocity = true;
  }
  return PoseLookup::interpolated;
}

Result<PoseQuery> PoseHistory::query(TimeNs t) const {
  PoseQuery q;
  switch (lookup(t, q.pose)) {
    case PoseLookup::exact: q.kind = PoseQueryKind::exact; return q;
    case PoseLookup::interpolated: q.kind = PoseQueryKind::interpolated; return q;
    case PoseLookup::predicted: q.kind = PoseQueryKind::predicted; return q;
    case PoseLookup::empty: return make_error(Errc::unavailable, "pose history is empty");
    case PoseLookup::too_old:
      return make_error(Errc::out_of_range, "requested time is " + ms(oldest_time_ns() - t) +
                                                " older than the oldest pose kept (history spans " +
                                                ms(newest_time_ns() - oldest_time_ns()) + ")");
    case PoseLookup::stale:
      return make_error(Errc::out_of_range, "requested time is " + ms(t - newest_time_ns()) +
                                                " past the newest pose; prediction is limited to " +
                                                ms(options_.max_prediction_ns));
    case PoseLookup::gap: break;
  }
  // Find the gap again for the message; this path is not hot.
  TimeNs before = oldest_time_ns(), after = newest_time_ns();
  for (std::size_t i = 0; i < size_; ++i) {
    if (at(i).time_ns <= t) before = at(i).time_ns;
    else { after = at(i).time_ns; break; }
  }
  return make_error(Errc::unavailable, "no pose near the requested time: it falls in a " + ms(after - before) +
                                           " gap between samples (limit " + ms(options_.max_interpolation_gap_ns) +
                                           ")");
}

}  // namespace proprio
