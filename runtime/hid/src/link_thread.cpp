#include "proprio/hid/link_thread.hpp"

#include <algorithm>
#include <chrono>

namespace proprio::hid {

void LinkStats::record_clock(const ClockSync& clock) noexcept {
  clock_locked = clock.locked();
  clock_skew_ppm = clock.skew_ppm();
  clock_span_ns = clock.span_ns();
  clock_relocks = clock.stats().relocks;
}

ClockSyncEvent LinkStats::observe_clock(ClockSync& clock, std::uint32_t device_time_us, TimeNs receive_ns) noexcept {
  const ClockSyncEvent event = clock.observe(device_time_us, receive_ns);
  if (event == ClockSyncEvent::tracked) {
    const DurationNs excess = clock.last_excess_latency_ns();
    excess_latency_max_ns = std::max(excess_latency_max_ns, excess);
    excess_latency_sum_ns += static_cast<double>(excess);
    ++excess_latency_count;
  }
  return event;
}

LinkThread::LinkThread(std::unique_ptr<HidTransport> transport, LinkThreadOptions options, const Clock& clock,
                       LinkHandler& handler, LinkStats& stats)
    : transport_(std::move(transport)), options_(options), clock_(clock), handler_(handler), stats_(stats) {
  options_.max_burst = std::max<std::size_t>(options_.max_burst, 1);
}

LinkThread::~LinkThread() { stop(); }

void LinkThread::start() {
  stop_requested_.store(false, std::memory_order_release);
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
}

void LinkThread::stop() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(mutex_);
    stop_requested_.store(true, std::memory_order_release);
  }
  stop_cv_.notify_all();
  thread_.join();
  transport_->close();
  set_state(LinkState::stopped, "stopped");
  running_.store(false, std::memory_order_release);
}

void LinkThread::set_state(LinkState state, std::string_view detail) {
  if (state_.exchange(state, std::memory_order_acq_rel) == state) return;
  stats_.state = state;
  handler_.publish();
  if (state_callback_) state_callback_(state, detail);
}

bool LinkThread::wait_for_stop(DurationNs duration) {
  std::unique_lock lock(mutex_);
  return stop_cv_.wait_for(lock, std::chrono::nanoseconds(duration),
                           [this] { return stop_requested_.load(std::memory_order_acquire); });
}

void LinkThread::lose_link(std::string_view why) {
  ++stats_.disconnects;
  transport_->close();
  handler_.on_link_lost();
  set_state(LinkState::disconnected, why);
  handler_.publish();
}

bool LinkThread::connect() {
  if (state_.load(std::memory_order_acquire) == LinkState::stopped) {
    set_state(LinkState::connecting, transport_->describe());
  }
  if (auto s = transport_->open(); !s) {
    ++stats_.open_failures;
    set_state(LinkState::disconnected, s.error().message);
    return false;
  }
  auto detail = handler_.on_open(*transport_);
  if (!detail) {
    transport_->close();
    set_state(LinkState::disconnected, detail.error().message);
    return false;
  }
  ++stats_.connects;
  set_state(LinkState::streaming, *detail);
  return true;
}

void LinkThread::run() {
  DurationNs backoff = options_.reconnect_backoff_min_ns;
  std::array<std::uint8_t, 256> buf{};  // larger than any report, so a foreign one shows as bad_length
  while (!stop_requested_.load(std::memory_order_acquire)) {
    if (!transport_->is_open()) {
      if (!connect()) {
        handler_.publish();
        if (wait_for_stop(backoff)) break;
        backoff = std::min(backoff * 2, options_.reconnect_backoff_max_ns);
        continue;
      }
      backoff = options_.reconnect_backoff_min_ns;
    }
    if (!handler_.before_read()) continue;
    auto n = transport_->read(buf, options_.read_timeout_ns);
    if (!n) {
      lose_link(n.error().message);
      continue;  // the first reconnect attempt is immediate; later ones back off
    }
    if (*n == 0) {
      handler_.on_silence(clock_.now_ns());
      continue;
    }
    ++stats_.reports_read;
    handler_.on_report(std::span<const std::uint8_t>(buf).first(*n), clock_.now_ns());
    // Whatever else is already waiting belongs to the same backlog: observe it all before mapping times.
    bool lost = false;
    for (std::size_t k = 1; k < options_.max_burst; ++k) {
      auto more = transport_->read(buf, 0);
      if (!more) {
        handler_.end_burst(true);
        lose_link(more.error().message);
        lost = true;
        break;
      }
      if (*more == 0) break;
      ++stats_.reports_read;
      handler_.on_report(std::span<const std::uint8_t>(buf).first(*more), clock_.now_ns());
    }
    if (lost) continue;
    handler_.end_burst(false);
  }
  handler_.on_exit();
}

}  // namespace proprio::hid
