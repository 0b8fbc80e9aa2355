// The FTM glove (issue 27 §4) driving an unmodified app's right hand through
// the layer, on Debian's real loader and the mock runtime: the simulated
// wearer behind the FTM board's emulator (the real HID bytes, the real
// driver), the wrist from a tracker the runtime tracks, as the thesis took it
// from a VIVE tracker. The wearer's truth comes from its own file
// (truth_path), never from the tracker.
//
// CI runs this on 2 cores beside other tests: the unplug is checked by the
// order of events (tracked, a long gap around the unplug, tracked again to the
// end), with seconds of slack, not by tight windows.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "layer_app_util.hpp"

using namespace proprio;
namespace mx = proprio::mock_xr;

namespace layer_ftm_test {

// A maximal run of inactive frames after the hand was first tracked, in
// seconds from the first frame.
struct FtmGap {
  double from_s = 0.0, to_s = 0.0;  // first and last inactive frame
  double length_s() const { return to_s - from_s; }
};

std::vector<FtmGap> ftm_gaps_after_tracking(const std::vector<layer_test::Frame>& frames) {
  std::vector<FtmGap> gaps;
  bool tracked = false, in_gap = false;
  for (const auto& f : frames) {
    const double s = static_cast<double>(f.t_ns - frames.front().t_ns) * 1e-9;
    if (f.active) {
      tracked = true;
      in_gap = false;
    } else if (tracked) {
      if (!in_gap) gaps.push_back({s, s});
      gaps.back().to_s = s;
      in_gap = true;
    }
  }
  return gaps;
}

std::string ftm_describe(const std::vector<FtmGap>& gaps) {
  std::string out;
  for (const auto& g : gaps) {
    char row[64];
    std::snprintf(row, sizeof row, "[%.2f s, %.2f s] ", g.from_s, g.to_s);
    out += row;
  }
  return out.empty() ? "none" : out;
}

class LayerFtm : public layer_test::LayerAppTest {};

TEST_F(LayerFtm, AnEmulatedFtmBoardOnATrackedWrist) {
  const auto truth_file = dir_.path() / "ftm_truth.csv";
  const std::string offsets = layer_test::tracker_wrist_offset_toml();
  // The board's cable comes out 3 s after the source starts, for 1.5 s.
  constexpr double kUnplugAtS = 3.0, kUnplugForS = 1.5, kRunS = 8.0;
  char unplug[64];
  std::snprintf(unplug, sizeof unplug, "unplug_s = [%.1f, %.1f]\n", kUnplugAtS, kUnplugForS);
  use_config("[layer]\nmax_prediction_ms = 100\nstale_timeout_ms = 200\n[[source]]\ntype = \"ftm\"\n"
             "input = \"emulated\"\nsubject = 4\nseed = 3\nhands = [\"right\"]\nwrist = \"tracker\"\n" +
             offsets + "truth_path = \"" + truth_file.string() + "\"\n" + unplug);
  XrHandTrackingLatencyPROPRIO latency{};
  std::vector<layer_test::Frame> frames;
  const auto served = layer_test::run_app(Handedness::right, kRunS, &latency, &frames);
  ASSERT_GT(frames.size(), 100u) << "the app ran its frames";

  // Tracked, then a long gap while the cable is out, then tracked again to the
  // end. The source's clock starts near the app's first frame; the slack
  // covers its start-up (calibrating from the wearer's own poses) under load.
  const auto gaps = ftm_gaps_after_tracking(frames);
  std::printf("FTM through the layer: inactive after first tracked (s from the first frame): %s\n",
              ftm_describe(gaps).c_str());
  const auto unplug_gap = std::find_if(gaps.begin(), gaps.end(), [&](const FtmGap& g) {
    return g.length_s() >= 0.4 && g.to_s > kUnplugAtS - 0.5 && g.from_s < kUnplugAtS + kUnplugForS + 2.5;
  });
  EXPECT_NE(unplug_gap, gaps.end()) << "the hand goes inactive while the board is unplugged; gaps after tracking: "
                                    << ftm_describe(gaps);
  // Tracked again: most of the last 1.5 s (a loaded machine may stall a frame
  // or two past the stale timeout), and frames tracked after the unplug's gap.
  std::size_t last = 0, last_active = 0;
  for (const auto& f : frames) {
    if (frames.back().t_ns - f.t_ns > 1500 * kNsPerMillisecond) continue;
    ++last;
    last_active += f.active;
  }
  EXPECT_GE(10 * last_active, 8 * last) << "tracked again once the board is back: " << last_active << " of the last "
                                        << last << " frames; gaps: " << ftm_describe(gaps);
  if (unplug_gap != gaps.end()) {
    std::size_t after = 0;
    for (const auto& f : frames) {
      after += f.active && static_cast<double>(f.t_ns - frames.front().t_ns) * 1e-9 > unplug_gap->to_s;
    }
    EXPECT_GT(after, 30u) << "frames tracked after the unplug; gaps: " << ftm_describe(gaps);
  }
  ASSERT_GT(served.size(), 100u) << "tracked poses served (the layer attaches its tracker action after 90 frames)";

  // The wrist is the tracker's, composed with the offset: exactly the mock's wrist.
  for (const auto& s : served) {
    const Pose expected =
        from_xr(mx::to_xr(mx::wrist_pose(mx::Hand::right, mx::xr_time_from_monotonic_ns(s.t_ns)).pose));
    const Pose& wrist = s.T_local_joint[index_of(HandJoint::wrist)];
    ASSERT_LT((wrist.p - expected.p).norm(), 1e-4) << "at " << s.t_ns << " ns";
    ASSERT_LT(angle_between(wrist.q, expected.q), 1e-3) << "at " << s.t_ns << " ns";
  }

  // The fingers, relative to the wrist, against the wearer's truth: the FTM
  // tracks the thumb, index and middle; ring and little only follow them.
  const auto truth = layer_test::read_truth(truth_file);
  ASSERT_GT(truth.size(), 200u) << "the emulated wearer wrote its truth";
  std::size_t compared = 0, compared_all = 0;
  const double error_m = layer_test::fingertip_error_m(
      served, truth, compared, {HandJoint::thumb_tip, HandJoint::index_tip, HandJoint::middle_tip});
  const double error_all_m = layer_test::fingertip_error_m(served, truth, compared_all);
  std::printf("emulated FTM through the layer: thumb/index/middle fingertip error rel. wrist %.1f mm mean over %zu "
              "tips (all five: %.1f mm); %llu poses served\n",
              error_m * 1e3, compared, error_all_m * 1e3, static_cast<unsigned long long>(latency.poseCount));
  EXPECT_GT(compared, 300u);
  // docs/ftm.md: 7.35 mm mean on the bench (free motion, held-out subjects,
  // same three tips). Predicting to "now" over the board's latency and a
  // source stalled by a loaded machine add a few millimetres; a wrong wrist
  // frame, a swapped hand or mis-mapped joints add centimetres.
  EXPECT_LT(error_m, 0.020) << "mean thumb/index/middle fingertip error relative to the wrist";
  std::uint64_t counted = 0;
  for (uint32_t i = 0; i < latency.binCount; ++i) counted += latency.ageAtLocate[i];
  EXPECT_EQ(counted, latency.poseCount);
  EXPECT_GE(latency.poseCount, served.size());
}

}  // namespace layer_ftm_test
