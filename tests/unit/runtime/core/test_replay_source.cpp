#include "proprio/core/replay_source.hpp"

#include <gtest/gtest.h>

#include "support/temp_dir.hpp"
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <random>

namespace proprio {
namespace {

namespace fs = std::filesystem;

using proprio::testing_support::TempDir;

// The analytic motion: the wrist moves at constant velocity and the whole hand
// turns at a constant rate about a fixed world axis, so lerp (position of the
// wrist) and slerp (every orientation) reproduce it exactly between samples.
const Vec3 kP0(0.1, 1.2, -0.4);
const Vec3 kVelocity(0.3, -0.2, 0.5);      // m/s
const Vec3 kOmega = Vec3(0.2, 1.0, -0.4).normalized() * 2.0;  // rad/s
constexpr TimeNs kStart = 2 * kNsPerSecond;
constexpr TimeNs kStep = 10 * kNsPerMillisecond;  // 100 Hz
constexpr int kSamples = 101;                      // 1 s

Vec3 joint_offset(std::size_t i) {
  if (joint_at(i) == HandJoint::wrist) return Vec3::Zero();
  return Vec3(0.01 * static_cast<double>(i % 5), 0.02 * static_cast<double>(i / 5), -0.005 * static_cast<double>(i));
}
Quat joint_rest(std::size_t i) { return so3_exp(Vec3(0.05, -0.03, 0.02) * static_cast<double>(i)); }

Quat hand_rotation(TimeNs t) { return so3_exp(kOmega * ns_to_seconds(t - kStart)); }
Vec3 wrist_position(TimeNs t) { return kP0 + kVelocity * ns_to_seconds(t - kStart); }

HandPose analytic_pose(TimeNs t, Handedness hand, const Vec3& shift = Vec3::Zero()) {
  HandPose p;
  p.time_ns = t;
  p.hand = hand;
  p.active = true;
  p.set_all_flags(kJointFullyTracked);
  const Quat R = hand_rotation(t);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    p.T_world_joint[i].q = (R * joint_rest(i)).normalized();
    p.T_world_joint[i].p = wrist_position(t) + R * joint_offset(i) + shift;
    p.radius_m[i] = 0.01;
  }
  return p;
}

struct StreamSpec {
  std::string name;
  Handedness hand;
  Vec3 shift = Vec3::Zero();
};

// time_of(k) gives sample k's time; by default the 100 Hz grid from kStart.
void write_recording(const fs::path& path, const std::vector<StreamSpec>& specs, int samples = kSamples,
                     const std::function<TimeNs(int)>& time_of = {}) {
  auto w = RecordingWriter::create(path, {.overwrite = true});
  ASSERT_TRUE(w.ok()) << w.error().message;
  const StreamId imu = w->add_stream(StreamKind::imu, "imu/0").value();
  std::vector<StreamId> ids;
  for (const auto& s : specs) ids.push_back(w->add_stream(StreamKind::hand_pose, s.name).value());
  for (int k = 0; k < samples; ++k) {
    const TimeNs t = time_of ? time_of(k) : kStart + k * kStep;
    ASSERT_TRUE(w->write(imu, ImuSample{}, t).ok());
    for (std::size_t i = 0; i < specs.size(); ++i) {
      ASSERT_TRUE(w->write(ids[i], analytic_pose(t, specs[i].hand, specs[i].shift)).ok());
    }
  }
  ASSERT_TRUE(w->close().ok());
}

ReplayOptions with_offset(DurationNs offset_ns) {
  ReplayOptions o;
  o.time_offset_ns = offset_ns;
  return o;
}

const std::vector<StreamSpec> kTrackedAndTruth = {
    {"hand/right/ground_truth", Handedness::right, Vec3(1.0, 0.0, 0.0)},
    {"hand/right", Handedness::right},
};

TEST(ReplayHandSource, InterpolatesAnalyticMotionBetweenSamples) {
  TempDir dir;
  write_recording(dir / "motion.prec", kTrackedAndTruth);
  constexpr DurationNs kOffset = 5 * kNsPerSecond;
  auto src = ReplayHandSource::open(dir / "motion.prec", with_offset(kOffset));
  ASSERT_TRUE(src.ok()) << src.error().message;

  EXPECT_EQ(src->name(), "replay");
  EXPECT_TRUE(src->available(Handedness::right));
  EXPECT_FALSE(src->available(Handedness::left));
  EXPECT_EQ(src->file_time_range().first_ns, kStart);
  EXPECT_EQ(src->file_time_range().last_ns, kStart + (kSamples - 1) * kStep);
  ASSERT_EQ(src->streams().size(), 1u);
  EXPECT_EQ(src->streams()[0].name, "hand/right") << "tracker output is preferred over ground truth";
  EXPECT_EQ(src->streams()[0].samples, static_cast<std::size_t>(kSamples));
  EXPECT_TRUE(src->recording_summary().clean());

  HandSource& source = *src;
  for (const TimeNs file_t : {kStart + 3 * kStep + kStep / 2, kStart + 57 * kStep + 1'234'567, kStart + 99 * kStep + 1}) {
    SCOPED_TRACE("file time " + std::to_string(file_t));
    auto pose = source.pose_at(Handedness::right, file_t + kOffset);
    ASSERT_TRUE(pose.ok()) << pose.error().message;
    EXPECT_EQ(pose->time_ns, file_t + kOffset);
    EXPECT_TRUE(pose->active);
    EXPECT_LT((pose->joint(HandJoint::wrist).p - wrist_position(file_t)).norm(), 1e-12);
    const Quat R = hand_rotation(file_t);
    for (std::size_t i = 0; i < kHandJointCount; ++i) {
      EXPECT_LT(angle_between(pose->T_world_joint[i].q, R * joint_rest(i)), 1e-9) << to_string(joint_at(i));
      // Positions off the rotation axis move on arcs; lerp cuts the chord: r ω² dt² / 8 < 1e-5 m.
      EXPECT_LT((pose->T_world_joint[i].p - (wrist_position(file_t) + R * joint_offset(i))).norm(), 1e-5);
    }
  }
}

TEST(ReplayHandSource, SampleTimesReturnTheRecordedPose) {
  TempDir dir;
  write_recording(dir / "m.prec", kTrackedAndTruth);
  auto src = ReplayHandSource::open(dir / "m.prec");
  ASSERT_TRUE(src.ok()) << src.error().message;
  const TimeNs t = kStart + 42 * kStep;
  auto pose = src->pose_at(Handedness::right, t);
  ASSERT_TRUE(pose.ok());
  const HandPose expected = analytic_pose(t, Handedness::right);
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    EXPECT_EQ(pose->T_world_joint[i].p, expected.T_world_joint[i].p);
    EXPECT_EQ(pose->T_world_joint[i].q.coeffs(), expected.T_world_joint[i].q.coeffs());
  }
}

TEST(ReplayHandSource, QueriesOutsideTheRecordingAreOutOfRange) {
  TempDir dir;
  write_recording(dir / "m.prec", kTrackedAndTruth);
  auto src = ReplayHandSource::open(dir / "m.prec", with_offset(-kStart));
  ASSERT_TRUE(src.ok());
  const FileTimeRange range = src->file_time_range();

  auto before = src->pose_at(Handedness::right, range.first_ns - kStart - 1);
  ASSERT_FALSE(before.ok());
  EXPECT_EQ(before.error().code, Errc::out_of_range);
  EXPECT_NE(before.error().message.find("file time " + std::to_string(range.first_ns - 1)), std::string::npos)
      << before.error().message;

  auto after = src->pose_at(Handedness::right, range.last_ns - kStart + 1);
  ASSERT_FALSE(after.ok());
  EXPECT_EQ(after.error().code, Errc::out_of_range);

  EXPECT_TRUE(src->pose_at(Handedness::right, range.first_ns - kStart).ok());
  EXPECT_TRUE(src->pose_at(Handedness::right, range.last_ns - kStart).ok());

  auto left = src->pose_at(Handedness::left, 0);
  ASSERT_FALSE(left.ok());
  EXPECT_EQ(left.error().code, Errc::unavailable);
  EXPECT_NE(left.error().message.find("no left-hand poses"), std::string::npos) << left.error().message;

  // Re-anchoring the offset moves the playable window.
  src->set_time_offset_ns(100 * kNsPerSecond - range.first_ns);
  EXPECT_TRUE(src->pose_at(Handedness::right, 100 * kNsPerSecond).ok());
  EXPECT_FALSE(src->pose_at(Handedness::right, 0).ok());
}

TEST(ReplayHandSource, StreamSelection) {
  TempDir dir;
  write_recording(dir / "m.prec", kTrackedAndTruth);
  const TimeNs t = kStart + 10 * kStep;

  auto truth = ReplayHandSource::open(dir / "m.prec", {.stream_name_filter = "ground_truth"});
  ASSERT_TRUE(truth.ok()) << truth.error().message;
  EXPECT_NEAR(truth->pose_at(Handedness::right, t)->joint(HandJoint::wrist).p.x(), wrist_position(t).x() + 1.0, 1e-12);

  auto exact = ReplayHandSource::open(dir / "m.prec", {.stream_name_filter = "hand/right"});
  ASSERT_TRUE(exact.ok()) << "an exact name wins over substring matches: " << exact.error().message;
  EXPECT_EQ(exact->streams()[0].name, "hand/right");

  auto none = ReplayHandSource::open(dir / "m.prec", {.stream_name_filter = "vist"});
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.error().code, Errc::not_found);
  EXPECT_NE(none.error().message.find("'hand/right/ground_truth', 'hand/right'"), std::string::npos)
      << none.error().message;

  write_recording(dir / "gt_only.prec", {{"hand/left/ground_truth", Handedness::left}});
  auto fallback = ReplayHandSource::open(dir / "gt_only.prec");
  ASSERT_TRUE(fallback.ok()) << fallback.error().message;
  EXPECT_TRUE(fallback->available(Handedness::left));
  EXPECT_FALSE(fallback->available(Handedness::right));

  write_recording(dir / "two.prec", {{"hand/right/vist", Handedness::right}, {"hand/right/glove", Handedness::right},
                                     {"hand/left/glove", Handedness::left}});
  auto ambiguous = ReplayHandSource::open(dir / "two.prec");
  ASSERT_FALSE(ambiguous.ok());
  EXPECT_EQ(ambiguous.error().code, Errc::invalid_argument);
  EXPECT_NE(ambiguous.error().message.find("right-hand poses in several streams"), std::string::npos)
      << ambiguous.error().message;
  EXPECT_NE(ambiguous.error().message.find("stream_name_filter"), std::string::npos);
  auto glove = ReplayHandSource::open(dir / "two.prec", {.stream_name_filter = "glove"});
  ASSERT_TRUE(glove.ok()) << glove.error().message;
  EXPECT_TRUE(glove->available(Handedness::left));
  EXPECT_TRUE(glove->available(Handedness::right));
}

TEST(ReplayHandSource, RecordingWithoutHandPosesIsAnError) {
  TempDir dir;
  write_recording(dir / "imu.prec", {});
  auto src = ReplayHandSource::open(dir / "imu.prec");
  ASSERT_FALSE(src.ok());
  EXPECT_EQ(src.error().code, Errc::not_found);
  EXPECT_NE(src.error().message.find("no hand_pose stream"), std::string::npos) << src.error().message;
  EXPECT_NE(src.error().message.find("'imu/0' (imu)"), std::string::npos) << src.error().message;

  auto missing = ReplayHandSource::open(dir / "nothing.prec");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, Errc::not_found);
}

TEST(ReplayHandSource, TruncatedRecordingReplaysItsCompleteRecordsAndMoves) {
  TempDir dir;
  const fs::path path = dir / "cut.prec";
  write_recording(path, {{"hand/right", Handedness::right}});
  fs::resize_file(path, fs::file_size(path) - 1000);  // the End record and part of the last pose
  auto opened = ReplayHandSource::open(path);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  ReplayHandSource src = std::move(opened.value());
  EXPECT_EQ(src.recording_summary().end, RecordingEnd::truncated);
  EXPECT_EQ(src.streams()[0].samples, static_cast<std::size_t>(kSamples - 1));
  EXPECT_EQ(src.file_time_range().last_ns, kStart + (kSamples - 2) * kStep);
  EXPECT_TRUE(src.pose_at(Handedness::right, kStart + 5 * kStep + 7).ok());
}

// Replay streams the file: what it holds stays within its options however
// long the recording, and every lookup answers what a history holding the
// whole file answers (interpolation, gaps, before and after the recording).
TEST(ReplayHandSource, StreamsALongRecordingInBoundedMemoryWithTheSameAnswers) {
  TempDir dir;
  const fs::path path = dir / "long.prec";
  constexpr int kLong = 3000;  // 30 s at 100 Hz, with a 0.5 s gap at 12 s
  const auto time_of = [](int k) { return kStart + k * kStep + (k >= 1200 ? 500 * kNsPerMillisecond : 0); };
  write_recording(path, {{"hand/right", Handedness::right}, {"hand/left", Handedness::left}}, kLong, time_of);

  ReplayOptions o;
  o.window_samples = 8;
  o.max_index_entries = 16;
  o.max_prediction_ns = 20 * kNsPerMillisecond;
  auto src = ReplayHandSource::open(path, o);
  ASSERT_TRUE(src.ok()) << src.error().message;
  EXPECT_EQ(src->streams()[0].samples, static_cast<std::size_t>(kLong));

  PoseHistoryOptions ho;
  ho.capacity = kLong;
  ho.max_prediction_ns = o.max_prediction_ns;
  ho.max_interpolation_gap_ns = o.max_interpolation_gap_ns;
  PoseHistory reference(ho);
  for (int k = 0; k < kLong; ++k) ASSERT_TRUE(reference.push(analytic_pose(time_of(k), Handedness::right)).ok());

  std::vector<TimeNs> times;
  const TimeNs first = time_of(0), last = time_of(kLong - 1);
  for (TimeNs t = first - kStep; t <= last + 5 * kStep; t += 13'888'889) times.push_back(t);  // 72 Hz, forward
  std::mt19937_64 rng(7);
  for (int i = 0; i < 400; ++i) times.push_back(first - kStep + static_cast<TimeNs>(rng() % (last - first + 3 * kStep)));
  for (int k : {0, 1, 1199, 1200, kLong - 1}) times.push_back(time_of(k));  // exact samples, around the gap
  times.push_back(time_of(1199) + 100 * kNsPerMillisecond);  // inside the gap

  std::size_t usable = 0;
  for (const TimeNs t : times) {
    SCOPED_TRACE("file time " + std::to_string(t));
    HandPose got, want;
    ASSERT_TRUE(src->wait_until_buffered(t));  // the reader thread moves the windows there
    const PoseLookup r = src->lookup(Handedness::right, t, got);
    ASSERT_EQ(r, reference.lookup(t, want));
    if (is_usable(r)) {
      ++usable;
      EXPECT_EQ(got.joint(HandJoint::wrist).p, want.joint(HandJoint::wrist).p);
      EXPECT_EQ(got.joint(HandJoint::index_tip).q.coeffs(), want.joint(HandJoint::index_tip).q.coeffs());
    }
    HandPose left;
    EXPECT_EQ(src->lookup(Handedness::left, t, left), r);
    EXPECT_LE(src->buffered_samples(), 2 * o.window_samples);
    EXPECT_LE(src->index_entries(), 2 * o.max_index_entries);
  }
  EXPECT_GT(usable, times.size() / 2);
  EXPECT_FALSE(src->read_failed());
}

// lookup() runs on the host app's frame thread: it answers from the window
// the reader thread filled, and never reads the file itself, even where the
// window does not reach (it used to read, allocate and wait on the disk there).
TEST(ReplayHandSource, LookupAnswersFromTheWindowAndLeavesReadingToTheReaderThread) {
  TempDir dir;
  const fs::path path = dir / "long.prec";
  constexpr int kLong = 3000;
  write_recording(path, {{"hand/right", Handedness::right}}, kLong);
  ReplayOptions o;
  o.window_samples = 16;
  o.max_index_entries = 16;
  auto src = ReplayHandSource::open(path, o);
  ASSERT_TRUE(src.ok()) << src.error().message;
  const TimeNs here = kStart + 1000 * kStep + kStep / 2;
  ASSERT_TRUE(src->wait_until_buffered(here));
  src->pause_reading_for_testing(true);

  HandPose got;
  ASSERT_EQ(src->lookup(Handedness::right, here, got), PoseLookup::interpolated);
  EXPECT_LT((got.joint(HandJoint::wrist).p - wrist_position(here)).norm(), 1e-12);
  // Further on than the window reaches: the newest pose read, flagged stale.
  const TimeNs far = kStart + 2500 * kStep;
  ASSERT_EQ(src->lookup(Handedness::right, far, got), PoseLookup::stale);
  EXPECT_GT(got.time_ns, here);
  EXPECT_LT(got.time_ns, far);
  // Before the window: too old, until the reader has gone back.
  EXPECT_EQ(src->lookup(Handedness::right, kStart + 10 * kStep, got), PoseLookup::too_old);
  EXPECT_LE(src->buffered_samples(), o.window_samples);

  // The reader catches up with the latest lookup (kStart + 10 steps) once it may.
  src->pause_reading_for_testing(false);
  ASSERT_TRUE(src->wait_until_buffered(far));
  EXPECT_EQ(src->lookup(Handedness::right, far, got), PoseLookup::exact);
  EXPECT_EQ(got.joint(HandJoint::wrist).p, analytic_pose(far, Handedness::right).joint(HandJoint::wrist).p);
  EXPECT_FALSE(src->read_failed());
}

// The file is cut short under an open source: the window still answers, and
// the reader, not the lookup, finds out; lookups then answer empty.
TEST(ReplayHandSource, AFileCutShortAfterOpenStopsTheReaderNotTheLookups) {
  TempDir dir;
  const fs::path path = dir / "cut.prec";
  write_recording(path, {{"hand/right", Handedness::right}}, 3000);
  ReplayOptions o;
  o.window_samples = 16;
  auto src = ReplayHandSource::open(path, o);
  ASSERT_TRUE(src.ok()) << src.error().message;
  const TimeNs here = kStart + 100 * kStep;
  ASSERT_TRUE(src->wait_until_buffered(here));
  src->pause_reading_for_testing(true);  // else it may meet the cut while reading ahead
  fs::resize_file(path, 0);
  HandPose got;
  EXPECT_EQ(src->lookup(Handedness::right, here, got), PoseLookup::exact);
  src->pause_reading_for_testing(false);
  EXPECT_FALSE(src->wait_until_buffered(kStart + 2000 * kStep));
  EXPECT_TRUE(src->read_failed());
  EXPECT_EQ(src->lookup(Handedness::right, here, got), PoseLookup::empty);
  auto pose = src->pose_at(Handedness::right, here);
  ASSERT_FALSE(pose.ok());
  EXPECT_EQ(pose.error().code, Errc::io_error);
}

// A looping replay wraps in time: each pass answers as the first did, the
// reader starting over from the file's beginning each time.
TEST(ReplayHandSource, LoopingStartsOverAtTheEnd) {
  TempDir dir;
  write_recording(dir / "loop.prec", {{"hand/right", Handedness::right}});
  ReplayOptions o;
  o.loop = true;
  o.window_samples = 8;
  auto src = ReplayHandSource::open(dir / "loop.prec", o);
  ASSERT_TRUE(src.ok()) << src.error().message;
  const DurationNs span = (kSamples - 1) * kStep;
  for (int pass = 0; pass < 3; ++pass) {
    for (const int k : {1, 40, 97}) {
      const TimeNs file_t = kStart + k * kStep + kStep / 3;
      const TimeNs t = file_t + pass * span;
      SCOPED_TRACE("pass " + std::to_string(pass) + ", sample " + std::to_string(k));
      ASSERT_TRUE(src->wait_until_buffered(t));
      HandPose got;
      ASSERT_EQ(src->lookup(Handedness::right, t, got), PoseLookup::interpolated);
      EXPECT_EQ(got.time_ns, t);
      EXPECT_LT((got.joint(HandJoint::wrist).p - wrist_position(file_t)).norm(), 1e-12);
    }
  }
  EXPECT_LE(src->buffered_samples(), o.window_samples);
}

TEST(ReplayHandSource, AnIsolatedFarFutureStampCostsOnePose) {
  TempDir dir;
  const fs::path path = dir / "stamp.prec";
  // Pose 50 carries a CLOCK_REALTIME stamp: it used to end the replay there.
  write_recording(path, {{"hand/right", Handedness::right}}, kSamples,
                  [](int k) { return k == 50 ? TimeNs{1'700'000'000'000'000'000} : kStart + k * kStep; });
  auto src = ReplayHandSource::open(path);
  ASSERT_TRUE(src.ok()) << src.error().message;
  EXPECT_EQ(src->skipped_samples(), 1u);
  EXPECT_EQ(src->streams()[0].samples, static_cast<std::size_t>(kSamples - 1));
  EXPECT_EQ(src->file_time_range().last_ns, kStart + (kSamples - 1) * kStep);
  EXPECT_TRUE(src->pose_at(Handedness::right, kStart + 80 * kStep).ok());
  auto check = check_replay_file(path);
  ASSERT_TRUE(check.ok());
  EXPECT_TRUE(check->damaged);
  EXPECT_NE(check->problem.find("1 hand poses out of time order"), std::string::npos) << check->problem;
}

TEST(ReplayHandSource, CheckReplayFileSaysWhatIsWrong) {
  TempDir dir;
  const fs::path good = dir / "good.prec";
  write_recording(good, {{"hand/right", Handedness::right}});
  auto ok = check_replay_file(good);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_FALSE(ok->damaged);
  EXPECT_EQ(ok->problem, "");

  const fs::path cut = dir / "cut.prec";
  fs::copy_file(good, cut);
  fs::resize_file(cut, fs::file_size(cut) - 1000);
  auto truncated = check_replay_file(cut);
  ASSERT_TRUE(truncated.ok());
  EXPECT_TRUE(truncated->damaged);
  EXPECT_NE(truncated->problem.find("cut short"), std::string::npos) << truncated->problem;

  // A flipped byte mid-file: the rest still plays, and the check says so.
  const fs::path bad = dir / "bad.prec";
  fs::copy_file(good, bad);
  {
    std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(fs::file_size(bad) / 2));
    f.put('\x55');
  }
  auto corrupt = check_replay_file(bad);
  ASSERT_TRUE(corrupt.ok()) << corrupt.error().message;
  EXPECT_TRUE(corrupt->damaged);
  EXPECT_EQ(corrupt->summary.end, RecordingEnd::corrupt);
  EXPECT_NE(corrupt->problem.find("damaged"), std::string::npos) << corrupt->problem;
  EXPECT_GE(corrupt->streams.at(0).samples, static_cast<std::size_t>(kSamples - 2));
}

}  // namespace
}  // namespace proprio
