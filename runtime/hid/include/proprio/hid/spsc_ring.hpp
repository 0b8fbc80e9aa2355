#pragma once
// Bounded single-producer/single-consumer ring of values: every value the
// producer pushes reaches the consumer in order, unless the ring is full, in
// which case try_push refuses and the producer counts the loss. Where the
// Mailbox (latest value only) fits a pose, a sample stream needs every
// sample: an IMU filter integrates all of them. Lock-free, no allocation after
// construction.
#include <atomic>
#include <cstddef>
#include <vector>

namespace proprio::hid {

template <typename T>
class SpscRing {
 public:
  // Capacity is rounded up to a power of two (at least 2).
  explicit SpscRing(std::size_t capacity) : slots_(round_up(capacity)), mask_(slots_.size() - 1) {}
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  // Producer thread only. False when full (the value is not stored).
  bool try_push(const T& value) {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) > mask_) return false;
    slots_[head & mask_] = value;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer thread only. False when empty.
  bool try_pop(T& out) {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_.load(std::memory_order_acquire)) return false;
    out = slots_[tail & mask_];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  // Either thread; exact only when the other side is idle.
  std::size_t size() const noexcept {
    return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
  }
  std::size_t capacity() const noexcept { return slots_.size(); }

 private:
  static std::size_t round_up(std::size_t n) {
    std::size_t c = 2;
    while (c < n) c <<= 1;
    return c;
  }
  std::vector<T> slots_;
  std::size_t mask_;
  // Producer and consumer indices on separate cache lines so the two threads do not false-share.
  alignas(64) std::atomic<std::size_t> head_{0};  // next slot to write; written by the producer
  alignas(64) std::atomic<std::size_t> tail_{0};  // next slot to read; written by the consumer
};

}  // namespace proprio::hid
