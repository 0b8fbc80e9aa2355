// proprio bench ftm: the FTM glove's evaluation (issue 27 §5) on held-out
// simulated subjects, every case through the full pipeline.
// proprio sim-ftm: one simulated FTM session recorded in the session format,
// optionally tracked and plotted (heading error with and without the
// magnetic-disturbance gate, and the detector's flags).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/ftm/ftm_tracker.hpp"
#include "proprio/ftm_eval/ftm_evaluation.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/ftm_sim/wearer_calibration.hpp"
#include "proprio/sim/subjects.hpp"
#include "svg_plot.hpp"

namespace proprio::cli {
namespace {

struct BenchFtmArgs {
  int subjects = 5;
  double minutes = 1.0;
  std::uint64_t seed = 1;
  std::string cases = "imu_bench,free_motion,pinch_grasp,disturbance";
  bool rigid_skin = false;
  bool json = false;
};

void ftm_progress(void* user, int done, int /*total*/) {
  static_cast<ProgressBar*>(user)->update(static_cast<double>(done));
}

// JSON has no NaN: a metric that could not be computed is null.
nlohmann::json ftm_number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

int run_bench_ftm(const BenchFtmArgs& a) {
  std::vector<ftm_eval::FtmCase> cases;
  std::stringstream list(a.cases);
  for (std::string name; std::getline(list, name, ',');) {
    auto c = ftm_eval::parse_ftm_case(name);
    if (!c) {
      std::fprintf(stderr, "error: --cases: %s\n", c.error().message.c_str());
      return 1;
    }
    cases.push_back(*c);
  }
  if (cases.empty()) {
    std::fprintf(stderr, "error: --cases names no case\n");
    return 1;
  }
  ftm_eval::FtmBenchOptions o;
  o.subjects = a.subjects;
  o.task_s = a.minutes * 60.0;
  o.seed = a.seed;
  if (a.rigid_skin) o.soft_tissue = sim::SoftTissueOptions::rigid();
  if (auto st = o.validate(); !st) {
    std::fprintf(stderr, "error: %s\n", st.error().message.c_str());
    return 1;
  }
  nlohmann::json out = {
      {"held_out_subjects", a.subjects}, {"first_subject", ftm_eval::kFirstHeldOutSubject},
      {"task_minutes", a.minutes},       {"seed", a.seed},
      {"config", o.describe()},          {"note", "simulated subjects; simulated accuracy is not real-world accuracy"},
      {"cases", nlohmann::json::array()}};
  int not_ran = 0;
  std::vector<ftm_eval::FtmCaseResult> results;
  for (auto c : cases) {
    const int total = a.subjects;  // one session (or bench plate) per subject
    ProgressBar progress("bench ftm " + std::string(ftm_eval::to_string(c)), static_cast<double>(total), "sessions");
    results.push_back(ftm_eval::run_ftm_case(c, o, ftm_progress, &progress));
    progress.finish();
  }
  for (const auto& r : results) {
    nlohmann::json j = {{"case", std::string(ftm_eval::to_string(r.which))}, {"ran", r.ran}};
    if (!r.ran) {
      ++not_ran;
      j["reason"] = r.reason;
      std::fprintf(stderr, "bench ftm: case %s did not run: %s\n", std::string(ftm_eval::to_string(r.which)).c_str(),
                   r.reason.c_str());
    } else {
      j["sessions"] = r.sessions;
      for (const auto& [k, v] : r.metrics) j["metrics"][k] = ftm_number(v);
      for (const auto& [k, v] : r.counts) j["counts"][k] = v;
    }
    out["cases"].push_back(j);
  }
  if (a.json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("\nFTM glove on held-out simulated subjects (%d..%d), %.1f min per on-hand session, seed %llu\n",
                ftm_eval::kFirstHeldOutSubject, ftm_eval::kFirstHeldOutSubject + a.subjects - 1, a.minutes,
                static_cast<unsigned long long>(a.seed));
    for (const auto& r : results) {
      std::printf("\n[%s]%s\n", std::string(ftm_eval::to_string(r.which)).c_str(), r.ran ? "" : " DID NOT RUN");
      if (!r.ran) {
        std::printf("  %s\n", r.reason.c_str());
        continue;
      }
      for (const auto& [k, v] : r.metrics) std::printf("  %-44s %10.4g\n", k.c_str(), v);
      for (const auto& [k, v] : r.counts) {
        std::printf("  %-44s %10llu\n", k.c_str(), static_cast<unsigned long long>(v));
      }
    }
  }
  return not_ran == 0 ? 0 : 1;
}

struct SimFtmArgs {
  int subject = 0;
  double seconds = 30.0;
  std::string protocol = "free-motion";
  std::uint64_t seed = 1;
  std::string out;
  std::string truth;
  std::string magnets;
  std::string plot;
  bool force = false;
};

Result<std::vector<ftm_sim::FtmMagneticObject>> parse_magnets(const std::string& list, TimeNs first_ns) {
  std::vector<ftm_sim::FtmMagneticObject> objects;
  std::stringstream in(list);
  TimeNs t = first_ns;
  for (std::string name; std::getline(in, name, ',');) {
    ftm_sim::FtmMagneticObject o;
    if (name == "drill")
      o.kind = ftm_sim::FtmMagneticObject::Kind::drill;
    else if (name == "fan")
      o.kind = ftm_sim::FtmMagneticObject::Kind::fan;
    else if (name == "earphone")
      o.kind = ftm_sim::FtmMagneticObject::Kind::earphone_case;
    else
      return make_error(Errc::invalid_argument, "--magnets: unknown object '" + name + "' (drill, fan, earphone)");
    o.t_start_ns = t;
    // The 10 s disturbance: 2 s approach, 10 s near the hand, 2 s away.
    o.hold_ns = 10 * kNsPerSecond;
    objects.push_back(o);
    t += o.approach_ns + o.hold_ns + o.retreat_ns + 4 * kNsPerSecond;
  }
  return objects;
}

double heading_deg(const Quat& q_est, const Quat& q_true) {
  const Quat e = (q_est * q_true.conjugate()).normalized();
  return rad_to_deg(std::remainder(2.0 * std::atan2(e.y(), e.w()), 2.0 * M_PI));
}

// A device or FIFO as an output would "succeed" (/dev/zero) or block: refused
// before anything is simulated.
Status check_output(const char* option, const std::string& path) {
  std::error_code ec;
  const auto st = std::filesystem::status(path, ec);
  if (!ec && std::filesystem::exists(st) && !std::filesystem::is_regular_file(st) &&
      !std::filesystem::is_directory(st)) {
    return make_error(Errc::invalid_argument, std::string(option) + " '" + path + "' is not a regular file");
  }
  return {};
}

int run_sim_ftm(const SimFtmArgs& a) {
  for (const auto& [option, path] :
       {std::pair<const char*, std::string>{"--out", a.out}, {"--truth", a.truth}, {"--plot", a.plot}}) {
    if (path.empty()) continue;
    if (auto st = check_output(option, path); !st)
      return std::fprintf(stderr, "error: %s\n", st.error().message.c_str()), 1;
  }
  ftm_sim::FtmWearerOptions o;
  o.seed = a.seed;
  o.subject.subject_index = a.subject;
  o.protocol = a.protocol == "pinch-grasp" ? sim::MotionProtocol::pinch_grasp : sim::MotionProtocol::free_motion;
  o.task_s = a.seconds;
  if (!a.magnets.empty()) {
    // Object times are simulation times: a probe wearer says when the task starts.
    auto probe = ftm_sim::FtmWearerSimulator::create(o);
    if (!probe) return std::fprintf(stderr, "error: %s\n", probe.error().message.c_str()), 1;
    auto objects = parse_magnets(a.magnets, (*probe)->task_begin_ns() + 2 * kNsPerSecond);
    if (!objects) return std::fprintf(stderr, "error: %s\n", objects.error().message.c_str()), 1;
    o.magnetic.objects = *objects;
  }
  if (auto st = o.validate(); !st) return std::fprintf(stderr, "error: %s\n", st.error().message.c_str()), 1;
  auto sim = ftm_sim::FtmWearerSimulator::create(o);
  if (!sim) return std::fprintf(stderr, "error: %s\n", sim.error().message.c_str()), 1;
  auto& wearer = **sim;

  // With --plot the session is tracked twice from the wearer's own
  // calibration: compass gated by the detector, and plain.
  std::vector<ftm::FtmEvent> events;
  std::vector<ftm::FtmTracker> trackers;
  if (!a.plot.empty()) {
    auto cal = ftm_sim::calibrate_from_wearer(wearer);
    if (!cal) return std::fprintf(stderr, "error: calibration: %s\n", cal.error().message.c_str()), 1;
    for (bool gate : {true, false}) {
      ftm::FtmTrackerOptions to;
      to.hand = o.hand;
      to.attitude.gate_mag = gate;
      auto tr = ftm::FtmTracker::create(to, cal->outcome.calibration);
      if (!tr) return std::fprintf(stderr, "error: %s\n", tr.error().message.c_str()), 1;
      trackers.push_back(std::move(*tr));
    }
    events = std::move(cal->events);
  }
  wearer.advance(wearer.end_ns(), events);

  RecordingWriterOptions wo;
  wo.overwrite = a.force;
  auto writer = RecordingWriter::create(a.out, wo);
  if (!writer) return std::fprintf(stderr, "error: %s\n", writer.error().message.c_str()), 1;
  const nlohmann::json about = {{"source", "proprio sim-ftm"}, {"simulated", wearer.describe()}};
  std::vector<StreamId> imu_streams, bend_streams;
  for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
    nlohmann::json meta = about;
    meta["segment"] = std::string(to_string(ftm::segment_of(static_cast<ftm::FtmImu>(i))));
    meta["note"] = "raw compass (hard/soft iron included); mag_T present on fresh compass samples only";
    auto id = writer->add_stream(StreamKind::imu, "ftm/imu/" + std::string(to_string(static_cast<ftm::FtmImu>(i))),
                                 meta.dump());
    if (!id) return std::fprintf(stderr, "error: %s\n", id.error().message.c_str()), 1;
    imu_streams.push_back(*id);
  }
  for (std::size_t b = 0; b < ftm::kFtmBendCount; ++b) {
    auto id = writer->add_stream(StreamKind::capacitance,
                                 "ftm/bend/" + std::string(to_string(static_cast<ftm::FtmBend>(b))), about.dump());
    if (!id) return std::fprintf(stderr, "error: %s\n", id.error().message.c_str()), 1;
    bend_streams.push_back(*id);
  }
  nlohmann::json wrist_meta = about;
  wrist_meta["note"] = "external wrist tracker; samples lost to dropouts are not written";
  auto wrist_stream = writer->add_stream(StreamKind::rigid_pose, "ftm/wrist", wrist_meta.dump());
  const std::string hand_prefix = std::string("hand/") + std::string(to_string(o.hand)) + "/";
  auto truth_stream = writer->add_stream(StreamKind::hand_pose, hand_prefix + "ground_truth", about.dump());
  auto event_stream = writer->add_stream(StreamKind::event, "events", about.dump());
  for (const auto* st : {&wrist_stream, &truth_stream, &event_stream}) {
    if (!*st) return std::fprintf(stderr, "error: %s\n", st->error().message.c_str()), 1;
  }
  for (const auto& span : wearer.phases()) {
    if (auto st =
            writer->write(*event_stream, Event{"phase " + std::string(ftm_sim::to_string(span.phase))}, span.begin_ns);
        !st) {
      return std::fprintf(stderr, "error: %s\n", st.error().message.c_str()), 1;
    }
  }

  std::FILE* truth_csv = nullptr;
  if (!a.truth.empty()) {
    truth_csv = std::fopen(a.truth.c_str(), "w");
    if (truth_csv == nullptr) return std::fprintf(stderr, "error: cannot write --truth %s\n", a.truth.c_str()), 1;
    std::fprintf(truth_csv, "time_s,phase");
    for (std::size_t d = 0; d < kHandDofCount; ++d) {
      std::fprintf(truth_csv, ",%s_rad", std::string(to_string(static_cast<HandDof>(d))).c_str());
    }
    for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
      std::fprintf(truth_csv, ",%s_mag_disturbed", std::string(to_string(static_cast<ftm::FtmImu>(i))).c_str());
    }
    std::fprintf(truth_csv, "\n");
  }
  PlotSeries gated{"gated", {}, {}};
  PlotSeries plain{"plain", {}, {}};
  PlotSeries truth_flag{"truth", {}, {}};
  PlotSeries detector_flag{"detector", {}, {}};
  const DurationNs truth_period = 10 * kNsPerMillisecond;
  TimeNs next_truth = 0;
  Status status;
  for (const auto& e : events) {
    const TimeNs t = e.time_ns();
    switch (e.kind) {
      case ftm::FtmEvent::Kind::imu: {
        ImuSample s;
        s.sensor_id = e.index;
        s.accel_mps2 = e.imu.accel_mps2;
        s.gyro_radps = e.imu.gyro_radps;
        if (e.imu.mag_fresh && (e.imu.status & ftm::sample_status::mag_overflow) == 0) s.mag_T = e.imu.mag_uT * 1e-6;
        status = writer->write(imu_streams[e.index], s, t);
        break;
      }
      case ftm::FtmEvent::Kind::bend:
        status = writer->write(bend_streams[e.index], CapacitanceFrame{{e.bend.capacitance_pF * 1e-12}}, t);
        break;
      case ftm::FtmEvent::Kind::wrist:
        if (e.wrist.valid) status = writer->write(*wrist_stream, RigidPose{e.wrist.T_world_wrist}, t);
        break;
    }
    if (!status) break;
    for (auto& tr : trackers) tr.push(e);
    if (t < next_truth) continue;
    next_truth = t + truth_period;
    const auto truth = wearer.truth_at(t);
    status = writer->write(*truth_stream, truth.pose);
    if (!status) break;
    if (truth_csv != nullptr) {
      std::fprintf(truth_csv, "%.4f,%s", 1e-9 * static_cast<double>(t),
                   std::string(ftm_sim::to_string(truth.phase)).c_str());
      for (double v : truth.angles) std::fprintf(truth_csv, ",%.6f", v);
      for (bool d : truth.mag_disturbed) std::fprintf(truth_csv, ",%d", d ? 1 : 0);
      std::fprintf(truth_csv, "\n");
    }
    if (!trackers.empty() && t >= wearer.task_begin_ns()) {
      const double ts = 1e-9 * static_cast<double>(t);
      const Quat q_true = truth.pose.T_world_joint[index_of(HandJoint::wrist)].q;
      HandPose est;
      trackers[0].estimate(est);
      gated.x.push_back(ts);
      gated.y.push_back(heading_deg(est.T_world_joint[index_of(HandJoint::wrist)].q, q_true));
      trackers[1].estimate(est);
      plain.x.push_back(ts);
      plain.y.push_back(heading_deg(est.T_world_joint[index_of(HandJoint::wrist)].q, q_true));
      truth_flag.x.push_back(ts);
      truth_flag.y.push_back(truth.mag_disturbed[index_of(ftm::FtmImu::dorsum)] ? 1.0 : 0.0);
      detector_flag.x.push_back(ts);
      detector_flag.y.push_back(trackers[0].mag_disturbed(ftm::FtmImu::dorsum) ? 1.0 : 0.0);
    }
  }
  if (truth_csv != nullptr && (std::fclose(truth_csv) != 0) && status) {
    status = make_error(Errc::io_error, "cannot write --truth " + a.truth);
  }
  if (status) status = writer->close();
  if (!status) return std::fprintf(stderr, "error: %s\n", status.error().message.c_str()), 1;
  if (!a.plot.empty()) {
    const std::vector<PlotPanel> panels = {
        {"Wrist heading error, tracker vs truth: compass gated by the detector, and plain", "deg", {gated, plain}},
        {"Dorsum compass disturbed (1): simulator truth and the detector's flag",
         "flag (0/1)",
         {truth_flag, detector_flag}}};
    if (auto st = write_svg_plot(a.plot, "FTM glove: heading under magnetic disturbance (simulated)",
                                 "session time (s)", panels);
        !st) {
      return std::fprintf(stderr, "error: %s\n", st.error().message.c_str()), 1;
    }
  }
  std::printf("sim-ftm: %zu samples, %.1f s simulated (task from %.1f s), written to %s\n", events.size(),
              1e-9 * static_cast<double>(wearer.end_ns()), 1e-9 * static_cast<double>(wearer.task_begin_ns()),
              a.out.c_str());
  return 0;
}

}  // namespace

void add_ftm_commands(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<BenchFtmArgs>();
  auto* b = add_command(app, "bench ftm");
  b->add_option("--subjects", args->subjects, "held-out simulated subjects (10, 11, ...)")
      ->check(CLI::Range(1, sim::kSimSubjectCount - ftm_eval::kFirstHeldOutSubject))
      ->capture_default_str();
  b->add_option("--minutes", args->minutes, "minutes of task per on-hand session")
      ->check(CLI::Range(2.0 / 60.0, 60.0))
      ->capture_default_str();
  b->add_option("--seed", args->seed, "first seed (subject i uses seed + i)")->capture_default_str();
  b->add_option("--cases", args->cases, "comma-separated: imu_bench, free_motion, pinch_grasp, disturbance")
      ->capture_default_str();
  b->add_flag("--rigid-skin", args->rigid_skin,
              "the IMUs fixed to the bones (by default they sit on skin that slides, wobbles and slips)");
  b->add_flag("--json", args->json, "print the metrics as JSON");
  b->callback([args, &exit_code] { exit_code = run_bench_ftm(*args); });

  auto sargs = std::make_shared<SimFtmArgs>();
  auto* s = add_command(app, "sim-ftm");
  s->add_option("--subject", sargs->subject, "simulated subject (0-14)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  s->add_option("--seconds", sargs->seconds, "task length after the calibration phases")
      ->check(CLI::Range(1.0, 3600.0))
      ->capture_default_str();
  s->add_option("--protocol", sargs->protocol, "the task")
      ->check(CLI::IsMember({"free-motion", "pinch-grasp"}))
      ->capture_default_str();
  s->add_option("--seed", sargs->seed, "simulation seed")->capture_default_str();
  s->add_option("--out", sargs->out, "recording to write (.prec)")->required();
  s->add_option("--truth", sargs->truth, "also write the ground truth (angles, disturbance flags) at 100 Hz as CSV");
  s->add_option(
      "--magnets", sargs->magnets,
      "comma-separated objects held near the hand for 10 s each from 2 s into the task: drill, fan, earphone");
  s->add_option("--plot", sargs->plot,
                "track the session (compass gated and plain) and plot heading error and detector flags as SVG");
  s->add_flag("--force", sargs->force, "replace an existing --out");
  s->callback([sargs, &exit_code] { exit_code = run_sim_ftm(*sargs); });
}

}  // namespace proprio::cli
