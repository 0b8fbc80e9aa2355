#pragma once
// Latest-value mailbox between two threads (one producer, one consumer): a
// lock-free triple buffer. The producer never waits for the consumer and the
// consumer always sees the newest complete value; intermediate values may be
// skipped, which is what a 1 kHz haptics loop reading a 90 Hz tracker wants.
#include <array>
#include <atomic>
#include <cstdint>

namespace proprio {

template <typename T>
class Mailbox {
 public:
  Mailbox() = default;
  Mailbox(const Mailbox&) = delete;
  Mailbox& operator=(const Mailbox&) = delete;

  // Producer thread only.
  void publish(const T& value) {
    slots_[back_].value = value;
    const std::uint8_t previous = middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh),
                                                   std::memory_order_acq_rel);
    back_ = previous & kIndexMask;
  }

  // Consumer thread only. Returns the newest published value, or nullptr if
  // nothing has been published yet. The pointer stays valid until the next
  // read() on this thread.
  const T* read() {
    if (middle_.load(std::memory_order_relaxed) & kFresh) {
      const std::uint8_t previous = middle_.exchange(front_, std::memory_order_acq_rel);
      front_ = previous & kIndexMask;
      has_value_ = true;
    }
    return has_value_ ? &slots_[front_].value : nullptr;
  }

  // Consumer thread only: copies the newest value into out if one arrived
  // since the last read/fetch; returns whether it did.
  bool fetch(T& out) {
    if (!(middle_.load(std::memory_order_relaxed) & kFresh)) return false;
    out = *read();
    return true;
  }

 private:
  static constexpr std::uint8_t kIndexMask = 0x3;
  static constexpr std::uint8_t kFresh = 0x4;

  // Each slot on its own cache line so producer and consumer do not false-share.
  struct alignas(64) Slot {
    T value{};
  };
  std::array<Slot, 3> slots_{};
  alignas(64) std::atomic<std::uint8_t> middle_{1};
  alignas(64) std::uint8_t back_ = 0;  // producer-owned
  alignas(64) std::uint8_t front_ = 2;  // consumer-owned
  bool has_value_ = false;              // consumer-owned
};

}  // namespace proprio
