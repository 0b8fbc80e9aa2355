#include "proprio/core/replay_source.hpp"

#include <algorithm>
#include <array>
#include <iterator>
#include <map>
#include <optional>
#include <utility>

namespace proprio {

namespace {

constexpr std::string_view kGroundTruth = "ground_truth";

std::string quoted_names(const std::vector<const StreamInfo*>& streams, bool with_kind) {
  std::string out;
  for (const StreamInfo* s : streams) {
    out += (out.empty() ? "'" : ", '") + s->name + "'";
    if (with_kind) out += " (" + std::string(to_string(s->kind)) + ")";
  }
  return out.empty() ? "none" : out;
}

using PoseCounts = std::map<std::pair<StreamId, Handedness>, std::size_t>;

// Visits every HandPose in the file; records the reader rejects are left out.
template <typename F>
Result<RecordingReader> for_each_pose(const std::filesystem::path& path, F&& visit) {
  auto reader = RecordingReader::open(path);
  if (!reader) return reader.error();
  for (;;) {
    auto rec = reader->next();
    if (!rec) {
      if (rec.error().code != Errc::parse_error) return rec.error();
      continue;
    }
    if (!*rec) break;
    if (const auto* pose = std::get_if<HandPose>(&(*rec)->payload)) visit((*rec)->stream, *pose);
  }
  return reader;
}

}  // namespace

Result<ReplayHandSource> ReplayHandSource::open(const std::filesystem::path& path, ReplayOptions options) {
  const std::string file = "'" + path.string() + "'";

  // Pass 1 counts poses per (stream, hand) so that pass 2 can size each history
  // for the whole file without holding the poses twice.
  PoseCounts counts;
  auto scan = for_each_pose(path, [&](StreamId id, const HandPose& p) { ++counts[{id, p.hand}]; });
  if (!scan) return scan.error();

  std::vector<const StreamInfo*> pose_streams, all_streams;
  for (const StreamInfo& s : scan->streams()) {
    all_streams.push_back(&s);
    if (s.kind == StreamKind::hand_pose) pose_streams.push_back(&s);
  }
  if (pose_streams.empty()) {
    return make_error(Errc::not_found, "recording " + file + " holds no hand_pose stream to replay (its streams: " +
                                           quoted_names(all_streams, true) + ")");
  }

  const std::string& filter = options.stream_name_filter;
  const bool exact = std::any_of(pose_streams.begin(), pose_streams.end(),
                                 [&](const StreamInfo* s) { return s->name == filter; });
  const auto selected = [&](const StreamInfo& s) {
    return exact ? s.name == filter : s.name.find(filter) != std::string::npos;
  };
  if (!filter.empty() && std::none_of(pose_streams.begin(), pose_streams.end(),
                                      [&](const StreamInfo* s) { return selected(*s); })) {
    return make_error(Errc::not_found, "no hand_pose stream of recording " + file + " matches '" + filter +
                                           "'; its hand_pose streams are: " + quoted_names(pose_streams, false));
  }

  ReplayHandSource src;
  std::array<std::optional<StreamId>, 2> chosen;
  for (const Handedness hand : {Handedness::left, Handedness::right}) {
    std::vector<const StreamInfo*> candidates;
    for (const StreamInfo* s : pose_streams) {
      if (counts.count({s->id, hand}) && selected(*s)) candidates.push_back(s);
    }
    if (filter.empty()) {
      std::vector<const StreamInfo*> tracked;
      std::copy_if(candidates.begin(), candidates.end(), std::back_inserter(tracked),
                   [](const StreamInfo* s) { return s->name.find(kGroundTruth) == std::string::npos; });
      if (!tracked.empty()) candidates = std::move(tracked);
    }
    if (candidates.size() > 1) {
      return make_error(Errc::invalid_argument, "recording " + file + " has " + std::string(to_string(hand)) +
                                                    "-hand poses in several streams (" +
                                                    quoted_names(candidates, false) +
                                                    "); pick one with ReplayOptions::stream_name_filter");
    }
    if (candidates.empty()) continue;
    const StreamInfo& s = *candidates.front();
    chosen[static_cast<std::size_t>(hand)] = s.id;
    src.streams_.push_back({s.name, hand, 0});
  }
  if (src.streams_.empty()) {
    return make_error(Errc::unavailable, "recording " + file + " has no hand poses in its hand_pose streams (" +
                                             quoted_names(pose_streams, false) + ")");
  }

  for (const Handedness hand : {Handedness::left, Handedness::right}) {
    const auto& id = chosen[static_cast<std::size_t>(hand)];
    PoseHistoryOptions ho;
    ho.capacity = id ? counts[{*id, hand}] : 0;
    ho.max_prediction_ns = options.max_prediction_ns;
    ho.max_interpolation_gap_ns = options.max_interpolation_gap_ns;
    src.histories_.emplace_back(ho);
  }
  auto load = for_each_pose(path, [&](StreamId id, const HandPose& p) {
    const auto h = static_cast<std::size_t>(p.hand);
    if (chosen[h] != id) return;
    if (!src.histories_[h].push(p)) ++src.skipped_;
  });
  if (!load) return load.error();

  bool first = true;
  for (ReplayStream& s : src.streams_) {
    const PoseHistory& h = src.history(s.hand);
    s.samples = h.size();
    src.range_.first_ns = first ? h.oldest_time_ns() : std::min(src.range_.first_ns, h.oldest_time_ns());
    src.range_.last_ns = first ? h.newest_time_ns() : std::max(src.range_.last_ns, h.newest_time_ns());
    first = false;
  }
  src.summary_ = load->summary();
  src.path_ = path.string();
  src.offset_ns_ = options.time_offset_ns;
  src.loop_ = options.loop;
  return src;
}

bool ReplayHandSource::to_file_time(TimeNs t_ns, TimeNs& file_t) const noexcept {
  if (__builtin_sub_overflow(t_ns, offset_ns_, &file_t)) return false;
  const DurationNs span = range_.last_ns - range_.first_ns;
  if (loop_ && span > 0) {
    DurationNs into = (file_t - range_.first_ns) % span;
    if (into < 0) into += span;
    file_t = range_.first_ns + into;
  }
  return true;
}

PoseLookup ReplayHandSource::lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept {
  if (!available(hand)) return PoseLookup::empty;
  TimeNs file_t = 0;
  if (!to_file_time(t_ns, file_t)) return PoseLookup::too_old;
  const PoseLookup r = history(hand).lookup(file_t, out);
  if (is_usable(r)) out.time_ns = t_ns;
  if (r == PoseLookup::stale) out.time_ns += t_ns - file_t;  // back to the caller's clock
  return r;
}

bool ReplayHandSource::available(Handedness hand) const noexcept {
  return static_cast<std::size_t>(hand) < histories_.size() && !history(hand).empty();
}

Result<HandPose> ReplayHandSource::pose_at(Handedness hand, TimeNs t_ns) {
  const std::string hand_name(to_string(hand));
  if (!available(hand)) {
    return make_error(Errc::unavailable, "replay of '" + path_ + "' has no " + hand_name + "-hand poses");
  }
  TimeNs file_t = 0;
  if (!to_file_time(t_ns, file_t)) {
    return make_error(Errc::out_of_range, "replay of '" + path_ + "': t=" + std::to_string(t_ns) +
                                              " ns minus the time offset overflows");
  }
  auto q = history(hand).query(file_t);
  if (!q) {
    return q.error().with_context("replay of '" + path_ + "', " + hand_name + " hand at t=" +
                                  std::to_string(t_ns) + " ns (file time " + std::to_string(file_t) +
                                  " ns; the recording spans " + std::to_string(range_.first_ns) + ".." +
                                  std::to_string(range_.last_ns) + " ns, time offset " +
                                  std::to_string(offset_ns_) + " ns)");
  }
  HandPose pose = std::move(q.value().pose);
  pose.time_ns = t_ns;
  return pose;
}

}  // namespace proprio
