#pragma once
// EmulatorServer: the device's end of a FakeHidLink, for any device emulator
// that runs on time (the stretch board, the fingertip devices). A thread runs
// the emulator in step with the link's clock (emulator time 0 = when start()
// was called) and queues its reports on the link, each delayed by a latency
// floor plus a seeded uniform jitter; host commands and feature reads reach
// the emulator through the link's handlers. The link's own faults (unplug,
// drop, duplicate, corrupt, reorder) apply on top: while the cable is out,
// commands cannot arrive, as on a real bus.
//
// The device supplies Traits:
//   using Emulator = ...;  // has stats()
//   using Options = ...;   // has latency_min_ns, latency_jitter_ns, pump_interval_ns, seed
//   using Report = ...;    // has bytes and send_ns (emulator time)
//   // Runs the emulator up to emulator time now_ns (plus any lookahead the
//   // device wants), appending the reports it sent.
//   static void advance(Emulator&, const Options&, TimeNs now_ns, std::vector<Report>& out);
//   static void handle_command(Emulator&, std::span<const std::uint8_t> bytes, TimeNs now_ns);
//   // Fills out (report ID first) and returns the length, or 0 for "no such report".
//   static std::size_t feature(Emulator&, std::uint8_t report_id, TimeNs now_ns, std::span<std::uint8_t> out);
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/hid_transport.hpp"

namespace proprio::hid {

template <typename Traits>
class EmulatorServer {
 public:
  using Emulator = typename Traits::Emulator;
  using Options = typename Traits::Options;
  using Report = typename Traits::Report;
  using Stats = std::decay_t<decltype(std::declval<const Emulator&>().stats())>;

  EmulatorServer(Emulator emulator, std::shared_ptr<FakeHidLink> link, Options options = {},
                 const Clock& clock = MonotonicClock::instance())
      : state_(std::make_shared<State>(std::move(emulator), options, clock)), link_(std::move(link)) {
    // The link outlives every call of its handlers (the transport holds it), so a plain pointer does.
    FakeHidLink* raw_link = link_.get();
    std::shared_ptr<State> state = state_;
    link_->set_write_handler([state, raw_link](std::span<const std::uint8_t> bytes) {
      std::lock_guard lock(state->mutex);
      // The device ran up to the instant the command arrives (everything it
      // sent before was made under the old configuration).
      pump_locked(*state, *raw_link);
      Traits::handle_command(state->emulator, bytes, state->emulator_now());
    });
    link_->set_feature_handler([state](std::uint8_t id, std::span<std::uint8_t> out) -> std::size_t {
      std::lock_guard lock(state->mutex);
      return Traits::feature(state->emulator, id, state->emulator_now(), out);
    });
  }
  ~EmulatorServer() {  // stops and detaches from the link
    stop();
    link_->set_write_handler({});
    link_->set_feature_handler({});
  }
  EmulatorServer(const EmulatorServer&) = delete;
  EmulatorServer& operator=(const EmulatorServer&) = delete;

  // Sets time zero to now and starts the pumping thread (once).
  void start() {
    {
      std::lock_guard lock(state_->mutex);
      if (state_->started) return;
      state_->t0 = state_->clock.now_ns();
      state_->started = true;
    }
    {
      std::lock_guard lock(thread_mutex_);
      stop_requested_ = false;
    }
    thread_ = std::thread([this] {
      const auto interval = std::chrono::nanoseconds(std::max<DurationNs>(state_->options.pump_interval_ns, 100'000));
      std::unique_lock lock(thread_mutex_);
      while (!stop_requested_) {
        lock.unlock();
        pump();
        lock.lock();
        stop_cv_.wait_for(lock, interval, [this] { return stop_requested_; });
      }
    });
  }
  void stop() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard lock(thread_mutex_);
      stop_requested_ = true;
    }
    stop_cv_.notify_all();
    thread_.join();
  }
  // Runs the emulator up to now and queues its reports; the thread calls it,
  // and so may a test that drives a ManualClock itself.
  void pump() {
    std::lock_guard lock(state_->mutex);
    pump_locked(*state_, *link_);
  }
  TimeNs time_zero_ns() const {
    std::lock_guard lock(state_->mutex);
    return state_->t0;
  }
  // A copy of the emulator's statistics.
  Stats emulator_stats() const {
    std::lock_guard lock(state_->mutex);
    return state_->emulator.stats();
  }
  // Anything else, read or changed under the emulator's lock.
  template <typename F>
  auto with_emulator(F&& f) const {
    std::lock_guard lock(state_->mutex);
    return f(static_cast<const Emulator&>(state_->emulator));
  }
  template <typename F>
  auto modify_emulator(F&& f) {
    std::lock_guard lock(state_->mutex);
    return f(state_->emulator);
  }

 private:
  // Shared with the link's handlers, which a reader thread may be running
  // while this object goes away. Everything in it is used under its mutex.
  struct State {
    State(Emulator e, Options o, const Clock& c)
        : emulator(std::move(e)), options(o), clock(c), latency_rng(o.seed) {}
    // Until start() the emulator stays at time 0: t0 means nothing yet.
    TimeNs emulator_now() const { return started ? clock.now_ns() - t0 : 0; }
    mutable std::mutex mutex;
    Emulator emulator;
    Options options;
    const Clock& clock;
    Rng latency_rng;
    bool started = false;
    TimeNs t0 = 0;
    TimeNs last_release_ns = 0;
    std::vector<Report> out;
  };
  static void pump_locked(State& state, FakeHidLink& link) {
    if (!state.started) return;
    state.out.clear();
    Traits::advance(state.emulator, state.options, state.clock.now_ns() - state.t0, state.out);
    for (const Report& r : state.out) {
      const DurationNs jitter = state.options.latency_jitter_ns > 0
                                    ? static_cast<DurationNs>(state.latency_rng.below(
                                          static_cast<std::uint64_t>(state.options.latency_jitter_ns) + 1))
                                    : 0;
      // A device's reports leave through one FIFO: a later report's jitter can
      // delay it but never overtake an earlier one (that is the link's reorder
      // fault, drawn on its own). Without this a restart's first report, sent
      // microseconds after the old stream's last, could arrive before it.
      state.last_release_ns =
          std::max(state.last_release_ns, state.t0 + r.send_ns + state.options.latency_min_ns + jitter);
      link.push(r.bytes, state.last_release_ns);
    }
  }

  std::shared_ptr<State> state_;
  std::shared_ptr<FakeHidLink> link_;
  std::mutex thread_mutex_;
  std::condition_variable stop_cv_;
  bool stop_requested_ = false;
  std::thread thread_;
};

}  // namespace proprio::hid
