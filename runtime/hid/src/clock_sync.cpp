#include "proprio/hid/clock_sync.hpp"

#include <algorithm>
#include <cmath>

namespace proprio::hid {

namespace {

constexpr double kNominalSlope = 1000.0;  // host ns per device µs
constexpr std::size_t kMaxBuckets = 4096;

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && (a < 0) != (b < 0)) ? q - 1 : q;
}

// Differences of arbitrary int64 times without signed overflow (a host clock
// far from zero minus an origin far below it wraps instead of being undefined).
std::int64_t wrapping_sub(std::int64_t a, std::int64_t b) noexcept {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) - static_cast<std::uint64_t>(b));
}
std::int64_t wrapping_add(std::int64_t a, std::int64_t b) noexcept {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) + static_cast<std::uint64_t>(b));
}

std::int64_t to_int64(double v) noexcept {
  // Converting a double outside int64's range is undefined; saturate instead.
  if (!(v > -9.2e18)) return std::numeric_limits<std::int64_t>::min();
  if (!(v < 9.2e18)) return std::numeric_limits<std::int64_t>::max();
  return std::llround(v);
}

// > 0 when o -> a -> b turns counter-clockwise (b above the line through o and a, seen from left to right).
double cross(const auto& o, const auto& a, const auto& b) noexcept {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

}  // namespace

const char* to_string(ClockSyncEvent event) noexcept {
  switch (event) {
    case ClockSyncEvent::locked: return "locked";
    case ClockSyncEvent::tracked: return "tracked";
    case ClockSyncEvent::relocked_backwards: return "relocked_backwards";
    case ClockSyncEvent::relocked_jump: return "relocked_jump";
    case ClockSyncEvent::relocked_late: return "relocked_late";
    case ClockSyncEvent::ignored: return "ignored";
  }
  return "unknown";
}

ClockSync::ClockSync(ClockSyncOptions options) : options_(options) {
  bucket_us_ = std::max<std::int64_t>(1, options_.bucket_ns / 1000);
  const std::int64_t window_us = std::max<std::int64_t>(bucket_us_, options_.window_ns / 1000);
  // One more bucket than the window holds, for the one being filled.
  const auto count = static_cast<std::size_t>(std::min<std::int64_t>(window_us / bucket_us_ + 1,
                                                                      static_cast<std::int64_t>(kMaxBuckets)));
  buckets_.assign(count, Bucket{});
  points_.reserve(count);
  hull_.reserve(count);
}

void ClockSync::reset() noexcept {
  if (locked_) ++stats_.relocks;
  locked_ = false;
}

void ClockSync::lock(std::uint32_t device_us, TimeNs receive_ns) noexcept {
  locked_ = true;
  origin_device_us_ = device_us;
  origin_host_ns_ = receive_ns;
  newest_device_us_ = device_us;
  newest_key_ = 0;
  last_receive_ns_ = receive_ns;
  late_run_ = 0;
  last_excess_ns_ = 0;
  stats_.timestamp_wraps = 0;
  std::fill(buckets_.begin(), buckets_.end(), Bucket{});
  line_x_ = line_y_ = 0.0;
  slope_ = kNominalSlope;
  add(0, 0);
  refit();
}

std::int64_t ClockSync::unwrap(std::uint32_t device_us) const noexcept {
  return newest_device_us_ + static_cast<std::int32_t>(device_us - static_cast<std::uint32_t>(newest_device_us_));
}

ClockSyncEvent ClockSync::observe(std::uint32_t device_us, TimeNs receive_ns) noexcept {
  ++stats_.observations;
  if (!locked_) {
    lock(device_us, receive_ns);
    return ClockSyncEvent::locked;
  }
  if (receive_ns < last_receive_ns_) {
    ++stats_.ignored;
    return ClockSyncEvent::ignored;
  }
  const std::int64_t device = unwrap(device_us);
  auto relock = [&](ClockSyncEvent why) {
    ++stats_.relocks;
    lock(device_us, receive_ns);
    return why;
  };
  if (device < newest_device_us_ - options_.backwards_threshold_ns / 1000) {
    return relock(ClockSyncEvent::relocked_backwards);
  }
  const std::int64_t x = device - origin_device_us_;
  const std::int64_t y = wrapping_sub(receive_ns, origin_host_ns_);
  const double excess = static_cast<double>(y) - line_at(static_cast<double>(x));
  last_excess_ns_ = to_int64(excess);
  if (excess < -static_cast<double>(options_.jump_threshold_ns)) return relock(ClockSyncEvent::relocked_jump);
  if (excess > static_cast<double>(options_.jump_threshold_ns)) {
    if (++late_run_ >= options_.relock_after_late) return relock(ClockSyncEvent::relocked_late);
  } else {
    late_run_ = 0;
  }
  last_receive_ns_ = receive_ns;
  if (device > newest_device_us_) {
    const std::int64_t lap = std::int64_t{1} << 32;
    stats_.timestamp_wraps += static_cast<std::uint64_t>(floor_div(device, lap) - floor_div(newest_device_us_, lap));
    newest_device_us_ = device;
  }
  add(x, y);
  refit();
  return ClockSyncEvent::tracked;
}

void ClockSync::add(std::int64_t x_us, std::int64_t y_ns) noexcept {
  const std::int64_t key = floor_div(x_us, bucket_us_);
  const auto n = static_cast<std::int64_t>(buckets_.size());
  if (key > newest_key_) newest_key_ = key;
  if (key <= newest_key_ - n) return;  // older than the window
  Bucket& b = buckets_[static_cast<std::size_t>(((key % n) + n) % n)];
  // Lowest by receive time less the current line: with the slope known, the
  // point closest to the floor, wherever it falls in the bucket.
  const auto below = [&](std::int64_t x, std::int64_t y) {
    return static_cast<double>(y) - slope_ * static_cast<double>(x);
  };
  if (b.key != key || below(x_us, y_ns) < below(b.x_us, b.y_ns)) b = Bucket{key, x_us, y_ns};
}

void ClockSync::refit() noexcept {
  // Bucket minima in time order, sheared by the nominal slope so that the
  // numbers stay small (a shear keeps convexity and "below").
  points_.clear();
  const auto n = static_cast<std::int64_t>(buckets_.size());
  for (std::int64_t key = newest_key_ - n + 1; key <= newest_key_; ++key) {
    const Bucket& b = buckets_[static_cast<std::size_t>(((key % n) + n) % n)];
    if (b.key != key) continue;
    points_.push_back({static_cast<double>(b.x_us),
                       static_cast<double>(b.y_ns) - kNominalSlope * static_cast<double>(b.x_us)});
  }
  if (points_.empty()) return;
  span_ns_ = static_cast<DurationNs>((points_.back().x - points_.front().x) * 1000.0);

  const auto use_nominal = [&] {
    const auto lowest = std::min_element(points_.begin(), points_.end(),
                                         [](const Point& a, const Point& b) { return a.y < b.y; });
    line_x_ = lowest->x;
    line_y_ = lowest->y + kNominalSlope * lowest->x;
    slope_ = kNominalSlope;
  };
  if (points_.size() == 1) return use_nominal();

  hull_.clear();
  double mean_x = 0.0;
  for (const Point& p : points_) {
    while (hull_.size() >= 2 && cross(hull_[hull_.size() - 2], hull_.back(), p) <= 0.0) hull_.pop_back();
    hull_.push_back(p);
    mean_x += p.x;
  }
  mean_x /= static_cast<double>(points_.size());
  // The envelope edge over the mean minimises the summed distance to all
  // points while staying below every one of them.
  std::size_t i = 0;
  while (i + 2 < hull_.size() && hull_[i + 1].x < mean_x) ++i;
  const Point& a = hull_[i];
  const Point& b = hull_[i + 1];
  const double sheared_slope = (b.y - a.y) / (b.x - a.x);
  if (!(std::fabs(sheared_slope) <= kNominalSlope * options_.max_skew_ppm * 1e-6)) return use_nominal();
  line_x_ = a.x;
  line_y_ = a.y + kNominalSlope * a.x;
  slope_ = kNominalSlope + sheared_slope;
}

TimeNs ClockSync::to_host_ns(std::uint32_t device_us) const noexcept {
  if (!locked_) return 0;
  const std::int64_t x = unwrap(device_us) - origin_device_us_;
  return wrapping_sub(wrapping_add(origin_host_ns_, to_int64(line_at(static_cast<double>(x)))),
                      options_.min_latency_ns);
}

double ClockSync::skew_ppm() const noexcept { return (kNominalSlope / slope_ - 1.0) * 1e6; }

DurationNs ClockSync::span_ns() const noexcept { return locked_ ? span_ns_ : 0; }

}  // namespace proprio::hid
