#pragma once
// The reader-thread plumbing every board driver's LinkHandler shares (IMU
// glove board, stretch board, FTM board): the link options a driver's own
// options name, sending queued commands, asking a silent board to stream
// again, and publishing statistics to the consumer. Small pieces rather than
// a driver base class: the drivers differ in how they decode and deliver, and
// those parts stay theirs.
#include <cstddef>
#include <cstdint>

#include "proprio/core/log.hpp"
#include "proprio/core/mailbox.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/clock_sync.hpp"
#include "proprio/hid/command_queue.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/hid/link_thread.hpp"

namespace proprio::hid {

// The link thread's options from a driver's options, which carry the same
// three fields under the same names.
template <typename DeviceOptions>
LinkThreadOptions link_options_of(const DeviceOptions& o, std::size_t max_burst) {
  LinkThreadOptions l;
  l.read_timeout_ns = o.read_timeout_ns;
  l.reconnect_backoff_min_ns = o.reconnect_backoff_min_ns;
  l.reconnect_backoff_max_ns = o.reconnect_backoff_max_ns;
  l.max_burst = max_burst;
  return l;
}

// Link thread: writes every queued command, oldest first. A failed write is
// counted and logged but does not close the link: the read that follows says
// whether the device is still there. device names it in the log ("FTM board").
template <typename Command, typename Encode>
void send_queued_commands(CommandQueue<Command>& queue, HidTransport& transport, LinkStats& stats, Encode encode,
                          const char* device) {
  for (const Command& c : queue.take()) {
    if (auto s = transport.write(encode(c)); !s) {
      ++stats.write_failures;
      logger().warn("{}: sending command {} failed: {}", device, static_cast<int>(c.op), s.error().message);
    }
  }
}

// A board whose link stays up but whose stream stopped (firmware that missed
// a START, or stopped after a host hiccup) is asked to start again after each
// silence of restart_after_ns; 0 never asks.
class SilenceRestart {
 public:
  // Link thread: the link opened or data arrived at t.
  void saw_data(TimeNs t_ns) noexcept { last_data_ns_ = t_ns; }
  // Link thread, from LinkHandler::on_silence: sends the board's
  // start_streaming Command (encoded by encode, a fresh token each time); a
  // sent one counts in restart_commands.
  template <typename Command, typename Encode>
  void on_silence(TimeNs now_ns, DurationNs restart_after_ns, HidTransport& transport, Encode encode, LinkStats& stats,
                  std::uint64_t& restart_commands) {
    if (restart_after_ns <= 0 || now_ns - last_data_ns_ < restart_after_ns) return;
    Command start;
    start.op = decltype(start.op)::start_streaming;
    start.token = next_token_++;
    if (auto s = transport.write(encode(start)); !s) {
      ++stats.write_failures;
    } else {
      ++restart_commands;
    }
    last_data_ns_ = now_ns;  // give the board another silence period before asking again
  }

 private:
  TimeNs last_data_ns_ = 0;
  std::uint8_t next_token_ = 1;
};

// A driver's statistics (LinkStats and its own fields) from the link thread
// to one consumer thread, the clock fields filled in on the way.
template <typename Stats>
class PublishedStats {
 public:
  // Link thread.
  void publish(Stats& stats, const ClockSync& clock) {
    stats.record_clock(clock);
    mailbox_.publish(stats);
  }
  // Consumer thread (one): the newest published, or what it last saw.
  Stats newest() {
    if (const Stats* n = mailbox_.read()) copy_ = *n;
    return copy_;
  }

 private:
  Mailbox<Stats> mailbox_;
  Stats copy_;
};

// Keeps one stream's delivered host times strictly increasing: a time that
// would not come after the previous one (the clock estimate improved by more
// than a period, which happens only just after a lock) is placed 1 µs after
// it instead, and counted.
class StrictlyIncreasing {
 public:
  TimeNs place(TimeNs t_ns, std::uint64_t& clamps) noexcept {
    if (any_ && t_ns <= last_ns_) {
      t_ns = last_ns_ + 1000;
      ++clamps;
    }
    any_ = true;
    last_ns_ = t_ns;
    return t_ns;
  }

 private:
  bool any_ = false;
  TimeNs last_ns_ = 0;
};

}  // namespace proprio::hid
