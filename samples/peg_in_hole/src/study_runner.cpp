#include "proprio/peg_in_hole/study_runner.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "proprio/core/random.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/study/session.hpp"

namespace proprio::peg_in_hole {
namespace fs = std::filesystem;
using nlohmann::json;

std::string simulated_participant_id(int index) { return fmt::format("sim{:02d}", index + 1); }

namespace {

Pose rest_wrist(const PegInHoleConfig& c, const TrialLayout& layout) {
  // Hand resting in front of the body, to the right of and above the peg.
  const Quat q(Eigen::AngleAxisd(-0.3, Vec3::UnitX()));
  return Pose{q, layout.p_peg_start_in_world + Vec3(0.0, c.peg.length_m + 0.12, 0.25)};
}

}  // namespace

Percept perceive(const PegWorld& w) {
  Percept p;
  const haptics::ServoSnapshot& s = w.snapshot();
  p.time_ns = w.now_ns();
  p.T_world_peg = w.peg_pose();
  p.peg_rgba = w.peg_rgba();
  p.T_world_proxy_wrist = s.hands[0].proxy.joint(HandJoint::wrist);
  for (std::size_t f = 0; f < kFingerCount; ++f) p.p_proxy_tip_in_world[f] = s.hands[0].proxy.joint(tip_of(static_cast<Finger>(f))).p;
  p.hole = w.hole();
  // Touch: what each device renders (its force sensors), nothing else.
  for (std::size_t c = 0; c < s.channel_count; ++c) {
    const auto fi = static_cast<std::size_t>(s.channels[c].finger);
    p.felt_normal_n[fi] = std::max(0.0, s.channels[c].measured.normal_n);
    p.felt_shear_n[fi] = s.channels[c].measured.shear_magnitude_n();
  }
  return p;
}

Result<TrialResult> run_simulated_trial(const PegInHoleConfig& config, const TrialLayout& layout, Setting setting,
                                        SimulatedUser& user, const HandModel& hand_model,
                                        std::shared_ptr<const haptics::FingertipDeviceModel> device_model,
                                        const SimulatedTrialOptions& options) {
  auto world_r = PegWorld::create(config, layout, setting, hand_model, std::move(device_model), options.phase);
  if (!world_r) return world_r.error();
  PegWorld& world = **world_r;

  std::optional<RecordingWriter> rec;
  StreamId s_tracked = 0, s_proxy = 0, s_peg = 0, s_events = 0;
  if (!options.recording.empty()) {
    RecordingWriterOptions ro;
    ro.overwrite = true;  // a trial repeated after a crash replaces its half-written recording
    auto w = RecordingWriter::create(options.recording, ro);
    if (!w) return w.error();
    rec.emplace(std::move(*w));
    const std::string rate = fmt::format("{{\"rate_hz\": {}}}", options.recording_rate_hz);
    auto a = rec->add_stream(StreamKind::hand_pose, "hand/right/tracked", rate);
    auto b = rec->add_stream(StreamKind::hand_pose, "hand/right/proxy", rate);
    auto c = rec->add_stream(StreamKind::rigid_pose, "object/peg", rate);
    auto d = rec->add_stream(StreamKind::event, "events", options.recording_meta);
    if (!a || !b || !c || !d) return make_error(Errc::io_error, "cannot add streams to " + options.recording.string());
    s_tracked = *a;
    s_proxy = *b;
    s_peg = *c;
    s_events = *d;
    if (Status st = rec->write(s_events, Event{fmt::format("start setting {} ({})", setting.number(), setting.label())}, 0);
        !st) {
      return st.error();
    }
  }
  const auto record_every = static_cast<std::int64_t>(std::max(1.0, std::round(1000.0 / options.recording_rate_hz)));

  user.begin(world.now_ns(), rest_wrist(config, layout));
  const auto limit_ticks = static_cast<std::int64_t>(std::llround(options.time_limit_s * 1000.0));
  TrialResult r;
  const HandModel& model = world.hand_model();
  // Per-tick cost of the servo tick (simulation, gates, devices) measured
  // here: ServoLoop only times its own thread, and this run has none.
  std::vector<float> tick_us;
  tick_us.reserve(static_cast<std::size_t>(std::min<std::int64_t>(limit_ticks, 200000)));
  SimulatedFtmGlove* glove = options.ftm_glove;
  for (std::int64_t tick = 0; tick < limit_ticks; ++tick) {
    const HandCommand truth = user.act(perceive(world));
    if (glove && tick == 0) {
      if (Status st = glove->begin_trial(truth, setting.abduction); !st) return st.error();
    }
    // With the FTM, the world gets the glove's estimate of the true hand.
    const HandCommand cmd = glove ? glove->track(world.now_ns(), truth) : truth;
    world.submit_hand(cmd.T_world_wrist, cmd.angles);
    const auto t0 = std::chrono::steady_clock::now();
    const PegEvent ev = world.step();
    if (glove) glove->set_device_currents(world.now_ns(), world.device_current_a());
    tick_us.push_back(std::chrono::duration<float, std::micro>(std::chrono::steady_clock::now() - t0).count());
    if (options.on_event && ev.kind != PegEvent::Kind::none) options.on_event(ev.kind, user.phase_name());
    if (rec && (tick % record_every == 0 || ev.kind != PegEvent::Kind::none)) {
      const HandPose tracked = model.forward(Handedness::right, cmd.angles, cmd.T_world_wrist, world.now_ns());
      Status st = rec->write(s_tracked, tracked);
      if (st) st = rec->write(s_proxy, world.snapshot().hands[0].proxy);
      if (st) st = rec->write(s_peg, RigidPose{world.peg_pose()}, world.now_ns());
      if (st && ev.kind != PegEvent::Kind::none) {
        static const char* names[] = {"none", "break", "respawn", "drop", "inserted"};
        st = rec->write(s_events, Event{names[static_cast<int>(ev.kind)]}, world.now_ns());
      }
      if (!st) return st.error();
    }
    if (ev.kind == PegEvent::Kind::inserted) {
      r.completed = true;
      break;
    }
  }
  r.completion_time_s = world.elapsed_s();
  r.breaks = world.breaks();
  r.drops = world.drops();
  r.regrasps = user.regrasps();
  r.peak_force_n = world.peak_force_n();
  r.mean_force_n = world.mean_force_n();
  r.timing = world.timing();
  if (glove) r.ftm = glove->end_trial();
  if (!tick_us.empty()) {
    std::sort(tick_us.begin(), tick_us.end());
    const auto at = [&](double q) { return static_cast<double>(tick_us[static_cast<std::size_t>(q * static_cast<double>(tick_us.size() - 1))]); };
    r.timing.tick_p50_us = at(0.5);
    r.timing.tick_p99_us = at(0.99);
    r.timing.tick_max_us = tick_us.back();
    r.timing.overruns = static_cast<std::uint64_t>(tick_us.end() - std::upper_bound(tick_us.begin(), tick_us.end(), 1000.0f));
  }
  if (rec) {
    if (Status st = rec->write(s_events, Event{r.completed ? "done" : "time limit"}, world.now_ns()); !st) return st.error();
    if (Status st = rec->close(); !st) return st.error();
  }
  world.servo().disengage_and_zero(world.now_ns());
  return r;
}

namespace {

struct Shared {
  std::mutex mutex;
  SimulatedStudyReport report;
  std::atomic<int> trials_total{0};
  std::atomic<bool> stop{false};
  std::optional<Error> error;
};

void accumulate(Shared& sh, const TrialResult& r, Setting setting) {
  std::lock_guard<std::mutex> lock(sh.mutex);
  SimulatedStudyReport& rep = sh.report;
  if (r.ftm) {
    auto& f = rep.ftm_by_setting[static_cast<std::size_t>(setting.number() - 1)];
    ++f.trials;
    for (std::size_t i = 0; i < kFtmCompassCount; ++i) {
      f.max_disturbance_uT[i] = std::max(f.max_disturbance_uT[i], r.ftm->max_disturbance_uT[i]);
      f.flagged_fraction_sum[i] += r.ftm->flagged_fraction[i];
      f.disturbed_fraction_max = std::max(f.disturbed_fraction_max, r.ftm->disturbed_fraction[i]);
    }
    f.angle_error_deg_sum += r.ftm->mean_angle_error_deg;
    f.wrist_error_mm_sum += r.ftm->mean_wrist_error_mm;
  }
  rep.ticks += r.timing.ticks;
  rep.overruns += r.timing.overruns;
  rep.tick_p50_us = std::max(rep.tick_p50_us, r.timing.tick_p50_us);
  rep.tick_p99_us = std::max(rep.tick_p99_us, r.timing.tick_p99_us);
  rep.tick_max_us = std::max(rep.tick_max_us, r.timing.tick_max_us);
  rep.simulated_s += r.completion_time_s;
}

Status run_participant(const PegInHoleConfig& config, const SimulatedStudyOptions& options,
                       const study::StudyDesign& design, int index, Shared& shared,
                       const std::shared_ptr<const haptics::FingertipDeviceModel>& device) {
  const std::string id = simulated_participant_id(index);
  study::SessionOptions so;
  so.out_dir = options.out_dir;
  so.participant = id;
  so.participant_index = index;
  so.sync_each_trial = false;  // simulated: see SessionOptions
  so.device_json = json{{"fingertip_devices", "emulated (in-process, real wire encoding)"},
                        {"fingers", config.devices.fingers.size()},
                        {"participant_kind", "simulated"},
                        {"tracker", to_string(config.tracker)},
                        {"config", config.describe()}}
                       .dump();
  auto session = study::Session::open(design, so);
  if (!session) return session.error();
  {
    std::lock_guard<std::mutex> lock(shared.mutex);
    shared.report.trials_recovered += session->recovered_trials();
    shared.report.csv_files.push_back(session->csv_path());
  }
  // The participant: its hand and its seed. It learns across trials and its
  // state is not saved, so a resumed participant goes through its
  // familiarisation and the trials already on disk again (without touching
  // their recordings) and then continues exactly as an uninterrupted run would.
  const std::uint64_t pseed = session->participant_seed();
  auto shape = simulated_participant_hand(config.sim_user);
  if (!shape) return shape.error();
  const HandModel hand(*shape);
  SimulatedUser user(config, hand, mix_seed(pseed, 0x55534552));
  // The glove is donned and calibrated once, before familiarisation, and
  // worn through every phase and trial (a resumed participant replays them
  // through it too, so its state is what an uninterrupted run's was).
  std::unique_ptr<SimulatedFtmGlove> glove;
  if (config.tracker == SimTracker::ftm) {
    SimulatedFtmGloveOptions go;
    go.seed = mix_seed(pseed, 0x46544d);
    go.device_leads = config.ftm_device_leads;
    auto g = SimulatedFtmGlove::create(*shape, go);
    if (!g) return g.error();
    glove = std::move(*g);
  }
  const fs::path rec_dir = options.out_dir / "recordings";
  if (config.recording.enabled) fs::create_directories(rec_dir);
  if (options.familiarisation) {
    const TrialLayout layout = trial_layout(config, pseed, -1);
    for (auto [phase, seconds] : {std::pair{WorldPhase::spring, config.familiarisation.spring_phase_s},
                                  std::pair{WorldPhase::ground, config.familiarisation.ground_phase_s}}) {
      if (seconds <= 0.0) continue;
      user.set_grasp_only(phase == WorldPhase::spring);
      SimulatedTrialOptions to;
      to.phase = phase;
      to.time_limit_s = seconds;
      to.ftm_glove = glove.get();
      auto r = run_simulated_trial(config, layout, Setting{true, true}, user, hand, device, to);
      if (!r) return r.error();
      user.set_grasp_only(false);
      if (options.progress) {
        options.progress(fmt::format("{} familiarisation ({}): {:.0f} s, {} breaks", id,
                                     phase == WorldPhase::spring ? "spring" : "ground", seconds, r->breaks));
      }
    }
  }
  const auto rec_name_of = [&id](int trial_index) {
    return fmt::format("{}_trial{:02d}.prec", id, trial_index + 1);
  };
  for (const study::Session::RecordedTrial& rec : session->recovered_trial_list()) {
    const Setting setting = setting_of(rec.trial.levels);
    const TrialLayout layout = trial_layout(config, pseed, rec.trial.index);
    SimulatedTrialOptions to;
    to.time_limit_s = config.main_task.trial_timeout_s;
    to.ftm_glove = glove.get();
    auto r = run_simulated_trial(config, layout, setting, user, hand, device, to);
    if (!r) return r.error();
    const study::Response again = trial_response(
        config, rec.trial.index, setting, layout,
        {r->completed, r->completion_time_s, r->breaks, r->drops, r->peak_force_n, r->mean_force_n,
         config.recording.enabled ? "recordings/" + rec_name_of(rec.trial.index) : "", "simulated", r->ftm});
    bool same = again.correct == rec.response.correct;
    for (const auto& [column, value] : again.extra) {
      const auto it = rec.response.extra.find(column);
      same = same && it != rec.response.extra.end() && it->second == value;
    }
    if (!same) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{}: trial {} on disk is not what this simulation does when it replays the "
                                    "recorded trials (written by another version or configuration?); start over "
                                    "with --force, or use another --out",
                                    session->csv_path().string(), rec.trial.index + 1));
    }
    if (options.progress) {
      options.progress(fmt::format("{} trial {:2d}/{}: replayed (recorded before the resume)", id,
                                   rec.trial.index + 1, session->planned_trials()));
    }
  }
  while (!session->finished() && !shared.stop.load()) {
    auto trial = session->next_trial();
    if (!trial) return trial.error();
    const Setting setting = setting_of(trial->levels);
    const TrialLayout layout = trial_layout(config, pseed, trial->index);
    SimulatedTrialOptions to;
    to.time_limit_s = config.main_task.trial_timeout_s;
    to.ftm_glove = glove.get();
    const std::string rec_name = rec_name_of(trial->index);
    if (config.recording.enabled) {
      to.recording = rec_dir / rec_name;
      to.recording_rate_hz = config.recording.rate_hz;
      to.recording_meta = json{{"participant", id}, {"trial", trial->index}, {"setting", setting.number()}}.dump();
    }
    auto r = run_simulated_trial(config, layout, setting, user, hand, device, to);
    if (!r) return r.error();
    const study::Response resp = trial_response(
        config, trial->index, setting, layout,
        {r->completed, r->completion_time_s, r->breaks, r->drops, r->peak_force_n, r->mean_force_n,
         config.recording.enabled ? "recordings/" + rec_name : "", "simulated", r->ftm});
    if (Status st = session->record(*trial, resp); !st) return st;
    accumulate(shared, *r, setting);
    if (options.progress) {
      options.progress(fmt::format("{} trial {:2d}/{}: setting {} ({}), {:.1f} s{}, {} breaks", id, trial->index + 1,
                                   session->planned_trials(), setting.number(), setting.label(), r->completion_time_s,
                                   r->completed ? "" : " (timed out)", r->breaks));
    }
    {
      std::lock_guard<std::mutex> lock(shared.mutex);
      ++shared.report.trials_run;
    }
    const int total = ++shared.trials_total;
    if (options.stop_after_trials >= 0 && total >= options.stop_after_trials) shared.stop.store(true);
  }
  return {};
}

}  // namespace

Result<SimulatedStudyReport> run_simulated_study(const PegInHoleConfig& config_in, const SimulatedStudyOptions& options) {
  PegInHoleConfig config = config_in;
  config.seed = options.seed;
  if (Status s = config.validate(); !s) return s.error();
  if (options.participants < 1 || options.participants > 999) {
    return make_error(Errc::invalid_argument, "--participants must be between 1 and 999");
  }
  if (options.out_dir.empty()) return make_error(Errc::invalid_argument, "an output folder (--out) is needed");
  auto design = study_design(config);
  if (!design) return design.error();
  // Before looking for, deleting or appending to sessions: a second process
  // on this folder would interleave and duplicate trials.
  auto folder_lock = study::StudyFolderLock::acquire(options.out_dir);
  if (!folder_lock) return folder_lock.error();
  std::error_code ec;
  if (fs::exists(options.out_dir) && !fs::is_empty(options.out_dir, ec)) {
    bool has_sessions = false;
    for (const auto& e : fs::directory_iterator(options.out_dir)) {
      has_sessions |= e.path().extension() == ".csv" && e.path().filename().string().rfind(design->name, 0) == 0;
    }
    if (has_sessions && options.force) {
      for (const auto& e : fs::directory_iterator(options.out_dir)) {
        const std::string n = e.path().filename().string();
        if (n.rfind(design->name + "_", 0) == 0) fs::remove(e.path(), ec);
      }
      fs::remove_all(options.out_dir / "recordings", ec);
    } else if (has_sessions && !options.resume) {
      return make_error(Errc::invalid_argument,
                        fmt::format("{} already holds {} sessions: pass --resume to continue them or --force to "
                                    "start over",
                                    options.out_dir.string(), design->name));
    }
  }
  fs::create_directories(options.out_dir, ec);
  if (ec) return make_error(Errc::io_error, fmt::format("cannot create {}: {}", options.out_dir.string(), ec.message()));
  auto device = load_device_model(config);
  if (!device) return device.error();

  Shared shared;
  shared.report.participants = options.participants;
  const auto t0 = std::chrono::steady_clock::now();
  std::atomic<int> next{0};
  const auto worker = [&] {
    for (int i = next++; i < options.participants && !shared.stop.load(); i = next++) {
      if (Status s = run_participant(config, options, *design, i, shared, *device); !s) {
        std::lock_guard<std::mutex> lock(shared.mutex);
        if (!shared.error) shared.error = s.error().with_context(simulated_participant_id(i));
        shared.stop.store(true);
      }
    }
  };
  const int threads = std::clamp(options.threads, 1, options.participants);
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  shared.report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (shared.error) return *shared.error;
  std::sort(shared.report.csv_files.begin(), shared.report.csv_files.end());
  return shared.report;
}

}  // namespace proprio::peg_in_hole
