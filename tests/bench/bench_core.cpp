// Hot paths of proprio::core. Run: build/dev/tests/proprio_bench (see docs/benchmarks.md).
#include <benchmark/benchmark.h>

#include <atomic>
#include <thread>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/mailbox.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/random.hpp"

using namespace proprio;

namespace {

HandModel default_model() { return HandModel(*HandShape::from_measurements(0.19, 0.10)); }

HandAngles random_angles(Rng& rng, const JointLimits& lim) {
  HandAngles a;
  for (std::size_t i = 0; i < kHandDofCount; ++i) a[i] = rng.uniform(lim.min_rad[i], lim.max_rad[i]);
  return a;
}

void BM_ForwardKinematics(benchmark::State& state) {
  const HandModel m = default_model();
  Rng rng(1);
  const HandAngles a = random_angles(rng, m.limits());
  const Pose T{so3_exp(Vec3(0.1, 0.2, 0.3)), Vec3(0, 1, -0.4)};
  for (auto _ : state) benchmark::DoNotOptimize(m.forward(Handedness::right, a, T, 0));
}
BENCHMARK(BM_ForwardKinematics);

void BM_InverseKinematics(benchmark::State& state) {
  const HandModel m = default_model();
  Rng rng(2);
  const HandPose p = m.forward(Handedness::left, random_angles(rng, m.limits()), Pose::identity(), 0);
  for (auto _ : state) benchmark::DoNotOptimize(m.inverse(p));
}
BENCHMARK(BM_InverseKinematics);

void BM_PoseHistoryInterpolate(benchmark::State& state) {
  const HandModel m = default_model();
  PoseHistory h;
  Rng rng(3);
  for (int k = 0; k < 256; ++k) {
    (void)h.push(m.forward(Handedness::right, random_angles(rng, m.limits()), Pose::identity(), TimeNs{k} * 11'111'111));
  }
  TimeNs t = h.oldest_time_ns() + 5'000'000;
  for (auto _ : state) {
    benchmark::DoNotOptimize(h.query(t));
    t += 1'000'003;
    if (t >= h.newest_time_ns()) t = h.oldest_time_ns() + 5'000'000;
  }
}
BENCHMARK(BM_PoseHistoryInterpolate);

void BM_PoseHistoryPredict(benchmark::State& state) {
  const HandModel m = default_model();
  PoseHistory h;
  Rng rng(4);
  for (int k = 0; k < 16; ++k) {
    (void)h.push(m.forward(Handedness::right, random_angles(rng, m.limits()), Pose::identity(), TimeNs{k} * 11'111'111));
  }
  const TimeNs t = h.newest_time_ns() + 20'000'000;
  for (auto _ : state) benchmark::DoNotOptimize(h.query(t));
}
BENCHMARK(BM_PoseHistoryPredict);

void BM_MailboxPublishRead(benchmark::State& state) {
  Mailbox<HandPose> box;
  HandPose p;
  for (auto _ : state) {
    box.publish(p);
    benchmark::DoNotOptimize(box.read());
  }
}
BENCHMARK(BM_MailboxPublishRead);

// Consumer cost while another thread publishes HandPoses continuously.
void BM_MailboxReadUnderContention(benchmark::State& state) {
  Mailbox<HandPose> box;
  std::atomic<bool> stop{false};
  std::thread producer([&] {
    HandPose p;
    while (!stop.load(std::memory_order_relaxed)) {
      p.time_ns++;
      box.publish(p);
    }
  });
  HandPose out;
  for (auto _ : state) benchmark::DoNotOptimize(box.fetch(out));
  stop = true;
  producer.join();
}
BENCHMARK(BM_MailboxReadUnderContention)->UseRealTime();

}  // namespace
