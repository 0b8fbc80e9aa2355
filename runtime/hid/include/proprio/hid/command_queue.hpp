#pragma once
// Commands any thread queues for a driver's link thread to send, in order.
// The link thread checks an atomic flag before taking the lock, so a report
// costs no lock while nothing is queued.
#include <atomic>
#include <mutex>
#include <vector>

namespace proprio::hid {

template <typename Command>
class CommandQueue {
 public:
  // Any thread.
  void push(const Command& command) {
    std::lock_guard lock(mutex_);
    pending_.push_back(command);
    pending_flag_.store(true, std::memory_order_release);
  }
  // Link thread: everything queued so far, oldest first (empty when nothing is).
  std::vector<Command> take() {
    std::vector<Command> out;
    if (!pending_flag_.load(std::memory_order_acquire)) return out;
    std::lock_guard lock(mutex_);
    out.swap(pending_);
    pending_flag_.store(false, std::memory_order_relaxed);
    return out;
  }

 private:
  std::mutex mutex_;
  std::vector<Command> pending_;
  std::atomic<bool> pending_flag_{false};
};

}  // namespace proprio::hid
