// The glove as built: the simulators' markers and IMUs sit off the drawn
// places by the configured amounts, per glove and per donning, and the drawn
// glove comes back unchanged when the errors are off.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <vector>

#include "proprio/sim/glove_as_built.hpp"
#include "proprio/sim/subjects.hpp"

using namespace proprio;
using namespace proprio::sim;

namespace glove_as_built_test {

HandShape shape() { return *sim_subject(4)->shape(); }

// Marker displacements (placed, right hand) between two descriptions, metres.
std::vector<Vec3> displacements(const ImuGloveDescription& a, const ImuGloveDescription& b) {
  const auto pa = a.place_markers(shape(), Handedness::right);
  const auto pb = b.place_markers(shape(), Handedness::right);
  std::vector<Vec3> d;
  for (std::size_t i = 0; i < pa.size(); ++i) d.push_back(pb[i].p_in_segment - pa[i].p_in_segment);
  return d;
}

double rms(const std::vector<Vec3>& d) {
  double s = 0.0;
  for (const Vec3& v : d) s += v.squaredNorm();
  return std::sqrt(s / static_cast<double>(d.size()));
}

TEST(GloveAsBuilt, AsDrawnIsTheDescriptionItself) {
  const auto drawn = ImuGloveDescription::vist_default();
  const auto built = glove_as_built(drawn, shape(), GloveBuildErrors::as_drawn(), 1, 2);
  EXPECT_EQ(rms(displacements(drawn, built)), 0.0);
  for (std::size_t i = 0; i < drawn.markers.size(); ++i) EXPECT_EQ(built.markers[i].diameter_m, drawn.markers[i].diameter_m);
}

TEST(GloveAsBuilt, MarkersMoveByTheConfiguredSigma) {
  // Surface displacement has two components (along, around), so its RMS is
  // sqrt(2) sigma; pooled over 37 markers and 40 gloves, within 10 %.
  const auto drawn = ImuGloveDescription::vist_default();
  GloveBuildErrors e;
  e.per_glove_m = 0.002;
  e.per_donning_m = 0.0;
  std::vector<Vec3> all;
  for (std::uint64_t g = 0; g < 40; ++g) {
    for (const Vec3& v : displacements(drawn, glove_as_built(drawn, shape(), e, g, 0))) all.push_back(v);
  }
  EXPECT_NEAR(rms(all), std::sqrt(2.0) * 0.002, 0.1 * std::sqrt(2.0) * 0.002);
}

TEST(GloveAsBuilt, ADonningMovesASegmentsMarkersTogetherAndTheGloveStaysTheGlove) {
  const auto drawn = ImuGloveDescription::vist_default();
  GloveBuildErrors donning_only;
  donning_only.per_glove_m = 0.0;
  donning_only.diameter_fraction = 0.0;
  const auto a = glove_as_built(drawn, shape(), donning_only, 1, 10);
  // Markers on one finger segment at the same around angle move by the same along-bone amount.
  const auto pd = drawn.place_markers(shape(), Handedness::right);
  const auto pa = a.place_markers(shape(), Handedness::right);
  std::map<HandJoint, std::vector<double>> along_shift;
  for (std::size_t i = 0; i < pd.size(); ++i) {
    // Away from the bone's ends, where a shift would be clamped to the bone.
    const double along = drawn.markers[i].along_fraction;
    if (pd[i].segment == HandJoint::wrist || drawn.markers[i].around_deg != 0.0 || along < 0.3 || along > 0.7) continue;
    along_shift[pd[i].segment].push_back(a.markers[i].along_fraction - drawn.markers[i].along_fraction);
  }
  std::size_t compared = 0;
  for (const auto& [segment, shifts] : along_shift) {
    for (double s : shifts) {
      EXPECT_NEAR(s, shifts.front(), 1e-12) << to_string(segment);
      ++compared;
    }
  }
  EXPECT_GT(compared, 3u);
  // Same glove, another donning: the per-glove part stays, the donning part changes.
  GloveBuildErrors glove_only;
  glove_only.per_donning_m = 0.0;
  const auto g1 = glove_as_built(drawn, shape(), glove_only, 7, 1);
  const auto g2 = glove_as_built(drawn, shape(), glove_only, 7, 2);
  EXPECT_EQ(rms(displacements(g1, g2)), 0.0);
  const auto d1 = glove_as_built(drawn, shape(), GloveBuildErrors{}, 7, 1);
  const auto d2 = glove_as_built(drawn, shape(), GloveBuildErrors{}, 7, 2);
  EXPECT_GT(rms(displacements(d1, d2)), 0.001);
}

TEST(GloveAsBuilt, DiametersVaryByTheConfiguredFraction) {
  const auto drawn = ImuGloveDescription::vist_default();
  GloveBuildErrors e;
  e.diameter_fraction = 0.05;
  double s2 = 0.0;
  std::size_t n = 0;
  for (std::uint64_t g = 0; g < 20; ++g) {
    const auto b = glove_as_built(drawn, shape(), e, g, 0);
    for (std::size_t i = 0; i < drawn.markers.size(); ++i) {
      const double r = b.markers[i].diameter_m / drawn.markers[i].diameter_m - 1.0;
      s2 += r * r;
      ++n;
    }
  }
  EXPECT_NEAR(std::sqrt(s2 / static_cast<double>(n)), 0.05, 0.006);
}

TEST(GloveAsBuilt, ValidateNamesTheBadValue) {
  GloveBuildErrors e;
  e.per_donning_m = std::nan("");
  const auto st = e.validate();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("per_donning_m"), std::string::npos);
  EXPECT_TRUE(GloveBuildErrors{}.validate().ok());
  EXPECT_EQ(GloveBuildErrors{}.describe(), "per_glove=1.5mm per_donning=2.0mm diameter=5%");
}

}  // namespace glove_as_built_test
