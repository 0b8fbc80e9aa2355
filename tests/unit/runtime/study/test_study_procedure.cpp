// Adaptive procedures converge where theory says, on simulated observers with
// known psychometric functions.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "proprio/study/procedure.hpp"
#include "study/simulated_observer.hpp"

namespace proprio::study {
namespace {

using testing::SimulatedObserver;

// Runs `runs` independent staircases and returns the proportion correct the
// observer has at the mean of their reversal estimates.
double staircase_convergence(int up, int down, double up_ratio, int runs, int trials) {
  SimulatedObserver obs;  // 2AFC Weibull, alpha 5, beta 3
  double sum = 0.0;
  int used = 0;
  for (int r = 0; r < runs; ++r) {
    StaircaseSettings s;
    s.start = 9.0;
    s.up = up;
    s.down = down;
    s.up_ratio = up_ratio;
    s.steps = {1.0, 0.5, 0.2};  // small final steps relative to the function's spread (~3 units)
    s.min = 0.1;
    s.max = 20.0;
    s.max_trials = trials;
    s.discard_reversals = 4;
    Staircase sc(s);
    Rng unused(0);
    obs.seed = mix_seed(77, static_cast<std::uint64_t>(r));
    for (int t = 0; !sc.finished(); ++t) {
      const StimulusRequest q = sc.next(unused);
      sc.record(q, obs.respond(q.stimulus, static_cast<std::uint64_t>(t)));
    }
    const ProcedureEstimate e = sc.estimate();
    if (e.reversals > s.discard_reversals) {
      sum += e.threshold;
      ++used;
    }
  }
  EXPECT_GT(used, runs * 9 / 10);
  return psi(obs.model, obs.params, sum / used);
}

TEST(Staircase, OneUpTwoDownConvergesOn70Point7Percent) {
  EXPECT_NEAR(transformed_target(2), 0.70711, 1e-5);
  const double p = staircase_convergence(1, 2, 1.0, 300, 120);
  std::printf("1-up-2-down: observer's p(correct) at the mean estimate = %.4f (theory 0.7071)\n", p);
  EXPECT_NEAR(p, 0.7071, 0.02);
}

TEST(Staircase, OneUpThreeDownConvergesOn79Point4Percent) {
  EXPECT_NEAR(transformed_target(3), 0.79370, 1e-5);
  const double p = staircase_convergence(1, 3, 1.0, 300, 150);
  std::printf("1-up-3-down: observer's p(correct) at the mean estimate = %.4f (theory 0.7937)\n", p);
  EXPECT_NEAR(p, 0.7937, 0.02);
}

TEST(Staircase, WeightedUpDownConvergesOnItsTarget) {
  // Kaernbach: 1-up-1-down with step_up / step_down = 0.75 / 0.25 = 3.
  EXPECT_DOUBLE_EQ(weighted_up_ratio(0.75), 3.0);
  const double p = staircase_convergence(1, 1, weighted_up_ratio(0.75), 300, 120);
  std::printf("weighted up/down (target 0.75): p(correct) at the mean estimate = %.4f\n", p);
  EXPECT_NEAR(p, 0.75, 0.02);
}

TEST(Staircase, StepsReversalsAndBoundsFollowTheRules) {
  StaircaseSettings s;
  s.start = 5.0;
  s.down = 2;
  s.steps = {1.0, 0.5};
  s.min = 3.5;
  s.max = 6.0;
  s.max_trials = 100;
  s.max_reversals = 3;
  s.discard_reversals = 0;
  Staircase sc(s);
  Rng rng(0);
  auto answer = [&](bool c) { sc.record(sc.next(rng), c); };
  answer(true);
  EXPECT_EQ(sc.current(), 5.0);  // one correct: no step yet
  answer(true);
  EXPECT_EQ(sc.current(), 4.0);  // two correct: down by the first step
  answer(false);
  EXPECT_EQ(sc.current(), 4.5);  // reversal at 4.0, then the second step size
  ASSERT_EQ(sc.reversal_levels().size(), 1u);
  EXPECT_EQ(sc.reversal_levels()[0], 4.0);
  answer(false);
  answer(false);
  answer(false);
  EXPECT_EQ(sc.current(), 6.0);  // clamped at max
  answer(true);
  answer(true);
  EXPECT_EQ(sc.current(), 5.5);  // reversal 2
  answer(false);                  // reversal 3: finished
  EXPECT_TRUE(sc.finished());
  EXPECT_EQ(sc.estimate().reversals, 3);
  EXPECT_NEAR(sc.estimate().threshold, (4.0 + 6.0 + 5.5) / 3.0, 1e-12);
}

TEST(Quest, ConvergesOnAKnownThreshold) {
  SimulatedObserver obs;
  obs.params = {5.0, 3.5, 0.5, 0.01};
  const double truth = obs.threshold(0.75);
  QuestSettings q;
  q.beta = 3.5;
  q.lapse = 0.01;
  q.target = 0.75;
  q.prior_mean = 7.0;  // a deliberately wrong start
  q.prior_sd = 3.0;
  q.grid_min = 0.5;
  q.grid_max = 15.0;
  q.grid_points = 300;
  q.max_trials = 80;
  double sum = 0.0;
  int within_2sd = 0;
  const int runs = 60;
  for (int r = 0; r < runs; ++r) {
    Quest quest(q);
    Rng unused(0);
    obs.seed = mix_seed(5, static_cast<std::uint64_t>(r));
    for (int t = 0; !quest.finished(); ++t) {
      const StimulusRequest req = quest.next(unused);
      quest.record(req, obs.respond(req.stimulus, static_cast<std::uint64_t>(t)));
    }
    const ProcedureEstimate e = quest.estimate();
    sum += e.threshold;
    within_2sd += std::abs(e.threshold - truth) <= 2.0 * e.sd ? 1 : 0;
  }
  std::printf("QUEST: mean estimate %.3f (truth %.3f); %d of %d within 2 posterior SDs\n", sum / runs, truth,
              within_2sd, runs);
  EXPECT_NEAR(sum / runs, truth, 0.05 * truth);
  EXPECT_GE(within_2sd, runs * 85 / 100);
}

TEST(Interleaved, AlternatesRandomlyAndReplaysTheSameChoices) {
  StaircaseSettings a;
  a.start = 8.0;
  a.max_trials = 10;
  StaircaseSettings b = a;
  b.start = 1.0;
  auto make = [&] {
    std::vector<std::unique_ptr<Procedure>> tracks;
    tracks.push_back(std::make_unique<Staircase>(a));
    tracks.push_back(std::make_unique<Staircase>(b));
    return Interleaved(std::move(tracks));
  };
  Interleaved first = make(), second = make();
  int per_track[2] = {0, 0};
  for (int t = 0; t < 20; ++t) {
    Rng r1(mix_seed(3, static_cast<std::uint64_t>(t))), r2(mix_seed(3, static_cast<std::uint64_t>(t)));
    const StimulusRequest q1 = first.next(r1), q2 = second.next(r2);
    EXPECT_EQ(q1.track, q2.track);
    EXPECT_EQ(q1.stimulus, q2.stimulus);
    ++per_track[q1.track];
    first.record(q1, t % 3 != 0);
    second.record(q2, t % 3 != 0);
  }
  // 10 trials each: a finished track is no longer chosen.
  EXPECT_EQ(per_track[0], 10);
  EXPECT_EQ(per_track[1], 10);
  EXPECT_TRUE(first.finished());
}

}  // namespace
}  // namespace proprio::study
