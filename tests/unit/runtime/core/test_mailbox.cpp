#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <thread>

#include "proprio/core/mailbox.hpp"

using namespace proprio;

TEST(Mailbox, EmptyUntilFirstPublishThenLatestWins) {
  Mailbox<int> box;
  EXPECT_EQ(box.read(), nullptr);
  int out = -1;
  EXPECT_FALSE(box.fetch(out));
  box.publish(1);
  box.publish(2);
  box.publish(3);
  ASSERT_NE(box.read(), nullptr);
  EXPECT_EQ(*box.read(), 3);
  EXPECT_FALSE(box.fetch(out)) << "no new value since the last read";
  box.publish(4);
  EXPECT_TRUE(box.fetch(out));
  EXPECT_EQ(out, 4);
}

// A value that is only consistent if copied whole: a torn read would mix
// elements of two different publishes.
struct Payload {
  std::array<std::uint64_t, 64> words{};
  bool consistent() const {
    for (auto w : words) {
      if (w != words[0]) return false;
    }
    return true;
  }
};

TEST(Mailbox, TwoThreadsNeverSeeTornOrOlderValues) {
  Mailbox<Payload> box;
  constexpr std::uint64_t kCount = 200000;
  std::atomic<bool> done{false};
  std::thread producer([&] {
    Payload p;
    for (std::uint64_t i = 1; i <= kCount; ++i) {
      p.words.fill(i);
      box.publish(p);
    }
    done.store(true, std::memory_order_release);
  });
  std::uint64_t last_seen = 0;
  std::uint64_t reads = 0;
  bool torn = false, went_back = false;
  while (true) {
    const bool finished = done.load(std::memory_order_acquire);
    if (const Payload* p = box.read()) {
      ++reads;
      torn |= !p->consistent();
      went_back |= p->words[0] < last_seen;
      last_seen = p->words[0];
    }
    if (finished) break;
  }
  producer.join();
  // After the producer finished, the consumer must converge on the final value.
  ASSERT_NE(box.read(), nullptr);
  EXPECT_EQ(box.read()->words[0], kCount);
  EXPECT_FALSE(torn);
  EXPECT_FALSE(went_back);
  EXPECT_GT(reads, 0u);
}
