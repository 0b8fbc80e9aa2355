#pragma once
// Where an input driver's decoded samples go: to a callback when one is set
// (it runs on the link thread and must be quick), else into a bounded ring
// that one consumer thread pops, every sample in order.
#include <cstddef>
#include <functional>
#include <utility>

#include "proprio/hid/spsc_ring.hpp"

namespace proprio::hid {

template <typename Sample>
class SampleOutlet {
 public:
  using Callback = std::function<void(const Sample&)>;

  explicit SampleOutlet(std::size_t capacity) : ring_(capacity) {}

  // Before the link thread starts.
  void set_callback(Callback callback) { callback_ = std::move(callback); }
  // Link thread. False when the ring was full: the sample is dropped (count it).
  bool deliver(const Sample& sample) {
    if (callback_) {
      callback_(sample);
      return true;
    }
    return ring_.try_push(sample);
  }
  // Consumer thread (one).
  bool pop(Sample& out) { return ring_.try_pop(out); }

 private:
  Callback callback_;
  SpscRing<Sample> ring_;
};

}  // namespace proprio::hid
