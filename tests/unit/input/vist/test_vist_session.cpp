// VIST sessions as recordings: what the tracker consumed, replayed through a
// fresh tracker (`proprio track vist`), and through the live VistHandSource.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <thread>

#include "proprio/core/recording.hpp"
#include "proprio/vist/vist_hand_source.hpp"
#include "proprio/vist/vist_session.hpp"
#include "proprio/vist_eval/evaluation.hpp"

namespace proprio::vist {
namespace {

namespace fs = std::filesystem;

fs::path temp_path(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("proprio_vist_session_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return dir / name;
}

// One short simulated session recorded to a file, shared by the tests.
const fs::path& recorded_session() {
  static const fs::path path = [] {
    auto p = temp_path("s.prec");
    vist_eval::SessionSpec spec;
    spec.subject = 4;
    spec.duration_s = 8.0;
    spec.warmup_s = 2.0;
    spec.record_path = p;
    spec.overwrite_record = true;
    auto r = vist_eval::run_session(ImuGloveDescription::vist_default(), spec);
    EXPECT_TRUE(r) << r.error().message;
    return p;
  }();
  return path;
}

std::vector<HandPose> read_poses(const fs::path& p, const std::string& stream) {
  auto r = RecordingReader::open(p);
  EXPECT_TRUE(r);
  std::vector<HandPose> out;
  for (;;) {
    auto rec = r->next();
    if (!rec || !*rec) break;
    const auto* info = r->stream((*rec)->stream);
    if (info && info->name == stream) out.push_back(std::get<HandPose>((*rec)->payload));
  }
  return out;
}

TEST(VistSession, ReplayReproducesTheLiveTrackerExactly) {
  const auto live = read_poses(recorded_session(), "hand/right/vist");
  ASSERT_GT(live.size(), 500u);
  const auto out = temp_path("tracked.prec");
  vist_eval::TrackSessionOptions o;
  o.output_path = out;
  o.overwrite_output = true;
  o.warmup_s = 2.0;
  auto r = vist_eval::track_session(recorded_session(), o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->recording.end, RecordingEnd::clean);
  EXPECT_EQ(r->skipped_records, 0u);
  EXPECT_EQ(r->info.glove.markers.size(), ImuGloveDescription::vist_default().markers.size());
  ASSERT_TRUE(r->scored);
  // A sanity bound: the session is 8 s of the realistic simulator (flicks,
  // soft tissue, the glove as built); docs/benchmarks.md has the figures.
  EXPECT_LT(r->keypoints.mean_mm, 15.0);
  EXPECT_GT(r->stereo_frames, 200u);

  // The replay sees the same inputs in the same order: the same output, to the bit.
  const auto replayed = read_poses(out, "hand/right/vist");
  ASSERT_GE(replayed.size(), live.size());
  std::size_t compared = 0;
  for (std::size_t i = 0, j = 0; i < live.size() && j < replayed.size();) {
    if (replayed[j].time_ns < live[i].time_ns) {
      ++j;
      continue;
    }
    ASSERT_EQ(replayed[j].time_ns, live[i].time_ns);
    for (std::size_t k = 0; k < kHandJointCount; ++k) {
      ASSERT_EQ(replayed[j].T_world_joint[k].p, live[i].T_world_joint[k].p) << "pose " << i << " joint " << k;
    }
    ++compared, ++i, ++j;
  }
  EXPECT_EQ(compared, live.size());
}

TEST(VistSession, ClippedImuSamplesKeepTheirFlag) {
  // The live tracker rejects samples its device flagged as clipped; a replay
  // must see the same flag, or it fuses what the live tracker did not.
  const auto path = temp_path("clipped.prec");
  VistSessionInfo info;
  info.glove = ImuGloveDescription::vist_default();
  {
    auto w = VistSessionWriter::create(path, info, true);
    ASSERT_TRUE(w) << w.error().message;
    for (int i = 0; i < 4; ++i) {
      TimedImuSample s;
      s.time_ns = 1'000'000 * (i + 1);
      s.sample.sensor_id = 1;
      s.sample.accel_mps2 = Vec3(0.0, i == 2 ? 156.9 : 9.8, 0.0);
      s.accel_clipped = i == 2;
      s.gyro_clipped = i == 3;
      ASSERT_TRUE(w->write_imu(s));
    }
    ASSERT_TRUE(w->close());
  }
  auto r = VistSessionReader::open(path);
  ASSERT_TRUE(r) << r.error().message;
  std::vector<bool> flags;
  for (;;) {
    auto item = r->next();
    ASSERT_TRUE(item) << item.error().message;
    if (!*item) break;
    if (auto* s = std::get_if<TimedImuSample>(&**item)) {
      EXPECT_EQ(s->sample.sensor_id, 1u);
      flags.push_back(s->accel_clipped);
      flags.push_back(s->gyro_clipped);
    }
  }
  EXPECT_EQ(flags, (std::vector<bool>{false, false, false, false, true, false, false, true}));
}

TEST(VistSession, ACrashCutSessionStillReplaysUpToTheCut) {
  const auto cut = temp_path("cut.prec");
  fs::copy_file(recorded_session(), cut, fs::copy_options::overwrite_existing);
  fs::resize_file(cut, fs::file_size(cut) / 2 + 7);  // mid-record
  vist_eval::TrackSessionOptions o;
  o.warmup_s = 1.0;
  auto r = vist_eval::track_session(cut, o);
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->recording.end, RecordingEnd::truncated);
  EXPECT_GT(r->session_seconds, 2.0);
  EXPECT_LT(r->session_seconds, 7.0);
  EXPECT_TRUE(r->scored);
}

TEST(VistSession, RecordingsThatAreNotVistSessionsAreRefusedClearly) {
  const auto p = temp_path("poses_only.prec");
  {
    RecordingWriterOptions o;
    o.overwrite = true;
    auto w = RecordingWriter::create(p, o);
    ASSERT_TRUE(w);
    ASSERT_TRUE(w->add_stream(StreamKind::hand_pose, "hand/right"));
    ASSERT_TRUE(w->close());
  }
  auto r = VistSessionReader::open(p);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("not a VIST session"), std::string::npos) << r.error().message;

  const auto bad_meta = temp_path("bad_meta.prec");
  {
    RecordingWriterOptions o;
    o.overwrite = true;
    auto w = RecordingWriter::create(bad_meta, o);
    ASSERT_TRUE(w);
    ASSERT_TRUE(w->add_stream(StreamKind::markers, kVistMarkersStream, "{\"glove_toml\": 3"));
    ASSERT_TRUE(w->close());
  }
  auto m = VistSessionReader::open(bad_meta);
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("meta"), std::string::npos) << m.error().message;

  EXPECT_FALSE(VistSessionReader::open(temp_path("missing.prec")));
}

TEST(VistHandSource, ServesTheSessionLiveWhileConsumersQueryIt) {
#ifdef __SANITIZE_ADDRESS__
  // Two full tracker runs of the session take minutes under ASan; this test
  // is about locking, so it runs in the main suite and under TSan.
  GTEST_SKIP() << "too slow under AddressSanitizer; covered by the main suite and TSan";
#endif
  // The player runs as fast as it can: a queue that holds the whole session,
  // so nothing is dropped however slowly the worker runs (sanitizers, load).
  VistHandSourceOptions options;
  options.max_queued_inputs = 1u << 20;
  auto source = VistHandSource::create(ImuGloveDescription::vist_default(), options);
  ASSERT_TRUE(source) << source.error().message;
  ManualClock clock(1'000'000'000);
  VistSessionPlayerOptions po;
  po.loop = false;
  po.speed = 0.0;  // as fast as possible
  // A consumer polls while the player and the worker run (TSan checks the locking).
  std::atomic<bool> done{false};
  std::atomic<int> usable{0};
  std::thread consumer([&] {
    HandPose out;
    while (!done.load()) {
      auto s = (*source)->stats();
      if (is_usable((*source)->lookup(Handedness::right, clock.now_ns() + s.tracker.imu_samples * 1'000'000, out))) {
        usable.fetch_add(1);
      }
      EXPECT_EQ((*source)->lookup(Handedness::left, clock.now_ns(), out), PoseLookup::empty);
    }
  });
  auto player = VistSessionPlayer::start(recorded_session(), **source, po, clock);
  ASSERT_TRUE(player) << player.error().message;
  while (!(*player)->finished()) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  (*source)->drain();
  done.store(true);
  consumer.join();

  const auto stats = (*source)->stats();
  EXPECT_EQ(stats.inputs_dropped, 0u);
  EXPECT_GT(stats.poses_published, 500u);
  EXPECT_EQ(stats.poses_rejected, 0u);
  EXPECT_GE(stats.tracker.acquisitions, 1u);
  // The session starts at the clock's time: the last live pose lies ~8 s later
  // and matches the recorded ground truth, shifted the same way.
  const auto truth = read_poses(recorded_session(), "hand/right/ground_truth");
  ASSERT_FALSE(truth.empty());
  const HandPose& last_truth = truth.back();
  TimeNs first_imu = 0;
  {
    auto r = VistSessionReader::open(recorded_session());
    ASSERT_TRUE(r);
    for (;;) {
      auto item = r->next();
      ASSERT_TRUE(item && *item);
      if (auto* s = std::get_if<TimedImuSample>(&**item)) {
        first_imu = s->time_ns;
        break;
      }
    }
  }
  const TimeNs shifted = last_truth.time_ns - first_imu + clock.now_ns();
  auto pose = (*source)->pose_at(Handedness::right, shifted);
  ASSERT_TRUE(pose) << pose.error().message;
  const double err = (pose->joint(HandJoint::index_tip).p - last_truth.joint(HandJoint::index_tip).p).norm();
  EXPECT_LT(err, 0.02) << "index tip " << 1e3 * err << " mm off";
  EXPECT_FALSE((*source)->pose_at(Handedness::left, shifted));
}

TEST(VistHandSource, ABoundedQueueDropsTheOldestInputWhenFlooded) {
  VistHandSourceOptions o;
  o.max_queued_inputs = 4;
  EXPECT_FALSE(VistHandSource::create(ImuGloveDescription::vist_default(), o));
  o.max_queued_inputs = 16;
  auto source = VistHandSource::create(ImuGloveDescription::vist_default(), o);
  ASSERT_TRUE(source);
  TimedImuSample s;
  s.sample.accel_mps2 = Vec3(0, 0, 9.81);
  for (int i = 0; i < 20000; ++i) {
    s.time_ns = 1'000'000'000 + TimeNs{i} * 1'000'000;
    s.sample.sensor_id = static_cast<std::uint16_t>(i % 7);
    (*source)->push_imu(s);
  }
  (*source)->drain();
  const auto st = (*source)->stats();
  EXPECT_EQ(st.tracker.imu_samples + st.inputs_dropped, 20000u);
}

}  // namespace
}  // namespace proprio::vist
