#include "proprio/vist/vist_session.hpp"

#include <nlohmann/json.hpp>

namespace proprio::vist {
namespace {

std::string side(Handedness h) { return std::string(to_string(h)); }
constexpr const char* kImuStreamPrefix = "imu/";
// Samples the device flagged as clipped go to streams of their own (the
// recording's IMU record has no flag), so a replay treats them as the live
// tracker did. Index: accel_clipped + 2 * gyro_clipped.
constexpr std::array<const char*, 4> kClipSuffix{"", "/clipped/accel", "/clipped/gyro", "/clipped/both"};

}  // namespace

Result<VistSessionWriter> VistSessionWriter::create(const std::filesystem::path& path, const VistSessionInfo& info,
                                                    bool overwrite) {
  RecordingWriterOptions o;
  o.overwrite = overwrite;
  auto w = RecordingWriter::create(path, o);
  if (!w) return w.error();
  VistSessionWriter s(std::move(*w));
  nlohmann::json meta = {{"glove_toml", info.glove.to_toml()},
                         {"hand", side(info.hand)},
                         {"nominal_hand_length_m", info.nominal_hand_length_m},
                         {"nominal_hand_width_m", info.nominal_hand_width_m}};
  auto m = s.writer_.add_stream(StreamKind::markers, kVistMarkersStream, meta.dump());
  if (!m) return m.error();
  s.markers_ = *m;
  auto c = s.writer_.add_stream(StreamKind::rigid_pose, kVistLeftCamStream,
                                R"({"what":"T_world_leftcam at each stereo frame's capture time"})");
  if (!c) return c.error();
  s.leftcam_ = *c;
  auto t = s.writer_.add_stream(StreamKind::hand_pose, "hand/" + side(info.hand) + "/ground_truth");
  if (!t) return t.error();
  s.truth_ = *t;
  auto o2 = s.writer_.add_stream(StreamKind::hand_pose, "hand/" + side(info.hand) + "/vist");
  if (!o2) return o2.error();
  s.output_ = *o2;
  s.imu_streams_[0].resize(info.glove.imus.size());
  for (std::size_t i = 0; i < info.glove.imus.size(); ++i) {
    nlohmann::json im = {{"sensor_id", i}, {"mount", info.glove.imus[i].name}};
    auto id = s.writer_.add_stream(StreamKind::imu, kImuStreamPrefix + std::to_string(i), im.dump());
    if (!id) return id.error();
    s.imu_streams_[0][i] = *id;
  }
  if (auto st = s.writer_.flush(); !st) return st.error();
  return s;
}

Result<StreamId> VistSessionWriter::imu_stream(std::uint16_t sensor_id, std::size_t clip) {
  auto& streams = imu_streams_[clip];
  if (sensor_id >= streams.size()) streams.resize(sensor_id + 1u);
  if (!streams[sensor_id]) {
    auto id = writer_.add_stream(StreamKind::imu, kImuStreamPrefix + std::to_string(sensor_id) + kClipSuffix[clip]);
    if (!id) return id.error();
    streams[sensor_id] = *id;
  }
  return *streams[sensor_id];
}

Status VistSessionWriter::write_imu(const TimedImuSample& s) {
  auto id = imu_stream(s.sample.sensor_id, (s.accel_clipped ? 1u : 0u) + (s.gyro_clipped ? 2u : 0u));
  if (!id) return id.error();
  return writer_.write(*id, s.sample, s.time_ns);
}

Status VistSessionWriter::write_stereo_frame(TimeNs capture_time_ns, const MarkerObservations& left,
                                             const MarkerObservations& right, const Pose& T_world_leftcam) {
  if (auto st = writer_.write(leftcam_, RigidPose{T_world_leftcam}, capture_time_ns); !st) return st;
  MarkerObservations l = left, r = right;
  l.camera_id = 0;
  r.camera_id = 1;
  if (auto st = writer_.write(markers_, l, capture_time_ns); !st) return st;
  if (auto st = writer_.write(markers_, r, capture_time_ns); !st) return st;
  return writer_.flush();
}

Status VistSessionWriter::write_ground_truth(const HandPose& pose) { return writer_.write(truth_, pose); }
Status VistSessionWriter::write_output(const HandPose& pose) { return writer_.write(output_, pose); }
Status VistSessionWriter::close() { return writer_.close(); }

Result<VistSessionReader> VistSessionReader::open(const std::filesystem::path& path) {
  auto r = RecordingReader::open(path);
  if (!r) return r.error();
  VistSessionReader s(std::move(*r));
  // Stream definitions come before their data; read until the markers stream
  // (with the glove) is known, keeping the first data record for next().
  while (!s.reader_.find_stream(kVistMarkersStream)) {
    auto rec = s.reader_.next();
    if (!rec) return rec.error().with_context(path.string());
    if (!*rec) {
      return make_error(Errc::parse_error,
                        path.string() + ": not a VIST session: it has no '" + std::string(kVistMarkersStream) +
                            "' stream (record one with 'proprio sim-vist' or a live VIST source)");
    }
    if (!s.lookahead_) s.lookahead_ = std::move(**rec);
  }
  const std::string& meta = s.reader_.find_stream(kVistMarkersStream)->meta;
  try {
    const auto j = nlohmann::json::parse(meta);
    auto glove = ImuGloveDescription::parse(j.at("glove_toml").get<std::string>(), path.string() + " (glove_toml)");
    if (!glove) return glove.error();
    s.info_.glove = std::move(*glove);
    const auto hand = j.value("hand", std::string("right"));
    if (hand != "left" && hand != "right") {
      return make_error(Errc::parse_error, path.string() + ": markers meta: hand must be \"left\" or \"right\", not \"" +
                                               hand + "\"");
    }
    s.info_.hand = hand == "left" ? Handedness::left : Handedness::right;
    s.info_.nominal_hand_length_m = j.value("nominal_hand_length_m", s.info_.nominal_hand_length_m);
    s.info_.nominal_hand_width_m = j.value("nominal_hand_width_m", s.info_.nominal_hand_width_m);
  } catch (const nlohmann::json::exception& e) {
    return make_error(Errc::parse_error, path.string() + ": the '" + std::string(kVistMarkersStream) +
                                             "' stream's meta is not the expected JSON: " + e.what());
  }
  return s;
}

Result<std::optional<VistSessionItem>> VistSessionReader::next() {
  auto pull = [&]() -> Result<std::optional<Record>> {
    if (lookahead_) {
      std::optional<Record> r = std::move(lookahead_);
      lookahead_.reset();
      return r;
    }
    for (;;) {
      auto r = reader_.next();
      if (r) return std::move(*r);
      ++skipped_;  // an intact record with bad content: skip it, go on
    }
  };
  std::optional<VistStereoFrame> frame;  // pose seen, images pending
  int images = 0;
  for (;;) {
    auto rec = pull();
    if (!rec) return rec.error();
    if (!*rec) return std::optional<VistSessionItem>{};
    Record& r = **rec;
    const StreamInfo* info = reader_.stream(r.stream);
    const std::string& name = info ? info->name : std::string();
    if (auto* imu = std::get_if<ImuSample>(&r.payload)) {
      if (frame) ++skipped_;  // a frame cut short by IMU data: incomplete, dropped
      frame.reset();
      TimedImuSample s{r.time_ns, *imu};
      for (std::size_t clip = 1; clip < kClipSuffix.size(); ++clip) {
        if (!name.ends_with(kClipSuffix[clip])) continue;
        s.accel_clipped = (clip & 1u) != 0;
        s.gyro_clipped = (clip & 2u) != 0;
      }
      return std::optional<VistSessionItem>{s};
    }
    if (auto* rp = std::get_if<RigidPose>(&r.payload); rp && name == kVistLeftCamStream) {
      if (frame) ++skipped_;
      frame.emplace();
      frame->capture_time_ns = r.time_ns;
      frame->T_world_leftcam = rp->T_world_body;
      images = 0;
      continue;
    }
    if (auto* mo = std::get_if<MarkerObservations>(&r.payload); mo && name == kVistMarkersStream) {
      if (!frame || frame->capture_time_ns != r.time_ns || mo->camera_id > 1) {
        ++skipped_;
        continue;
      }
      (mo->camera_id == 0 ? frame->left : frame->right) = std::move(*mo);
      if (++images == 2) {
        VistStereoFrame f = std::move(*frame);
        return std::optional<VistSessionItem>{std::move(f)};
      }
      continue;
    }
    if (auto* hp = std::get_if<HandPose>(&r.payload); hp && name.ends_with("/ground_truth")) {
      return std::optional<VistSessionItem>{VistGroundTruth{*hp}};
    }
    // Tracker outputs, events and anything else: not input.
  }
}

}  // namespace proprio::vist
