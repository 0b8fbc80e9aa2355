// Design files, counterbalancing and seeded trial plans.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

#include "proprio/core/random.hpp"
#include "proprio/study/design.hpp"

namespace proprio::study {
namespace {

const char* kMinimal = R"(
[study]
name = "t"
seed = 5
[[factor]]
name = "cond"
levels = ["a", "b", "c"]
[blocks]
by = "cond"
counterbalance = "latin-square"
[procedure]
type = "constant"
levels = [1.0, 2.0, 3.0]
repetitions = 4
)";

TEST(StudyDesign, LoadsTheShippedExamples) {
  for (const char* file : {"perception_threshold.toml", "staircase_example.toml"}) {
    auto d = StudyDesign::load_file(std::string(PROPRIO_SOURCE_DIR) + "/config/studies/" + file);
    ASSERT_TRUE(d) << d.error().message;
  }
  auto d = StudyDesign::load_file(std::string(PROPRIO_SOURCE_DIR) + "/config/studies/perception_threshold.toml");
  ASSERT_TRUE(d);
  EXPECT_EQ(d->name, "perception-threshold");
  EXPECT_EQ(d->stimulus_column, "offset_cm");
  EXPECT_EQ(d->procedure.levels, (std::vector<double>{1.5, 3.0, 4.5, 6.0, 7.5}));
  ASSERT_EQ(d->block_groups.size(), 2u);
  EXPECT_EQ(d->block_groups[1].levels, (std::vector<std::string>{"true_sphere", "false_sphere"}));
  // 3 conditions x 5 offsets x 8 repetitions.
  EXPECT_EQ(plan_trials(*d, 0, 1).size(), 120u);
}

TEST(StudyDesign, ErrorsNameTheKeyAndLine) {
  auto typo = StudyDesign::parse(std::string(kMinimal) + "[analysis]\nmodle = \"weibull\"\n", "x.toml");
  ASSERT_FALSE(typo);
  EXPECT_NE(typo.error().message.find("modle"), std::string::npos) << typo.error().message;
  EXPECT_NE(typo.error().message.find("x.toml"), std::string::npos);

  std::string bad_cb = kMinimal;
  bad_cb.replace(bad_cb.find("latin-square"), 12, "latin");
  auto cb = StudyDesign::parse(bad_cb, "y.toml");
  ASSERT_FALSE(cb);
  EXPECT_NE(cb.error().message.find("counterbalance"), std::string::npos);

  std::string numeric_levels = kMinimal;
  numeric_levels.replace(numeric_levels.find("[\"a\", \"b\", \"c\"]"), 15, "[1, 2, 3]");
  auto nl = StudyDesign::parse(numeric_levels, "z.toml");
  ASSERT_FALSE(nl);
  EXPECT_NE(nl.error().message.find("quote"), std::string::npos) << nl.error().message;

  auto broken = StudyDesign::parse("[study\nname = 1", "b.toml");
  ASSERT_FALSE(broken);
  EXPECT_NE(broken.error().message.find("b.toml"), std::string::npos);

  auto clash = StudyDesign::parse("[study]\nname = \"t\"\nstimulus = \"trial\"\n[procedure]\ntype = \"constant\"\n"
                                  "levels = [1.0]\n",
                                  "c.toml");
  ASSERT_FALSE(clash);
  EXPECT_NE(clash.error().message.find("twice"), std::string::npos);

  auto staircase = StudyDesign::parse("[study]\nname = \"t\"\n[procedure]\ntype = \"staircase\"\nstart = 20.0\n"
                                      "step = 1.0\nmin = 0.0\nmax = 10.0\n",
                                      "s.toml");
  ASSERT_FALSE(staircase);
  EXPECT_NE(staircase.error().message.find("outside"), std::string::npos) << staircase.error().message;
}

TEST(Counterbalance, WilliamsSquaresAreBalancedForCarryOver) {
  for (int k = 2; k <= 7; ++k) {
    const auto rows = williams_latin_square(k);
    ASSERT_EQ(rows.size(), static_cast<std::size_t>(k % 2 == 0 ? k : 2 * k));
    std::map<std::pair<int, int>, int> follows;
    std::vector<std::vector<int>> position_count(static_cast<std::size_t>(k), std::vector<int>(k, 0));
    for (const auto& row : rows) {
      ASSERT_EQ(std::set<int>(row.begin(), row.end()).size(), static_cast<std::size_t>(k));
      for (int j = 0; j < k; ++j) ++position_count[static_cast<std::size_t>(row[j])][static_cast<std::size_t>(j)];
      for (int j = 1; j < k; ++j) ++follows[{row[j - 1], row[j]}];
    }
    // Every ordered pair is adjacent equally often (once, or twice for odd k),
    // and every condition appears in every position equally often.
    EXPECT_EQ(follows.size(), static_cast<std::size_t>(k * (k - 1))) << k;
    for (const auto& [pair, n] : follows) EXPECT_EQ(n, k % 2 == 0 ? 1 : 2) << k;
    for (const auto& counts : position_count) {
      for (int n : counts) EXPECT_EQ(n, k % 2 == 0 ? 1 : 2) << k;
    }
  }
}

TEST(Counterbalance, AbbaAlternatesAcrossParticipants) {
  auto d = StudyDesign::parse(std::string(kMinimal).replace(std::string(kMinimal).find("latin-square"), 12, "abba"));
  ASSERT_TRUE(d) << d.error().message;
  const std::vector<int> fwd = {0, 1, 2}, rev = {2, 1, 0};
  EXPECT_EQ(block_order(*d, 0), fwd);
  EXPECT_EQ(block_order(*d, 1), rev);
  EXPECT_EQ(block_order(*d, 2), rev);
  EXPECT_EQ(block_order(*d, 3), fwd);
  EXPECT_EQ(block_order(*d, 4), fwd);
}

TEST(TrialPlan, IsIdenticalForTheSameSeedAndBalanced) {
  auto d = StudyDesign::parse(kMinimal);
  ASSERT_TRUE(d);
  const auto a = plan_trials(*d, 1, 1234);
  const auto b = plan_trials(*d, 1, 1234);
  const auto c = plan_trials(*d, 1, 1235);
  ASSERT_EQ(a.size(), 36u);
  bool differs = false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].cell, b[i].cell);
    EXPECT_EQ(a[i].stimulus, b[i].stimulus);
    differs = differs || a[i].cell != c[i].cell || a[i].stimulus != c[i].stimulus;
  }
  EXPECT_TRUE(differs) << "another seed must give another order";
  // Blocks are contiguous, follow the participant's Latin-square row, and
  // hold every level `repetitions` times.
  const std::vector<int> order = block_order(*d, 1);
  std::map<std::pair<int, double>, int> counts;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].block, static_cast<int>(i / 12));
    EXPECT_EQ(a[i].cell, order[static_cast<std::size_t>(a[i].block)]);
    ++counts[{a[i].cell, a[i].stimulus}];
  }
  EXPECT_EQ(counts.size(), 9u);
  for (const auto& [key, n] : counts) EXPECT_EQ(n, 4);
  // Not simply in generation order within a block.
  bool shuffled = false;
  for (std::size_t i = 1; i < 12; ++i) shuffled = shuffled || a[i].stimulus < a[i - 1].stimulus;
  EXPECT_TRUE(shuffled);
}

TEST(TrialPlan, TheShuffleIsOurOwnFisherYates) {
  // The plan uses proprio::Rng's Fisher-Yates, not std::shuffle: replaying the
  // documented algorithm by hand (back to front, j = below(i + 1)) must give
  // the same order as plan_trials' first block.
  auto d = StudyDesign::parse("[study]\nname = \"t\"\n[procedure]\ntype = \"constant\"\n"
                              "levels = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]\n");
  ASSERT_TRUE(d) << d.error().message;
  const std::uint64_t seed = 99;
  const auto plan = plan_trials(*d, 0, seed);
  std::vector<double> v = {0, 1, 2, 3, 4, 5, 6, 7};
  std::mt19937_64 engine(mix_seed(seed, 1));
  for (std::uint64_t i = v.size(); i > 1; --i) {
    const std::uint64_t limit = ~std::uint64_t{0} - (~std::uint64_t{0} % i);
    std::uint64_t x;
    do { x = engine(); } while (x >= limit);
    std::swap(v[i - 1], v[x % i]);
  }
  ASSERT_EQ(plan.size(), v.size());
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(plan[i].stimulus, v[i]) << i;
}

}  // namespace
}  // namespace proprio::study
