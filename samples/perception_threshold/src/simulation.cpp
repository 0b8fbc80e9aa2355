#include "proprio/perception_threshold/simulation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "proprio/core/file_io.hpp"
#include "proprio/haptics/device_model.hpp"
#include "proprio/haptics/emulated_fingertip.hpp"
#include "proprio/perception_threshold/observer.hpp"
#include "proprio/perception_threshold/trial.hpp"
#include "proprio/study/session.hpp"

namespace proprio::perception {
namespace {

constexpr DurationNs kTickNs = kNsPerMillisecond;
constexpr double kTickS = 1e-3;
// Seed streams of a participant (the study library's plan uses stream 1,
// presentations 1000 + trial).
constexpr std::uint64_t kObserverStream = 11;
constexpr std::uint64_t kMotorStream = 12;

// The simulated finger's motion, planned in the cylinder frame.
constexpr double kSwipeAngleRad = 0.3;     // side to side on the curved surface (about +-7.5 cm)
constexpr double kSwipePeriodS = 2.5;      // adaptation: one back-and-forth
constexpr double kPressDepthM = 0.003;     // how far a swiping sphere goes into the surface
constexpr double kHoverM = 0.03;           // lifted above the surface between swipes
constexpr double kSwipeZ = 0.08;           // along the axis, toward the participant's end
constexpr double kReachS = 0.8;            // moving to the swipe path at the start of a phase
constexpr double kCueStepM = 0.05;         // blind phase: how far one arrow moves the finger
constexpr double kCueMoveS = 0.7;
constexpr double kAnswerSwipeS = 2.5;      // per sphere
constexpr double kMotorNoiseTauS = 0.3;    // correlation time of the finger's wander

double min_jerk(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * x * (10 - 15 * x + 6 * x * x);
}

struct Context {
  const PerceptionProtocol& protocol;
  const PlacedScene& scene;
  Pose T_world_view;  // the head as it is (looking down at the cylinder); the scene uses it levelled
};

// A point on (depth > 0: under) the curved surface, at swipe angle alpha.
Vec3 surface_point(const Context& c, double alpha, double depth_m) {
  const double rho = c.protocol.cylinder_radius_m + c.protocol.fingertip_radius_m - depth_m;
  return c.scene.cylinder.T_world_object * Vec3(rho * std::sin(alpha), rho * std::cos(alpha), kSwipeZ);
}

// The finger's slow wander: an Ornstein-Uhlenbeck process per axis.
struct MotorNoise {
  Vec3 n = Vec3::Zero();
  double sigma_m = 0;
  void step(Rng& rng) {
    const double a = kTickS / kMotorNoiseTauS;
    const double s = sigma_m * std::sqrt(2 * a);
    for (int i = 0; i < 3; ++i) n[i] += -a * n[i] + s * rng.normal();
  }
};

struct TrialResult {
  bool chose_true = false;
  double peak_force_n = 0;
  int attribution = 0;  // +1 haptic sphere, -1 the other, 0 none
  std::uint64_t ticks = 0;
};

class SimulatedParticipantRun {
 public:
  SimulatedParticipantRun(const PerceptionProtocol& protocol, const PlacedScene& scene, const Pose& T_world_view,
                          ForceChannel& channel, SimulatedObserver& observer, std::uint64_t motor_seed)
      : c_{protocol, scene, T_world_view}, channel_(channel), observer_(observer), motor_rng_(motor_seed) {
    noise_.sigma_m = protocol.observer.motor_noise_cm * 0.01;
    plan_ = surface_point(c_, 0.0, -kHoverM);
  }

  TrialResult run(const TrialPresentation& trial, TimeNs& now) {
    TrialResult r;
    const auto& p = c_.protocol;
    if (trial.haptic == HapticTarget::none) {
      channel_.disengage(now);  // Experiment 1: the device is off
    } else if (!channel_.engaged()) {
      channel_.engage(now);
    }
    // Adaptation: from wherever the finger is to swiping side to side.
    const Vec3 start = plan_;
    for (double t = 0; t < p.adaptation_s; t += kTickS) {
      const Vec3 swipe = surface_point(c_, kSwipeAngleRad * std::sin(2 * kPi * t / kSwipePeriodS), kPressDepthM);
      plan_ = start + min_jerk(t / kReachS) * (swipe - start);
      tick(trial, Phase::adaptation, Cue::none, now, r);
    }
    // Blind: follow the arrow, re-read every cue_update_s.
    Cue cue = Cue::none;
    Vec3 from = plan_, to = plan_;
    double cue_t = -1;
    for (double t = 0; t < p.blind_s; t += kTickS) {
      if (cue_t < 0 || t - cue_t >= p.cue_update_s) {
        cue_t = t;
        const Vec3 p_in_head = c_.T_world_view.inverse() * finger();
        cue = blind_cue(p_in_head, p.cue_dead_zone_deg * kPi / 180.0);
        Vec3 step_in_head = Vec3::Zero();
        if (cue == Cue::up) step_in_head.y() = kCueStepM;
        if (cue == Cue::down) step_in_head.y() = -kCueStepM;
        if (cue == Cue::left) step_in_head.x() = -kCueStepM;
        if (cue == Cue::right) step_in_head.x() = kCueStepM;
        from = plan_;
        to = plan_ + c_.T_world_view.q * step_in_head;
      }
      plan_ = from + min_jerk((t - cue_t) / kCueMoveS) * (to - from);
      tick(trial, Phase::blind, cue, now, r);
    }
    // Answer: treat the blue sphere as the finger and swipe, then the red.
    observer_.begin_answer();
    for (int s = 0; s < 2; ++s) {
      const bool blue = s == 0;
      const bool this_is_true = blue == trial.true_is_blue;
      const Vec3 offset = this_is_true ? Vec3::Zero() : Vec3(trial.offset_m * trial.u_offset_in_world);
      const Vec3 sphere_start = plan_ + offset;
      const Vec3 above = surface_point(c_, -kSwipeAngleRad, -kHoverM);
      for (double t = 0; t < kAnswerSwipeS; t += kTickS) {
        Vec3 sphere;
        if (t < 0.5) {
          sphere = sphere_start + min_jerk(t / 0.5) * (above - sphere_start);
        } else if (t < 0.8) {
          sphere = above + min_jerk((t - 0.5) / 0.3) * (surface_point(c_, -kSwipeAngleRad, kPressDepthM) - above);
        } else if (t < 2.0) {
          sphere = surface_point(c_, -kSwipeAngleRad + 2 * kSwipeAngleRad * min_jerk((t - 0.8) / 1.2), kPressDepthM);
        } else {
          const Vec3 end = surface_point(c_, kSwipeAngleRad, kPressDepthM);
          sphere = end + min_jerk((t - 2.0) / 0.5) * (surface_point(c_, kSwipeAngleRad, -kHoverM) - end);
        }
        plan_ = sphere - offset;
        tick(trial, Phase::answer, Cue::none, now, r);
      }
    }
    const Vec3 p_true = finger();
    const Vec3 p_false = trial.p_false_in_world(p_true);
    const Vec3& p_blue = trial.true_is_blue ? p_true : p_false;
    const Vec3& p_red = trial.true_is_blue ? p_false : p_true;
    const bool chose_blue = observer_.choose_blue(p_true, p_blue, p_red);
    r.chose_true = chose_blue == trial.true_is_blue;
    if (trial.haptic != HapticTarget::none && observer_.last_attribution() != 0) {
      const bool haptic_is_blue = (trial.haptic == HapticTarget::true_sphere) == trial.true_is_blue;
      r.attribution = (observer_.last_attribution() > 0) == haptic_is_blue ? 1 : -1;
    }
    return r;
  }

 private:
  Vec3 finger() const { return plan_ + noise_.n; }

  void tick(const TrialPresentation& trial, Phase phase, Cue cue, TimeNs& now, TrialResult& r) {
    now += kTickNs;
    ++r.ticks;
    noise_.step(motor_rng_);
    const Vec3 p_finger = finger();
    const TrialView view = trial_view(c_.protocol, c_.scene, trial, phase, p_finger, cue);
    channel_.update(haptic_force(c_.protocol, c_.scene, view, c_.scene.T_world_head.q), now);
    const double felt = channel_.felt().in_tip_frame().norm();
    r.peak_force_n = std::max(r.peak_force_n, felt);
    if (phase == Phase::answer) {
      // What is seen: whether each drawn sphere rests on the cylinder.
      const Vec3 p_false = trial.p_false_in_world(p_finger);
      const bool true_touches = drawn_sphere(c_.protocol, c_.scene, p_finger).contact.in_contact;
      const bool false_touches = drawn_sphere(c_.protocol, c_.scene, p_false).contact.in_contact;
      const bool blue_touches = trial.true_is_blue ? true_touches : false_touches;
      const bool red_touches = trial.true_is_blue ? false_touches : true_touches;
      observer_.feel(felt, blue_touches ? 1.0 : 0.0, red_touches ? 1.0 : 0.0);
    }
  }

  Context c_;
  ForceChannel& channel_;
  SimulatedObserver& observer_;
  Rng motor_rng_;
  MotorNoise noise_;
  Vec3 plan_;
};

// The simulated head: standing at the origin, facing -z, looking down at the
// top of the cylinder (so the view's centre line, where the blind phase's
// arrows lead the finger, runs through the swiping area).
Pose simulated_head(const PerceptionProtocol& protocol) {
  const Pose level{Quat::Identity(), Vec3(0.0, 1.6, 0.0)};
  const Vec3 top = protocol.T_head_cylinder() * Vec3(0, protocol.cylinder_radius_m, 0);
  const double pitch = std::atan2(top.y(), -top.z());
  return {Quat(Eigen::AngleAxisd(pitch, Vec3::UnitX())), level.p};
}

Status run_participant(const PerceptionProtocol& protocol, const study::StudyDesign& design,
                       const SimulatedStudyOptions& options,
                       std::shared_ptr<const haptics::FingertipDeviceModel> model, SimulatedParticipant& out,
                       std::uint64_t& ticks, const std::function<void()>& on_trial) {
  study::SessionOptions so;
  so.out_dir = options.out_dir;
  so.participant = out.id;
  so.participant_index = out.index;
  so.sync_each_trial = options.sync_each_trial;
  so.device_json = nlohmann::json{{"participant", "simulated"},
                                  {"fingertip_device", model->describe()},
                                  {"observer", protocol.observer.describe()},
                                  {"proprioceptive_noise_cm", out.proprioceptive_noise_cm}}
                       .dump();
  so.calibration_json = R"J({"T_hmd_graphics": "identity (simulated head)"})J";
  auto session = study::Session::open(design, so);
  if (!session) return session.error().with_context("participant " + out.id);
  out.csv = session->csv_path();
  out.trials_recovered = session->recovered_trials();
  out.seed = session->participant_seed();
  auto sink_r = haptics::EmulatedFingertip::create(model);
  if (!sink_r) return sink_r.error();
  std::shared_ptr<haptics::FingertipSink> sink = std::move(*sink_r);
  ForceChannel channel(model, sink);
  const Pose T_world_view = simulated_head(protocol);
  const PlacedScene scene = PlacedScene::place(protocol, T_world_view);
  // The observer, the finger and the device carry state from trial to trial
  // (random streams, the finger's position and wander), so a resumed
  // participant first lives through the trials already on disk again:
  // what follows is then exactly what an uninterrupted run would have done.
  SimulatedObserver observer(protocol.observer, out.proprioceptive_noise_cm, mix_seed(out.seed, kObserverStream));
  SimulatedParticipantRun run(protocol, scene, T_world_view, channel, observer, mix_seed(out.seed, kMotorStream));
  TimeNs now = kNsPerSecond;
  const auto count = [&out](const TrialPresentation& presentation, const TrialResult& r) {
    out.peak_device_force_n = std::max(out.peak_device_force_n, r.peak_force_n);
    if (presentation.haptic != HapticTarget::none) {
      ++out.haptic_answers;
      if (r.attribution > 0) ++out.correct_attributions;
    }
  };
  for (const study::Session::RecordedTrial& rec : session->recovered_trial_list()) {
    auto presentation = make_presentation(rec.trial, design, out.seed);
    if (!presentation) return presentation.error();
    const TrialResult r = run.run(*presentation, now);
    ticks += r.ticks;
    study::Response again;
    fill_response_columns(*presentation, r.chose_true, r.peak_force_n, again);
    bool same = again.correct == rec.response.correct;
    for (const auto& [column, value] : again.extra) {
      const auto it = rec.response.extra.find(column);
      same = same && it != rec.response.extra.end() && it->second == value;
    }
    if (!same) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: trial {} on disk is not what this simulation answers when it replays the "
                                    "recorded trials (written by another version or observer model?); start the "
                                    "simulated study over with --force, or use another --out",
                                    session->csv_path().string(), rec.trial.index));
    }
    count(*presentation, r);
  }
  while (!session->finished()) {
    if (options.stop_after_trials >= 0 && out.trials_run >= options.stop_after_trials) break;
    auto trial = session->next_trial();
    if (!trial) return trial.error();
    auto presentation = make_presentation(*trial, design, out.seed);
    if (!presentation) return presentation.error();
    const TrialResult r = run.run(*presentation, now);
    ticks += r.ticks;
    study::Response response;
    fill_response_columns(*presentation, r.chose_true, r.peak_force_n, response);
    response.response_time_s = 0.0;  // the model answers at once
    if (auto s = session->record(*trial, response); !s) return s.error();
    ++out.trials_run;
    count(*presentation, r);
    on_trial();
  }
  channel.disengage(now);
  return {};
}

}  // namespace

std::string SimulatedStudyOptions::describe() const {
  return fmt::format("{} simulated participants, seed {}, {} threads, out {}", participants,
                     seed ? std::to_string(*seed) : "from the design", threads, out_dir.string());
}

Result<SimulatedStudy> run_simulated_study(const PerceptionProtocol& protocol, const study::StudyDesign& design_in,
                                           const SimulatedStudyOptions& options) {
  if (auto s = protocol.validate(); !s) return s.error();
  if (options.participants < 1 || options.participants > 999) {
    return make_error(Errc::invalid_argument, fmt::format("participants must be 1..999, not {}", options.participants));
  }
  study::StudyDesign design = design_in;
  if (options.seed) design.seed = *options.seed;
  auto model_r = haptics::load_device_model(options.device_model);
  if (!model_r) return model_r.error().with_context("the emulated fingertip device");
  std::shared_ptr<const haptics::FingertipDeviceModel> model(std::move(*model_r));
  // Held until the ground truth is written: --force deletes, the sessions
  // append, and a second process must touch none of it.
  auto folder_lock = study::StudyFolderLock::acquire(options.out_dir);
  if (!folder_lock) return folder_lock.error();
  std::error_code ec;

  SimulatedStudy result;
  result.seed = design.seed;
  result.participants.resize(static_cast<std::size_t>(options.participants));
  for (int i = 0; i < options.participants; ++i) {
    SimulatedParticipant& p = result.participants[static_cast<std::size_t>(i)];
    p.index = i;
    p.id = fmt::format("S{:02d}", i + 1);
    if (options.force) {
      study::SessionOptions so;
      so.out_dir = options.out_dir;
      so.participant = p.id;
      std::filesystem::remove(study::session_csv_path(design, so), ec);
      std::filesystem::remove(study::session_sidecar_path(design, so), ec);
    }
    // From the study seed and the index alone, so a resumed run simulates the same people.
    const std::uint64_t seed = mix_seed(design.seed, static_cast<std::uint64_t>(i));
    p.proprioceptive_noise_cm = participant_proprioceptive_noise_cm(protocol.observer, seed);
    p.true_threshold_none_cm = true_threshold_cm(protocol.observer, p.proprioceptive_noise_cm, HapticTarget::none, 0.75);
    p.true_threshold_true_sphere_cm =
        true_threshold_cm(protocol.observer, p.proprioceptive_noise_cm, HapticTarget::true_sphere, 0.75);
    p.true_threshold_false_sphere_cm =
        true_threshold_cm(protocol.observer, p.proprioceptive_noise_cm, HapticTarget::false_sphere, 0.75);
    p.true_max_allowable_error_cm = true_max_allowable_error_cm(protocol.observer, p.proprioceptive_noise_cm);
  }

  const auto wall_start = std::chrono::steady_clock::now();
  const int total = options.participants * static_cast<int>(study::plan_trials(design, 0, 0).size());
  std::atomic<int> next{0}, done{0};
  std::atomic<std::uint64_t> ticks{0};
  std::mutex mutex;
  std::optional<Error> first_error;
  auto worker = [&] {
    for (int i = next++; i < options.participants; i = next++) {
      std::uint64_t my_ticks = 0;
      auto s = run_participant(protocol, design, options, model, result.participants[static_cast<std::size_t>(i)],
                               my_ticks, [&] {
                                 const int d = ++done;
                                 if (options.progress) {
                                   std::lock_guard lock(mutex);
                                   options.progress(d, total);
                                 }
                               });
      ticks += my_ticks;
      if (!s) {
        std::lock_guard lock(mutex);
        if (!first_error) first_error = s.error();
        next = options.participants;  // the others finish their participant and stop
      }
    }
  };
  const int threads = std::clamp(options.threads > 0 ? options.threads
                                                     : static_cast<int>(std::thread::hardware_concurrency()),
                                 1, options.participants);
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (first_error) return *first_error;

  result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  result.servo_ticks = ticks.load();
  result.simulated_s = static_cast<double>(result.servo_ticks) * kTickS;

  // The model's ground truth, for checking what the analysis recovers.
  nlohmann::json truth;
  truth["observer"] = protocol.observer.describe();
  truth["note"] = "True thresholds of the simulated observers (cm), from the model's closed form "
                  "(docs/perception-threshold.md). The haptic values assume the felt force is attributed to the "
                  "haptic sphere; attribution_rate says how often it was.";
  truth["population"] = {
      {"threshold_none_cm", true_threshold_cm(protocol.observer, protocol.observer.proprioceptive_noise_cm,
                                              HapticTarget::none, 0.75)},
      {"threshold_true_sphere_cm", true_threshold_cm(protocol.observer, protocol.observer.proprioceptive_noise_cm,
                                                     HapticTarget::true_sphere, 0.75)},
      {"threshold_false_sphere_cm", true_threshold_cm(protocol.observer, protocol.observer.proprioceptive_noise_cm,
                                                      HapticTarget::false_sphere, 0.75)},
      {"max_allowable_error_cm",
       true_max_allowable_error_cm(protocol.observer, protocol.observer.proprioceptive_noise_cm)}};
  for (const auto& p : result.participants) {
    truth["participants"][p.id] = {
        {"proprioceptive_noise_cm", p.proprioceptive_noise_cm},
        {"threshold_none_cm", p.true_threshold_none_cm},
        {"threshold_true_sphere_cm", p.true_threshold_true_sphere_cm},
        {"threshold_false_sphere_cm", p.true_threshold_false_sphere_cm},
        {"max_allowable_error_cm", p.true_max_allowable_error_cm},
        {"attribution_rate",
         p.haptic_answers > 0 ? nlohmann::json(static_cast<double>(p.correct_attributions) / p.haptic_answers)
                              : nlohmann::json(nullptr)}};
  }
  result.ground_truth_json = options.out_dir / "ground_truth.json";
  if (Status s = write_file_atomic(result.ground_truth_json, truth.dump(2) + "\n", "ground truth"); !s) {
    return s.error();
  }
  return result;
}

}  // namespace proprio::perception
