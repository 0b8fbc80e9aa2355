// proprio replay: read a recording back, say what is in it and whether it is
// intact, and play its hand poses through the replay HandSource.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/core/replay_source.hpp"
#include "svg_plot.hpp"

namespace proprio::cli {

namespace {

struct ReplayArgs {
  std::string file;
  bool summary = false;
  std::size_t print_records = 0;
  std::string plot;
  double replay_rate_hz = 72.0;
};

struct StreamStats {
  std::uint64_t count = 0;
  TimeNs first = 0, last = 0;
};

// Motion of one hand-pose stream, accumulated record by record.
struct HandStats {
  std::uint64_t poses = 0;
  double wrist_path_m = 0.0;
  double tip_speed_sum = 0.0;
  std::optional<Vec3> last_wrist;
  std::optional<HandPose> last_pose;
  std::optional<HandModel> model;  // from the stream's meta, for the IK check
  double ik_error_sum_rad = 0.0, ik_error_max_rad = 0.0;
  std::uint64_t ik_checked = 0;
};

struct AngleStats {
  std::vector<std::string> dof_names;
  std::vector<double> min, max;
};

std::optional<nlohmann::json> parse_meta(const std::string& meta) {
  auto j = nlohmann::json::parse(meta, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return std::nullopt;
  return j;
}

std::string describe_record(const RecordingReader& reader, const Record& r) {
  const StreamInfo* s = reader.stream(r.stream);
  char head[128];
  std::snprintf(head, sizeof head, "%12.6f s  %-36s ", ns_to_seconds(r.time_ns), s ? printable(s->name, 60).c_str() : "?");
  std::string body = std::visit(
      [](const auto& p) -> std::string {
        using T = std::decay_t<decltype(p)>;
        char buf[160];
        if constexpr (std::is_same_v<T, HandPose>) {
          const Vec3 w = p.joint(HandJoint::wrist).p;
          std::snprintf(buf, sizeof buf, "%s hand %s, wrist at (%.3f, %.3f, %.3f) m", std::string(to_string(p.hand)).c_str(),
                        p.active ? "active" : "inactive", w.x(), w.y(), w.z());
        } else if constexpr (std::is_same_v<T, JointAngles>) {
          std::snprintf(buf, sizeof buf, "%zu joint angles", p.angles_rad.size());
        } else if constexpr (std::is_same_v<T, RigidPose>) {
          std::snprintf(buf, sizeof buf, "at (%.3f, %.3f, %.3f) m", p.T_world_body.p.x(), p.T_world_body.p.y(),
                        p.T_world_body.p.z());
        } else if constexpr (std::is_same_v<T, Event>) {
          return "\"" + printable(p.text) + "\"";
        } else if constexpr (std::is_same_v<T, ImuSample>) {
          std::snprintf(buf, sizeof buf, "IMU %u accel (%.2f, %.2f, %.2f) m/s2", p.sensor_id, p.accel_mps2.x(),
                        p.accel_mps2.y(), p.accel_mps2.z());
        } else if constexpr (std::is_same_v<T, MarkerObservations>) {
          std::snprintf(buf, sizeof buf, "camera %u, %zu markers", p.camera_id, p.markers.size());
        } else if constexpr (std::is_same_v<T, CapacitanceFrame>) {
          std::snprintf(buf, sizeof buf, "%zu capacitances", p.values_F.size());
        } else {
          std::snprintf(buf, sizeof buf, "%zu raw bytes", p.bytes.size());
        }
        return buf;
      },
      r.payload);
  return head + body;
}

// Keeps a plot series bounded on long recordings: past kMaxPoints it drops
// every other point and from then on keeps every second one (and so on).
struct Thinning {
  std::uint64_t seen = 0;
  unsigned shift = 0;
};
void append_thinned(PlotSeries& s, Thinning& th, double x, double y) {
  constexpr std::size_t kMaxPoints = 20000;
  const std::uint64_t keep_every = std::uint64_t{1} << th.shift;
  if (th.seen++ % keep_every != 0) return;
  s.x.push_back(x);
  s.y.push_back(y);
  if (s.x.size() < kMaxPoints) return;
  std::size_t w = 0;
  for (std::size_t r = 0; r < s.x.size(); r += 2, ++w) s.x[w] = s.x[r], s.y[w] = s.y[r];
  s.x.resize(w);
  s.y.resize(w);
  ++th.shift;
}

int run_replay(const ReplayArgs& a) {
  auto reader = RecordingReader::open(a.file);
  if (!reader) return logger().error("{}", reader.error().message), 1;

  std::map<StreamId, StreamStats> stats;
  std::map<StreamId, HandStats> hands;
  std::map<StreamId, AngleStats> angles;
  std::uint64_t rejected = 0;
  std::size_t printed = 0;
  const bool plotting = !a.plot.empty();
  std::array<Thinning, 3> wrist_thinning{};
  std::array<Thinning, 4> finger_thinning{};

  // Plot data (write_svg_plot thins long series).
  PlotPanel finger_panel{"Index finger and thumb joint angles (ground truth)", "deg", {}};
  PlotPanel wrist_panel{"Wrist position", "m", {}};
  const char* plotted_dofs[] = {"index_mcp_flexion", "index_pip_flexion", "index_mcp_abduction", "thumb_cmc_flexion"};
  for (const char* d : plotted_dofs) finger_panel.series.push_back({d, {}, {}});
  for (const char* axis : {"wrist x", "wrist y", "wrist z"}) wrist_panel.series.push_back({axis, {}, {}});

  // A damaged file can reject thousands of records: show the first few, count the rest.
  constexpr std::uint64_t kShownWarnings = 5;
  ProgressBar progress("replay", 1.0, "of file");
  while (true) {
    auto next = reader->next();
    if (!next) {
      if (++rejected <= kShownWarnings) logger().warn("{}", printable(next.error().message, 400));
      continue;
    }
    if (!next->has_value()) break;
    const Record& r = **next;
    StreamStats& st = stats[r.stream];
    if (st.count++ == 0) st.first = r.time_ns;
    st.last = r.time_ns;
    if (printed < a.print_records) {
      std::printf("%s\n", describe_record(*reader, r).c_str());
      ++printed;
    }
    const StreamInfo* info = reader->stream(r.stream);
    if (const auto* pose = std::get_if<HandPose>(&r.payload); pose && pose->active) {
      HandStats& h = hands[r.stream];
      if (h.poses == 0 && info) {
        if (auto meta = parse_meta(info->meta); meta && meta->contains("hand_length_m") && meta->contains("hand_width_m")) {
          if (auto shape = HandShape::from_measurements((*meta)["hand_length_m"].get<double>(),
                                                        (*meta)["hand_width_m"].get<double>())) {
            h.model.emplace(*shape);
          }
        }
      }
      const Vec3 wrist = pose->joint(HandJoint::wrist).p;
      if (h.last_wrist) h.wrist_path_m += (wrist - *h.last_wrist).norm();
      h.last_wrist = wrist;
      if (pose->has_velocity) h.tip_speed_sum += pose->linear_velocity_in_world[index_of(HandJoint::index_tip)].norm();
      for (int i = 0; i < 3 && plotting; ++i) {
        const auto k = static_cast<std::size_t>(i);
        append_thinned(wrist_panel.series[k], wrist_thinning[k], ns_to_seconds(r.time_ns), wrist[i]);
      }
      ++h.poses;
      h.last_pose = *pose;
    }
    if (const auto* ja = std::get_if<JointAngles>(&r.payload)) {
      AngleStats& as = angles[r.stream];
      if (as.dof_names.empty() && info) {
        if (auto meta = parse_meta(info->meta); meta && meta->contains("dof_names")) {
          for (const auto& n : (*meta)["dof_names"]) as.dof_names.push_back(n.get<std::string>());
        }
      }
      if (as.min.empty()) as.min = as.max = ja->angles_rad;
      for (std::size_t i = 0; i < std::min(as.min.size(), ja->angles_rad.size()); ++i) {
        as.min[i] = std::min(as.min[i], ja->angles_rad[i]);
        as.max[i] = std::max(as.max[i], ja->angles_rad[i]);
      }
      for (std::size_t f = 0; f < finger_panel.series.size(); ++f) {
        PlotSeries& series = finger_panel.series[f];
        const auto it = std::find(as.dof_names.begin(), as.dof_names.end(), series.label);
        const auto i = static_cast<std::size_t>(it - as.dof_names.begin());
        if (i < ja->angles_rad.size() && plotting) {
          append_thinned(series, finger_thinning[f], ns_to_seconds(r.time_ns), rad_to_deg(ja->angles_rad[i]));
        }
      }
      // Recorded angles against IK of the pose recorded at the same instant:
      // checks that poses and angles in the file describe the same hand.
      for (auto& [id, h] : hands) {
        if (h.model && h.last_pose && h.last_pose->time_ns == r.time_ns && h.last_pose->hand == ja->hand &&
            ja->angles_rad.size() == kHandDofCount) {
          const auto ik = h.model->inverse(*h.last_pose);
          for (std::size_t i = 0; i < kHandDofCount; ++i) {
            const double e = std::abs(ik.angles[i] - ja->angles_rad[i]);
            h.ik_error_sum_rad += e;
            h.ik_error_max_rad = std::max(h.ik_error_max_rad, e);
          }
          ++h.ik_checked;
        }
      }
    }
    progress.update(0.5);
  }
  progress.finish();

  const RecordingSummary& sum = reader->summary();
  TimeNs t0 = INT64_MAX, t1 = INT64_MIN;
  for (const auto& [id, st] : stats) t0 = std::min(t0, st.first), t1 = std::max(t1, st.last);
  // In double: time stamps from a damaged or foreign file can be anything.
  const double span = stats.empty() ? 0.0 : 1e-9 * (static_cast<double>(t1) - static_cast<double>(t0));
  std::printf("Recording %s (format %u.%u): %zu streams, %llu records, %.2f s\n", printable(a.file, 300).c_str(),
              reader->format_major(), reader->format_minor(), reader->streams().size(),
              static_cast<unsigned long long>(sum.records), span);
  std::printf("Integrity: %s%s%s\n", to_string(sum.end), sum.detail.empty() ? "" : ": ",
              printable(sum.detail, 1000).c_str());
  if (rejected) {
    std::printf("  %llu records were rejected (the first %llu are shown in the warnings above)\n",
                static_cast<unsigned long long>(rejected),
                static_cast<unsigned long long>(std::min(rejected, kShownWarnings)));
  }
  std::printf("\n  %-38s %-13s %9s %10s  %s\n", "stream", "kind", "records", "rate", "span");
  for (const auto& s : reader->streams()) {
    const StreamStats st = stats.count(s.id) ? stats[s.id] : StreamStats{};
    const double dur = 1e-9 * (static_cast<double>(st.last) - static_cast<double>(st.first));
    char rate[32] = "-";
    if (st.count > 1 && dur > 0) std::snprintf(rate, sizeof rate, "%.1f Hz", static_cast<double>(st.count - 1) / dur);
    std::printf("  %-38s %-13s %9llu %10s  %.3f-%.3f s\n", printable(s.name, 60).c_str(), std::string(to_string(s.kind)).c_str(),
                static_cast<unsigned long long>(st.count), rate, ns_to_seconds(st.first), ns_to_seconds(st.last));
  }

  for (const auto& [id, h] : hands) {
    const StreamInfo* info = reader->stream(id);
    std::printf("\nHand motion in %s: %llu poses, wrist path %.2f m", info ? printable(info->name, 60).c_str() : "?",
                static_cast<unsigned long long>(h.poses), h.wrist_path_m);
    if (h.poses > 0 && h.tip_speed_sum > 0) std::printf(", mean index-tip speed %.3f m/s", h.tip_speed_sum / static_cast<double>(h.poses));
    std::printf("\n");
    if (h.ik_checked > 0) {
      std::printf("  IK of recorded poses vs recorded joint angles: mean %.2e deg, max %.2e deg over %llu frames\n",
                  rad_to_deg(h.ik_error_sum_rad / static_cast<double>(h.ik_checked * kHandDofCount)),
                  rad_to_deg(h.ik_error_max_rad), static_cast<unsigned long long>(h.ik_checked));
    }
  }
  for (const auto& [id, as] : angles) {
    std::printf("\nJoint ranges in %s (deg):\n", printable(reader->stream(id)->name, 60).c_str());
    for (std::size_t i = 0; i < as.min.size(); ++i) {
      const std::string name = i < as.dof_names.size() ? printable(as.dof_names[i], 40) : "dof " + std::to_string(i);
      std::printf("  %-22s %7.1f .. %6.1f%s", name.c_str(), rad_to_deg(as.min[i]), rad_to_deg(as.max[i]),
                  (i % 2 == 1 || i + 1 == as.min.size()) ? "\n" : "   ");
    }
  }

  if (!hands.empty()) {
    auto source = ReplayHandSource::open(a.file);
    if (!source) {
      std::printf("\nReplay source: %s\n", printable(source.error().message, 1000).c_str());
    } else {
      const auto range = source->file_time_range();
      // Query at the replay rate, but never more than kMaxQueries times per
      // hand: a file spanning years (a wall-clock stamp from a foreign
      // writer) is sampled more coarsely, and says so, rather than hanging.
      constexpr double kMaxQueries = 2e6;
      const double span_ns = static_cast<double>(range.last_ns) - static_cast<double>(range.first_ns);
      double step_ns = 1e9 / a.replay_rate_hz;
      const bool thinned = span_ns / step_ns + 1.0 > kMaxQueries;
      if (thinned) step_ns = span_ns / (kMaxQueries - 1.0);
      const auto queries = static_cast<std::uint64_t>(span_ns / step_ns) + 1;
      std::uint64_t served = 0, refused = 0;
      std::string first_refusal;
      if (source->skipped_samples() > 0) {
        std::printf("\nReplay source: %zu hand poses left out (out of time order, or isolated time jumps)\n",
                    source->skipped_samples());
      }
      if (thinned) {
        std::printf("\nThe hand poses span %.3g s: querying %.0f times at %.3g s intervals instead of at %.0f Hz\n",
                    span_ns * 1e-9, kMaxQueries, step_ns * 1e-9, a.replay_rate_hz);
      }
      for (const auto& s : source->streams()) {
        for (std::uint64_t i = 0; i < queries; ++i) {
          const TimeNs t = std::min(range.last_ns, range.first_ns + static_cast<TimeNs>(static_cast<double>(i) * step_ns));
          auto p = source->pose_at(s.hand, t);
          if (p && p->fully_valid()) {
            ++served;
          } else {
            ++refused;
            if (first_refusal.empty()) first_refusal = p ? "pose not fully valid" : p.error().message;
          }
        }
      }
      std::printf("\nReplayed through the replay HandSource at %.0f Hz: %llu poses served, %llu refused%s%s\n",
                  a.replay_rate_hz, static_cast<unsigned long long>(served), static_cast<unsigned long long>(refused),
                  first_refusal.empty() ? "" : " (first: ",
                  first_refusal.empty() ? "" : (printable(first_refusal, 400) + ")").c_str());
    }
  }

  if (!a.plot.empty()) {
    std::vector<PlotPanel> panels;
    if (!finger_panel.series.front().x.empty()) panels.push_back(finger_panel);
    if (!wrist_panel.series.front().x.empty()) panels.push_back(wrist_panel);
    if (panels.empty()) {
      std::printf("\nNothing to plot: no joint angles or hand poses in this recording.\n");
    } else if (auto s = write_svg_plot(a.plot, a.file, "time (s)", panels); !s) {
      return logger().error("{}", s.error().message), 1;
    } else {
      std::printf("\nPlot written to %s (open it in a browser)\n", printable(a.plot, 300).c_str());
    }
  }
  return sum.end == RecordingEnd::clean || sum.end == RecordingEnd::missing_end || sum.end == RecordingEnd::truncated ? 0 : 3;
}

}  // namespace

void add_replay_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ReplayArgs>();
  CLI::App* cmd = add_command(app, "replay");
  cmd->add_option("file", args->file, "Recording (.prec)")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--summary", args->summary, "Print the summary (the default output)");
  cmd->add_option("--records", args->print_records, "Also print the first N records, one per line");
  cmd->add_option("--plot", args->plot, "Write joint angles and wrist position over time to this SVG file");
  cmd->add_option("--replay-rate", args->replay_rate_hz, "Rate at which to query the replay HandSource, Hz")
      ->check(CLI::Range(1.0, 2000.0))
      ->capture_default_str();
  cmd->callback([args, &exit_code] { exit_code = run_replay(*args); });
}

}  // namespace proprio::cli
