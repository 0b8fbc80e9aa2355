// DatasetRecorder: a glove's measurements paired with a ground-truth hand
// source into a training session, checked against the simulator's truth.
#include <gtest/gtest.h>

#include <filesystem>

#include "proprio/core/pose_history.hpp"
#include "proprio/stretch_glove/dataset_recorder.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::stretch_glove {
namespace {

// A ground-truth tracker: poses at 90 Hz in a history, like a replayed recording.
class TruthSource final : public HandSource {
 public:
  TruthSource() : history_(PoseHistoryOptions{100000, 0, 200 * kNsPerMillisecond}) {}
  std::string_view name() const noexcept override { return "test truth"; }
  bool available(Handedness hand) const noexcept override { return hand == Handedness::right; }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override {
    HandPose p;
    if (!is_usable(lookup(hand, t_ns, p))) return make_error(Errc::unavailable, "no truth then");
    return p;
  }
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override {
    if (hand != Handedness::right) return PoseLookup::empty;
    return history_.lookup(t_ns, out);
  }
  void push(const HandPose& p) { ASSERT_TRUE(history_.push(p)); }

 private:
  PoseHistory history_;
};

constexpr TimeNs kT0 = 5'000 * kNsPerSecond;  // CLOCK_MONOTONIC-like: far from zero

struct Recorded {
  DatasetRecorder recorder;
  TruthSource truth;
  sim::HandMotionGenerator motion;
};

// `seconds` of one simulated subject: the glove's measurements into the
// recorder, the truth (from truth_from_s on) into the source.
Recorded record(double seconds, double truth_from_s) {
  const auto layout = StretchGloveLayout::thesis_default();
  const auto subject = sim::sim_subject(4);
  const HandShape shape = *subject->shape();
  sim::HandMotionOptions mo;
  mo.hand = Handedness::right;
  mo.seed = 8;
  Recorded r{*DatasetRecorder::create(layout), TruthSource{}, sim::HandMotionGenerator(HandModel(shape), mo)};
  auto glove = sim::StretchGloveSimulator::create(layout, shape, sim::StretchGloveSimOptions{});
  EXPECT_TRUE(glove) << glove.error().message;
  const TimeNs end = seconds_to_ns(seconds);
  TimeNs next_truth = seconds_to_ns(truth_from_s);
  while (glove->measurement_time(glove->next_index()) < end) {
    const TimeNs t = glove->measurement_time(glove->next_index());
    while (next_truth <= t) {
      HandPose p = r.motion.sample(next_truth).pose;
      p.time_ns = kT0 + next_truth;
      r.truth.push(p);
      next_truth += kNsPerSecond / 90;
    }
    const sim::StretchMeasurement m = glove->measure(r.motion.sample(t).angles);
    devices::StretchSample s;
    s.capacitance_pf = m.capacitance_pf;
    s.combination = m.combination;
    s.status = m.saturated ? devices::StretchMeasurementStatus::saturated : devices::StretchMeasurementStatus::ok;
    s.time_ns = kT0 + m.time_ns;
    r.recorder.push(s);
  }
  return r;
}

TEST(DatasetRecorder, PairsFramesWithTheTruthAndCalibratesFromTheExploration) {
  Recorded r = record(10.0, 1.0);  // short: the ASan build runs it too
  ASSERT_GT(r.recorder.frames(), 500u);
  DatasetSessionInfo info;
  info.subject = 4;
  info.session = 2;
  info.donning = 2;
  info.hand_length_m = sim::sim_subject(4)->hand_length_m;
  info.hand_width_m = sim::sim_subject(4)->hand_width_m;
  info.exploration_end_ns = kT0 + 5 * kNsPerSecond;
  auto session = r.recorder.finish(r.truth, info);
  ASSERT_TRUE(session) << session.error().message;
  const DatasetRecorderStats& st = r.recorder.stats();
  SCOPED_TRACE(::testing::Message() << st.frames << " frames, " << st.paired << " paired, " << st.without_truth
                                    << " without truth, IK residual " << st.ik_residual_max_m);

  // The first second has no truth: those frames are dropped, not guessed
  // (less the first few, which the read-out's first cycle left incomplete).
  const double rate = static_cast<double>(st.frames) / 10.0;
  EXPECT_NEAR(static_cast<double>(st.without_truth + st.frames_invalid), rate, 0.05 * rate);
  EXPECT_LT(st.frames_invalid, 0.2 * rate);
  EXPECT_EQ(session->frames(), st.paired);
  EXPECT_EQ(st.paired + st.without_truth, r.recorder.frames());
  EXPECT_NEAR(static_cast<double>(st.exploration), 4.0 * rate, 0.05 * rate * 4.0);
  EXPECT_EQ(session->cells.size(), session->frames() * StretchGloveLayout::thesis_default().cell_count());
  EXPECT_EQ(session->angles.size(), session->frames() * kHandDofCount);
  EXPECT_EQ(session->phase.front(), 0);
  EXPECT_EQ(session->phase.back(), 1);
  EXPECT_EQ(session->subject, 4);
  EXPECT_EQ(session->calibration.cell_count(), StretchGloveLayout::thesis_default().cell_count());

  // The stored angles are the truth's, recovered by IK from poses interpolated at 90 Hz.
  ASSERT_EQ(r.recorder.paired_times().size(), session->frames());
  double err_sum = 0.0, motion_sum = 0.0;
  std::size_t n = 0;
  for (std::size_t f = 0; f < session->frames(); f += 10) {
    const HandAngles truth = r.motion.sample(r.recorder.paired_times()[f] - kT0).angles;
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      err_sum += std::abs(session->angles[f * kHandDofCount + d] - truth[d]);
      motion_sum += std::abs(truth[d]);
      ++n;
    }
  }
  std::printf("recorded angles vs truth: mean %.4f rad over %zu values (mean |angle| %.3f rad), IK residual max %.2f mm\n",
              err_sum / n, n, motion_sum / n, 1e3 * st.ik_residual_max_m);
  EXPECT_LT(err_sum / n, 0.02);
  EXPECT_GT(motion_sum / n, 0.1) << "the hand moves: a zero-angle recording would pass the check above";

  // DatasetWriter takes the session as it is.
  const auto dir = std::filesystem::temp_directory_path() / ("proprio_rec_" + std::to_string(::getpid()));
  auto writer = DatasetWriter::create(dir, StretchGloveLayout::thesis_default(), 60.0, true);
  ASSERT_TRUE(writer) << writer.error().message;
  ASSERT_TRUE(writer->add_session(*session));
  ASSERT_TRUE(writer->finish("{\"generator\": \"test\"}"));
  EXPECT_TRUE(std::filesystem::exists(dir / "meta.json"));
  std::filesystem::remove_all(dir);
}

TEST(DatasetRecorder, WithoutOverlappingTruthItSaysSo) {
  Recorded r = record(3.0, 100.0);  // the truth starts long after the glove stopped
  DatasetSessionInfo info;
  info.exploration_end_ns = kT0 + kNsPerSecond;
  auto session = r.recorder.finish(r.truth, info);
  ASSERT_FALSE(session);
  EXPECT_EQ(session.error().code, Errc::unavailable);
  EXPECT_NE(session.error().message.find("same clock"), std::string::npos) << session.error().message;
}

}  // namespace
}  // namespace proprio::stretch_glove
