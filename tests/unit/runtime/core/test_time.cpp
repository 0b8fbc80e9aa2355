#include <gtest/gtest.h>

#include <thread>

#include "proprio/core/time.hpp"

using namespace proprio;

TEST(Time, SecondsNanosecondsRoundTripExactlyOnRateGrids) {
  EXPECT_EQ(seconds_to_ns(1.0 / 90.0), 11'111'111);
  EXPECT_EQ(seconds_to_ns(0.9999999996e-9), 1);  // rounds, does not truncate
  EXPECT_EQ(seconds_to_ns(0.001), 1'000'000);
  EXPECT_EQ(seconds_to_ns(-0.5), -500'000'000);
  EXPECT_DOUBLE_EQ(ns_to_seconds(2'500'000'000), 2.5);
}

TEST(Time, MonotonicClockNeverGoesBackwards) {
  auto& clock = MonotonicClock::instance();
  TimeNs previous = clock.now_ns();
  for (int i = 0; i < 10000; ++i) {
    const TimeNs now = clock.now_ns();
    ASSERT_GE(now, previous);
    previous = now;
  }
  EXPECT_GT(previous, 0);
}

TEST(ManualClock, MovesOnlyWhenToldEvenAcrossThreads) {
  ManualClock clock(100);
  EXPECT_EQ(clock.now_ns(), 100);
  clock.advance(50);
  EXPECT_EQ(clock.now_ns(), 150);
  std::thread t([&] {
    for (int i = 0; i < 1000; ++i) clock.advance(1);
  });
  for (int i = 0; i < 1000; ++i) clock.advance(1);
  t.join();
  EXPECT_EQ(clock.now_ns(), 2150);
  clock.set(7);
  EXPECT_EQ(clock.now_ns(), 7);
}
