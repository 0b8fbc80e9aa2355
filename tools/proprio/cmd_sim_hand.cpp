// proprio sim-hand: simulate a subject's hand performing a protocol and record
// the ground truth (joint poses, joint angles, head pose, keyframe events).
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "commands.hpp"
#include "progress.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::cli {

namespace {

struct SimHandArgs {
  int subject = 0;
  std::string protocol = "free-motion";
  double seconds = 60.0;
  std::uint64_t seed = 1;
  double rate_hz = 90.0;
  std::string hand = "right";
  std::string out;
  bool force = false;
};

int run_sim_hand(const SimHandArgs& a) {
  auto subject = sim::sim_subject(a.subject);
  if (!subject) return logger().error("{}", subject.error().message), 1;
  auto shape = subject->shape();
  if (!shape) return logger().error("{}", shape.error().message), 1;

  sim::HandMotionOptions options;
  options.protocol = *sim::parse_motion_protocol(a.protocol);  // CLI11 already checked the name
  options.seed = a.seed;
  options.hand = *parse_handedness(a.hand);
  sim::HandMotionGenerator generator(HandModel(*shape), options);

  RecordingWriterOptions wo;
  wo.overwrite = a.force;
  auto writer = RecordingWriter::create(a.out, wo);
  if (!writer) return logger().error("{}", writer.error().message), 1;

  nlohmann::json about = {
      {"generator", "proprio sim-hand"},
      {"version", PROPRIO_VERSION},
      {"subject", a.subject},
      {"hand_length_m", subject->hand_length_m},
      {"hand_width_m", subject->hand_width_m},
      {"hand", a.hand},
      {"protocol", a.protocol},
      {"seed", a.seed},
      {"rate_hz", a.rate_hz},
      {"options", options.describe()},
  };
  nlohmann::json angles_meta = about;
  for (std::size_t i = 0; i < kHandDofCount; ++i) angles_meta["dof_names"].push_back(to_string(static_cast<HandDof>(i)));

  const std::string hand_prefix = "hand/" + a.hand + "/";
  auto pose_stream = writer->add_stream(StreamKind::hand_pose, hand_prefix + "ground_truth", about.dump());
  auto angle_stream =
      writer->add_stream(StreamKind::joint_angles, hand_prefix + "joint_angles_ground_truth", angles_meta.dump());
  auto head_stream = writer->add_stream(StreamKind::rigid_pose, "head/ground_truth", about.dump());
  auto event_stream = writer->add_stream(StreamKind::event, "events", about.dump());
  for (const auto* s : {&pose_stream, &angle_stream, &head_stream, &event_stream}) {
    if (!*s) return logger().error("{}", s->error().message), 1;
  }

  logger().info("{}", subject->describe());
  logger().info("motion: {}", options.describe());
  const auto n_samples = static_cast<std::int64_t>(a.seconds * a.rate_hz) + 1;
  ProgressBar progress("sim-hand", a.seconds, "s simulated");
  std::size_t last_keyframe = SIZE_MAX;
  for (std::int64_t k = 0; k < n_samples; ++k) {
    // k / rate, rounded once: the grid does not drift over long sessions.
    const TimeNs t = seconds_to_ns(static_cast<double>(k) / a.rate_hz);
    const auto frame = generator.sample(t);
    Status s;
    if (frame.keyframe != last_keyframe) {
      last_keyframe = frame.keyframe;
      s = writer->write(*event_stream, Event{"keyframe " + std::to_string(frame.keyframe)}, t);
    }
    if (s) s = writer->write(*pose_stream, frame.pose);
    if (s) s = writer->write(*angle_stream, JointAngles{options.hand, {frame.angles.begin(), frame.angles.end()}}, t);
    if (s) s = writer->write(*head_stream, RigidPose{frame.T_world_head}, t);
    if (!s) return logger().error("writing {} failed: {}", a.out, s.error().message), 1;
    progress.update(ns_to_seconds(t));
  }
  progress.finish();
  if (auto s = writer->close(); !s) return logger().error("closing {} failed: {}", a.out, s.error().message), 1;
  std::printf("wrote %s: %lld samples at %.1f Hz (%.1f s), %llu records\n", a.out.c_str(),
              static_cast<long long>(n_samples), a.rate_hz, a.seconds,
              static_cast<unsigned long long>(writer->records_written()));
  return 0;
}

}  // namespace

void add_sim_hand_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SimHandArgs>();
  CLI::App* cmd = add_command(app, "sim-hand");
  cmd->add_option("--subject", args->subject, "Simulated subject 0-14 (hand sizes span 17-20.5 cm x 9-11 cm)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  cmd->add_option("--protocol", args->protocol,
                  "free-motion: new random target pose every 3 s (Lee 2021, 4.6); "
                  "pinch-grasp: pinch, tripod and power grasp; wrist-sweep: wrist moves through the view; "
                  "natural: continuous overlapping movements with tremor and flicks; tapping: a finger taps a table; "
                  "pinch-grasp-contact: pinch-grasp with contact stops")
      ->check(CLI::IsMember(sim::motion_protocol_names()))
      ->capture_default_str();
  cmd->add_option("--seconds", args->seconds, "Duration to simulate, s")
      ->check(CLI::Range(0.0, 24.0 * 3600.0))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "Random seed; the same seed gives an identical file")->capture_default_str();
  cmd->add_option("--rate", args->rate_hz, "Sample rate, Hz")->check(CLI::Range(1.0, 10000.0))->capture_default_str();
  cmd->add_option("--hand", args->hand, "Which hand")->check(CLI::IsMember({"left", "right"}))->capture_default_str();
  cmd->add_option("--out", args->out, "Recording to write (.prec)")->required();
  cmd->add_flag("--force", args->force, "Overwrite an existing file");
  cmd->callback([args, &exit_code] { exit_code = run_sim_hand(*args); });
}

}  // namespace proprio::cli
