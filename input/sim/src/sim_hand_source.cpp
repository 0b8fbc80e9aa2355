#include "proprio/sim/sim_hand_source.hpp"

#include <chrono>
#include <cstdio>

#include "proprio/core/log.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::sim {

namespace {
// Half-width of the central difference for head-relative velocities.
constexpr TimeNs kVelocityStepNs = 1'000'000;

std::size_t slot(Handedness h) { return static_cast<std::size_t>(h); }
}  // namespace

std::string SimHandSourceOptions::describe() const {
  std::string hand_list;
  for (auto h : hands) hand_list += (hand_list.empty() ? "" : "+") + std::string(to_string(h));
  char buf[200];
  std::snprintf(buf, sizeof buf, "sim subject=%d protocol=%s seed=%llu rate=%.1fHz hands=%s frame=%s", subject,
                std::string(to_string(protocol)).c_str(), static_cast<unsigned long long>(seed), rate_hz,
                hand_list.c_str(), relative_to_head ? "head" : "world");
  return buf;
}

Result<std::unique_ptr<SimHandSource>> SimHandSource::create(SimHandSourceOptions options, const Clock& clock) {
  auto subject = sim_subject(options.subject);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();
  if (!(options.rate_hz >= 0.0 && options.rate_hz <= 2000.0)) {
    return make_error(Errc::out_of_range, "sim source rate " + std::to_string(options.rate_hz) +
                                              " Hz is outside 0-2000 Hz (0 = no thread)");
  }
  if (options.hands.empty()) return make_error(Errc::invalid_argument, "sim source serves no hands");
  std::unique_ptr<SimHandSource> src(new SimHandSource(std::move(options), clock));
  for (Handedness h : src->options_.hands) {
    HandMotionOptions mo;
    mo.protocol = src->options_.protocol;
    mo.hand = h;
    // Each hand moves on its own, reproducibly.
    mo.seed = mix_seed(src->options_.seed, 100 + slot(h));
    src->generators_[slot(h)].emplace(HandModel(*shape), mo);
    src->histories_[slot(h)].emplace(src->options_.history);
  }
  src->start_ns_ = clock.now_ns();
  src->produce(src->start_ns_);
  if (src->options_.rate_hz > 0.0) src->thread_ = std::thread([s = src.get()] { s->run(); });
  return src;
}

SimHandSource::SimHandSource(SimHandSourceOptions options, const Clock& clock)
    : options_(std::move(options)), clock_(clock) {}

SimHandSource::~SimHandSource() {
  {
    std::lock_guard lock(stop_mutex_);
    stop_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool SimHandSource::available(Handedness hand) const noexcept { return histories_[slot(hand)].has_value(); }

HandPose SimHandSource::sample_relative_to_head(HandMotionGenerator& g, TimeNs t, TimeNs stamp_ns) {
  auto in_head = [&](TimeNs at) {
    const HandMotionFrame f = g.sample(at);
    HandPose p = f.pose;
    const Pose T_head_world = f.T_world_head.inverse();
    for (auto& T : p.T_world_joint) T = T_head_world * T;
    return p;
  };
  HandPose p = in_head(t);
  const HandPose before = in_head(std::max<TimeNs>(0, t - kVelocityStepNs));
  const HandPose after = in_head(t + kVelocityStepNs);
  const double dt = ns_to_seconds(after.time_ns - before.time_ns);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    p.linear_velocity_in_world[i] = (after.T_world_joint[i].p - before.T_world_joint[i].p) / dt;
    p.angular_velocity_in_world[i] = so3_log(after.T_world_joint[i].q * before.T_world_joint[i].q.conjugate()) / dt;
  }
  p.time_ns = stamp_ns;
  return p;
}

void SimHandSource::produce(TimeNs now_ns) {
  const TimeNs t = std::max<TimeNs>(0, now_ns - start_ns_);
  for (Handedness h : options_.hands) {
    auto& g = *generators_[slot(h)];
    HandPose p;
    if (options_.relative_to_head) {
      p = sample_relative_to_head(g, t, now_ns);
    } else {
      p = g.sample(t).pose;
      p.time_ns = now_ns;
    }
    std::lock_guard lock(mutex_);
    (void)histories_[slot(h)]->push(p);  // a non-increasing clock drops the sample, nothing else
  }
}

void SimHandSource::run() {
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / options_.rate_hz));
  auto next = std::chrono::steady_clock::now();
  std::unique_lock lock(stop_mutex_);
  while (!stop_) {
    next += period;
    if (stop_cv_.wait_until(lock, next, [this] { return stop_; })) break;
    lock.unlock();
    produce(clock_.now_ns());
    lock.lock();
  }
}

Result<HandPose> SimHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  if (!available(hand)) {
    return make_error(Errc::unavailable, "the sim source does not simulate the " + std::string(to_string(hand)) + " hand");
  }
  std::lock_guard lock(mutex_);
  auto q = histories_[slot(hand)]->query(t_ns);
  if (!q) return q.error().with_context("sim source");
  return std::move(q->pose);
}

PoseLookup SimHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (!available(hand)) return PoseLookup::empty;
  std::lock_guard lock(mutex_);
  return histories_[slot(hand)]->lookup(t_ns, out);
}

}  // namespace proprio::sim
