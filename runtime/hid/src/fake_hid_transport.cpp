// FakeHidLink / FakeHidTransport: an in-memory HID device for tests.
#include <algorithm>
#include <chrono>

#include "proprio/hid/hid_transport.hpp"

namespace proprio::hid {

FakeHidLink::FakeHidLink(const Clock& clock, FakeHidFaults faults)
    : clock_(clock),
      faults_(faults),
      drop_rng_(mix_seed(faults.seed, 1)),
      duplicate_rng_(mix_seed(faults.seed, 2)),
      corrupt_rng_(mix_seed(faults.seed, 3)),
      reorder_rng_(mix_seed(faults.seed, 4)) {}

void FakeHidLink::enqueue(Entry entry) {
  // Keep release order so that a late push with an early release time cannot
  // block the queue behind later reports.
  auto it = std::upper_bound(queue_.begin(), queue_.end(), entry.release_ns,
                             [](TimeNs t, const Entry& e) { return t < e.release_ns; });
  queue_.insert(it, std::move(entry));
}

void FakeHidLink::push(std::span<const std::uint8_t> report, TimeNs release_ns) {
  {
    std::lock_guard lock(mutex_);
    ++stats_.pushed;
    // One draw per report from each stream, whatever the outcome, so that the
    // faults stay independent of each other.
    const bool drop = drop_rng_.uniform01() < faults_.drop_probability;
    const bool duplicate = duplicate_rng_.uniform01() < faults_.duplicate_probability;
    const bool corrupt = corrupt_rng_.uniform01() < faults_.corrupt_probability;
    const bool reorder = reorder_rng_.uniform01() < faults_.reorder_probability;
    const std::uint64_t at = report.empty() ? 0 : corrupt_rng_.below(report.size());
    const std::uint64_t bit = corrupt_rng_.below(8);
    if (drop) {
      ++stats_.dropped;
      return;
    }
    Entry e{release_ns, {report.begin(), report.end()}};
    if (corrupt && !e.bytes.empty()) {
      e.bytes[at] ^= static_cast<std::uint8_t>(1u << bit);
      ++stats_.corrupted;
    }
    if (reorder && held_.empty()) {
      held_.push_back(std::move(e));
      ++stats_.reordered;
      return;
    }
    if (duplicate) {
      enqueue(e);
      ++stats_.duplicated;
    }
    enqueue(e);
    if (!held_.empty()) {
      held_.front().release_ns = release_ns;
      enqueue(std::move(held_.front()));
      held_.clear();
    }
  }
  cv_.notify_all();
}

void FakeHidLink::flush() {
  {
    std::lock_guard lock(mutex_);
    if (held_.empty()) return;
    enqueue(std::move(held_.front()));
    held_.clear();
  }
  cv_.notify_all();
}

void FakeHidLink::schedule_unplug(TimeNs at_ns, DurationNs duration_ns) {
  {
    std::lock_guard lock(mutex_);
    outages_.push_back({at_ns, at_ns + std::max<DurationNs>(duration_ns, 0)});
  }
  cv_.notify_all();
}

bool FakeHidLink::unplugged_at(TimeNs t) const {
  return std::any_of(outages_.begin(), outages_.end(), [t](const Outage& o) { return t >= o.at_ns && t < o.until_ns; });
}

bool FakeHidLink::outage_since(TimeNs opened_ns, TimeNs now) const {
  return std::any_of(outages_.begin(), outages_.end(),
                     [&](const Outage& o) { return o.at_ns > opened_ns && o.at_ns <= now; });
}

bool FakeHidLink::plugged() const {
  std::lock_guard lock(mutex_);
  return !unplugged_at(clock_.now_ns());
}

void FakeHidLink::set_write_handler(std::function<void(std::span<const std::uint8_t>)> handler) {
  std::lock_guard lock(mutex_);
  write_handler_ = std::move(handler);
}

void FakeHidLink::set_feature_handler(std::function<std::size_t(std::uint8_t, std::span<std::uint8_t>)> handler) {
  std::lock_guard lock(mutex_);
  feature_handler_ = std::move(handler);
}

std::vector<std::vector<std::uint8_t>> FakeHidLink::writes() const {
  std::lock_guard lock(mutex_);
  return writes_;
}

std::size_t FakeHidLink::pending() const {
  std::lock_guard lock(mutex_);
  return queue_.size() + held_.size();
}

FakeHidLinkStats FakeHidLink::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

FakeHidTransport::FakeHidTransport(std::shared_ptr<FakeHidLink> link) : link_(std::move(link)) {}

Status FakeHidTransport::open() {
  if (open_) return {};
  std::lock_guard lock(link_->mutex_);
  const TimeNs now = link_->clock_.now_ns();
  if (link_->unplugged_at(now)) {
    ++link_->stats_.failed_opens;
    return make_error(Errc::not_found, "fake HID device is unplugged");
  }
  ++link_->stats_.opens;
  open_ = true;
  opened_ns_ = now;
  return {};
}

void FakeHidTransport::close() noexcept { open_ = false; }

Status FakeHidTransport::check_alive() {
  if (!open_) return make_error(Errc::unavailable, "fake HID device is not open");
  const TimeNs now = link_->clock_.now_ns();
  if (link_->unplugged_at(now) || link_->outage_since(opened_ns_, now)) {
    open_ = false;
    ++link_->stats_.read_errors;
    return make_error(Errc::unavailable, "fake HID device was unplugged");
  }
  return {};
}

Result<std::size_t> FakeHidTransport::read(std::span<std::uint8_t> buffer, DurationNs timeout) {
  FakeHidLink& l = *link_;
  std::unique_lock lock(l.mutex_);
  // Time runs on the link's clock, but waiting is bounded in real time as
  // well, so a clock that does not move (ManualClock) cannot hang a reader.
  const auto real_deadline = std::chrono::steady_clock::now() + std::chrono::nanoseconds(std::max<DurationNs>(timeout, 0));
  const TimeNs deadline = l.clock_.now_ns() + std::max<DurationNs>(timeout, 0);
  for (;;) {
    if (auto s = check_alive(); !s) return s.error();
    const TimeNs now = l.clock_.now_ns();
    // Reports that fell due while the cable was out never arrive.
    while (!l.queue_.empty() && l.queue_.front().release_ns <= now && l.unplugged_at(l.queue_.front().release_ns)) {
      l.queue_.pop_front();
      ++l.stats_.lost_unplugged;
    }
    if (!l.queue_.empty() && l.queue_.front().release_ns <= now) {
      const auto& bytes = l.queue_.front().bytes;
      const std::size_t n = std::min(bytes.size(), buffer.size());
      std::copy_n(bytes.begin(), n, buffer.begin());
      l.queue_.pop_front();
      ++l.stats_.delivered;
      return n;
    }
    if (now >= deadline || std::chrono::steady_clock::now() >= real_deadline) return std::size_t{0};
    // Sleep until the next thing that can change the answer: the next report
    // falls due, a cable event, the deadline, or a push (notify).
    TimeNs wake = deadline;
    if (!l.queue_.empty()) wake = std::min(wake, l.queue_.front().release_ns);
    for (const auto& o : l.outages_) {
      if (o.at_ns > now) wake = std::min(wake, o.at_ns);
    }
    const auto wait = std::chrono::nanoseconds(std::max<TimeNs>(wake - now, 100'000));
    l.cv_.wait_until(lock, std::min(std::chrono::steady_clock::now() + wait, real_deadline));
  }
}

Status FakeHidTransport::write(std::span<const std::uint8_t> report) {
  std::function<void(std::span<const std::uint8_t>)> handler;
  {
    std::lock_guard lock(link_->mutex_);
    if (auto s = check_alive(); !s) return s;
    link_->writes_.emplace_back(report.begin(), report.end());
    ++link_->stats_.writes;
    handler = link_->write_handler_;
  }
  if (handler) handler(report);
  return {};
}

Result<std::size_t> FakeHidTransport::get_feature(std::uint8_t report_id, std::span<std::uint8_t> buffer) {
  std::function<std::size_t(std::uint8_t, std::span<std::uint8_t>)> handler;
  {
    std::lock_guard lock(link_->mutex_);
    if (auto s = check_alive(); !s) return s.error();
    handler = link_->feature_handler_;
  }
  const std::size_t n = handler ? handler(report_id, buffer) : 0;
  if (n == 0) return make_error(Errc::io_error, "fake HID device has no feature report " + std::to_string(report_id));
  return n;
}

}  // namespace proprio::hid
