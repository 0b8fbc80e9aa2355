// The completion-time analysis against numbers worked out by hand.
#include <gtest/gtest.h>

#include <cmath>

#include "proprio/study/completion_time.hpp"

using namespace proprio;
using namespace proprio::study;

namespace {

CsvTable table(const std::string& text, const std::string& name) {
  auto t = parse_csv(text, name);
  EXPECT_TRUE(t) << t.error().message;
  return *t;
}

// P1 takes 2 s in setting 1 and 4 s in setting 2 in both rounds (mean 3 s);
// P2 takes 5/5 s in round 1 and 4/6 s in round 2 (mean 5 s). A familiarisation
// row (100 s) must be ignored.
std::vector<CsvTable> two_by_two() {
  return {table("participant,round,setting,familiarisation,completion_time_s\n"
                "P1,1,1,1,100\nP1,1,1,0,2\nP1,1,2,0,4\nP1,2,2,0,4\nP1,2,1,0,2\n",
                "p1.csv"),
          table("participant,round,setting,familiarisation,completion_time_s\n"
                "P2,1,1,0,5\nP2,1,2,0,5\nP2,2,1,0,4\nP2,2,2,0,6\n",
                "p2.csv")};
}

}  // namespace

TEST(CompletionTime, NormalisedMeansSdsAndTestsMatchHandCalculation) {
  auto a = analyze_completion_times(two_by_two());
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_EQ(a->excluded_trials, 1);
  EXPECT_DOUBLE_EQ(a->participant_mean_time_s.at("P1"), 3.0);
  EXPECT_DOUBLE_EQ(a->participant_mean_time_s.at("P2"), 5.0);
  ASSERT_EQ(a->summary.size(), 2u);
  // Setting 1: 2/3, 2/3, 1, 0.8 -> mean 0.78333, SD 0.157527.
  EXPECT_NEAR(a->summary[0].mean, 0.783333, 1e-6);
  EXPECT_NEAR(a->summary[0].sd, 0.157527, 1e-6);
  // Setting 2: 4/3, 4/3, 1, 1.2 -> mean 1.216667 (normalised means average to 1).
  EXPECT_NEAR(a->summary[1].mean, 1.216667, 1e-6);
  EXPECT_EQ(a->summary[0].n, 4);
  // Profiles: P1 (2/3, 4/3), P2 (0.9, 1.1).
  EXPECT_NEAR(a->profile[0][0], 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(a->profile[1][1], 1.1, 1e-12);
  // Rounds as subjects: differences -2/3, -2/3, 0, -0.4: mean -0.433333,
  // SD 0.315053, t(3) = -2.75085; with two settings F = t^2 and epsilon = 1.
  ASSERT_EQ(a->pairwise.size(), 1u);
  EXPECT_EQ(a->pairwise[0].test.n, 4);
  EXPECT_NEAR(a->pairwise[0].test.mean_difference, -0.433333, 1e-6);
  EXPECT_NEAR(a->pairwise[0].test.t, -2.75085, 1e-4);
  EXPECT_NEAR(a->anova_rounds.f, 2.75085 * 2.75085, 1e-3);
  EXPECT_EQ(a->anova_rounds.subjects, 4);
  EXPECT_NEAR(a->anova_rounds.gg_epsilon, 1.0, 1e-12);
  EXPECT_NEAR(a->anova_rounds.p, a->pairwise[0].test.p, 1e-9);
  EXPECT_DOUBLE_EQ(a->pairwise[0].p_bonferroni, a->pairwise[0].test.p);  // one comparison
  // Participant means as subjects: differences -2/3 and -0.2.
  EXPECT_EQ(a->anova_participants.subjects, 2);
  EXPECT_NEAR(a->anova_participants.f, std::pow(-0.433333 / (0.329983 / std::sqrt(2.0)), 2), 1e-3);
}

TEST(CompletionTime, HolmAndBonferroniOverSixPairs) {
  // Four settings, three participants, one round each.
  auto a = analyze_completion_times({table("participant,round,setting,completion_time_s\n"
                                           "A,1,1,3\nA,1,2,5\nA,1,3,6\nA,1,4,9\n"
                                           "B,1,1,4\nB,1,2,5\nB,1,3,8\nB,1,4,10\n"
                                           "C,1,1,2\nC,1,2,4\nC,1,3,5\nC,1,4,6\n",
                                           "four.csv")});
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_EQ(a->pairwise.size(), 6u);
  std::vector<double> raw;
  for (const auto& c : a->pairwise) {
    EXPECT_NEAR(c.p_bonferroni, std::min(1.0, 6.0 * c.test.p), 1e-12);
    EXPECT_GE(c.p_holm, c.test.p);
    EXPECT_LE(c.p_holm, c.p_bonferroni + 1e-12);
    raw.push_back(c.test.p);
  }
  const auto holm_expected = holm(raw);
  for (std::size_t k = 0; k < 6; ++k) EXPECT_DOUBLE_EQ(a->pairwise[k].p_holm, holm_expected[k]);
  EXPECT_GT(a->anova_rounds.f, 1.0);
  EXPECT_LE(a->anova_rounds.gg_epsilon, 1.0);
  EXPECT_GE(a->anova_rounds.gg_epsilon, 1.0 / 3.0);
  const std::string svg = completion_time_svg(*a, "t");
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("polyline"), std::string::npos) << "per-participant profiles";
  EXPECT_NE(completion_time_text(*a).find("Greenhouse-Geisser"), std::string::npos);
}

TEST(CompletionTime, BadInputGivesClearErrors) {
  auto missing = analyze_completion_times({table("participant,setting\nP1,1\n", "m.csv")});
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("completion_time_s"), std::string::npos) << missing.error().message;
  auto negative = analyze_completion_times({table("participant,setting,completion_time_s\nP1,1,-2\nP1,2,3\n", "n.csv")});
  ASSERT_FALSE(negative);
  EXPECT_NE(negative.error().message.find("n.csv:2"), std::string::npos) << negative.error().message;
  auto not_number = analyze_completion_times({table("participant,setting,completion_time_s\nP1,1,abc\n", "x.csv")});
  EXPECT_FALSE(not_number);
  auto one_setting = analyze_completion_times({table("participant,setting,completion_time_s\nP1,1,2\n", "o.csv")});
  EXPECT_FALSE(one_setting);
  auto incomplete = analyze_completion_times(
      {table("participant,setting,completion_time_s\nP1,1,2\nP1,2,3\nP2,1,2\n", "i.csv")});
  EXPECT_FALSE(incomplete) << "P2 never did setting 2";
}
