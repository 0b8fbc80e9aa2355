#include "proprio/peg_in_hole/live.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <nlohmann/json.hpp>

#include "proprio/peg_in_hole/protocol.hpp"
#include "proprio/peg_in_hole/world.hpp"
#include "proprio/study/session.hpp"

namespace proprio::peg_in_hole {
namespace fs = std::filesystem;

LiveTrial::LiveTrial(const PegInHoleConfig& config, const engine::Scene& scene, const std::string& instruction,
                     double time_limit_s, bool finish_on_insert, const Vec3& p_hole_in_world,
                     const Vec3& p_peg_start_in_world)
    : config_(config),
      instruction_(instruction),
      limit_s_(time_limit_s),
      finish_on_insert_(finish_on_insert),
      p_hole_(p_hole_in_world),
      p_peg_start_(p_peg_start_in_world),
      monitor_(config.peg.break_force_n, config.peg.break_filter_time_constant_s) {
  int free_index = 0;
  for (std::size_t i = 0; i < scene.entities.size(); ++i) {
    if (scene.entities[i].physics != engine::Physics::free) continue;
    if (scene.entities[i].body.name == "peg") {
      peg_entity_ = static_cast<int>(i);
      peg_object_ = free_index;
    }
    ++free_index;
  }
}

void LiveTrial::continue_after_respawn() noexcept {
  carried_s_ = elapsed_s_;
  start_ns_ = -1;
  respawn_pending_ = false;
  monitor_.reset();
}

void LiveTrial::on_frame(engine::FrameContext& c) {
  if (start_ns_ < 0) start_ns_ = c.time_ns;
  elapsed_s_ = carried_s_ + 1e-9 * static_cast<double>(c.time_ns - start_ns_);
  double force = 0.0;
  if (c.servo != nullptr) {
    force = grasp_force_n(c.servo->hands[0].object_normal_n);
    if (std::isfinite(force)) {
      peak_ = std::max(peak_, force);
      if (force > 0.05) {
        force_sum_ += force;
        ++contact_frames_;
      }
    }
  }
  if (!monitor_.broken() && monitor_.update(c.time_ns, force)) {
    ++breaks_;
    broken_at_ns_ = c.time_ns;
  }
  if (peg_entity_ >= 0 && static_cast<std::size_t>(peg_entity_) < c.entities.size()) {
    c.entities[static_cast<std::size_t>(peg_entity_)].rgba =
        peg_colour(monitor_.filtered_n(), config_.peg.colour_scale_max_n, monitor_.broken());
  }
  c.prompt = monitor_.broken() ? "The peg broke - it comes back at the start" : instruction_;
  if (monitor_.broken() && 1e-9 * static_cast<double>(c.time_ns - broken_at_ns_) >= config_.peg.respawn_delay_s) {
    respawn_pending_ = true;
    c.stop = true;
    return;
  }
  if (finish_on_insert_ && c.servo != nullptr && static_cast<std::size_t>(peg_object_) < c.servo->object_count) {
    const Pose peg = c.servo->object_poses[static_cast<std::size_t>(peg_object_)];
    if (insertion_state(peg, 0.5 * config_.peg.length_m, hole_geometry(config_, p_hole_)).inserted) {
      inserted_ = done_ = true;
      c.stop = true;
      return;
    }
  }
  if (elapsed_s_ >= limit_s_) {
    done_ = true;
    c.stop = true;
  }
}

namespace {

int index_from_id(const std::string& id) {
  std::size_t i = id.size();
  while (i > 0 && std::isdigit(static_cast<unsigned char>(id[i - 1]))) --i;
  if (i == id.size()) return 0;
  return std::max(0, std::atoi(id.c_str() + i) - 1);
}

struct TrialOutcome {
  double time_s = 0;
  bool inserted = false;
  int breaks = 0;
  double peak = 0, mean = 0;
  // The 1 kHz servo loop's timing over the trial's App runs (a break restarts
  // the App): worst percentiles, summed counts.
  haptics::ServoTiming servo;
  double render_ms_mean = 0;
};

void merge_timing(haptics::ServoTiming& total, const haptics::ServoTiming& run) {
  total.ticks += run.ticks;
  total.overruns += run.overruns;
  total.stale_hand_ticks += run.stale_hand_ticks;
  total.rejected_hands += run.rejected_hands;
  total.realtime = run.realtime;
  total.jitter_p50_us = std::max(total.jitter_p50_us, run.jitter_p50_us);
  total.jitter_p99_us = std::max(total.jitter_p99_us, run.jitter_p99_us);
  total.jitter_max_us = std::max(total.jitter_max_us, run.jitter_max_us);
  total.tick_p50_us = std::max(total.tick_p50_us, run.tick_p50_us);
  total.tick_p99_us = std::max(total.tick_p99_us, run.tick_p99_us);
  total.tick_max_us = std::max(total.tick_max_us, run.tick_max_us);
}

Result<TrialOutcome> run_one(const PegInHoleConfig& config, const TrialLayout& layout, Setting setting,
                             const std::string& instruction, double limit_s, bool finish_on_insert, bool no_hole,
                             const LiveRunner& run) {
  haptics::HapticScene hs = trial_scene(config, layout);
  if (no_hole) std::erase_if(hs.objects, [](const haptics::SceneObject& o) { return o.name == "hole_plate"; });
  engine::Scene scene = engine::Scene::from_haptic_scene("peg-in-hole", hs, layout.p_peg_start_in_world + Vec3(0.1, 0.15, 0));
  for (auto& e : scene.entities) e.peg_visual = e.body.name == "peg";
  LiveTrial trial(config, scene, instruction, limit_s, finish_on_insert, layout.p_hole_in_world,
                  layout.p_peg_start_in_world);
  TrialOutcome out;
  while (true) {
    engine::AppInputs extra;
    extra.servo_options = servo_loop_options(config, setting);
    extra.contact_options = contact_sim_options(config);
    extra.on_frame = [&trial](engine::FrameContext& c) { trial.on_frame(c); };
    auto report = run(scene, std::move(extra));
    if (!report) return report.error();
    merge_timing(out.servo, report->servo);
    out.render_ms_mean = std::max(out.render_ms_mean, report->render_ms_mean);
    if (trial.needs_respawn()) {
      trial.continue_after_respawn();  // the scene starts with the peg at its start again
      continue;
    }
    break;
  }
  out.time_s = trial.elapsed_s();
  out.inserted = trial.inserted();
  out.breaks = trial.breaks();
  out.peak = trial.peak_force_n();
  out.mean = trial.mean_force_n();
  return out;
}

}  // namespace

Result<int> run_live_session(const PegInHoleConfig& config, const LiveStudyOptions& options, const LiveRunner& run) {
  if (Status s = config.validate(); !s) return s.error();
  auto design = study_design(config);
  if (!design) return design.error();
  study::SessionOptions so;
  so.out_dir = options.out_dir;
  so.participant = options.participant;
  so.participant_index = options.participant_index >= 0 ? options.participant_index : index_from_id(options.participant);
  so.device_json = nlohmann::json{{"participant_kind", "real"}, {"config", config.describe()}}.dump();
  // Before the session files are looked at or deleted (--force).
  auto folder_lock = study::StudyFolderLock::acquire(options.out_dir);
  if (!folder_lock) return folder_lock.error();
  const fs::path csv = study::session_csv_path(*design, so);
  if (fs::exists(csv) && !options.resume) {
    if (!options.force) {
      return make_error(Errc::invalid_argument, fmt::format("{} exists: pass --resume to continue that session or "
                                                            "--force to start over",
                                                            csv.string()));
    }
    fs::remove(csv);
    fs::remove(study::session_sidecar_path(*design, so));
  }
  auto session = study::Session::open(*design, so);
  if (!session) return session.error();
  const auto say = [&](const std::string& s) {
    if (options.progress) options.progress(s);
  };
  const std::uint64_t pseed = session->participant_seed();
  if (options.familiarisation && session->completed_trials() == 0) {
    const TrialLayout layout = trial_layout(config, pseed, -1);
    say("Familiarisation 1: touch and grasp the peg (full haptics and AA)");
    // The spring phase needs the simulation's spring, which the engine's
    // scene does not carry: the peg stands on the table instead (docs).
    if (auto r = run_one(config, layout, Setting{true, true}, "Touch and grasp the peg: watch its colour",
                         config.familiarisation.spring_phase_s, false, true, run);
        !r) {
      return r.error();
    }
    say("Familiarisation 2: lift and rotate the peg");
    if (auto r = run_one(config, layout, Setting{true, true}, "Lift the peg gently and rotate it",
                         config.familiarisation.ground_phase_s, false, true, run);
        !r) {
      return r.error();
    }
  }
  int recorded = 0;
  while (!session->finished()) {
    auto trial = session->next_trial();
    if (!trial) return trial.error();
    const Setting setting = setting_of(trial->levels);
    const TrialLayout layout = trial_layout(config, pseed, trial->index);
    say(fmt::format("Trial {}/{} (setting {})", trial->index + 1, session->planned_trials(), setting.number()));
    auto r = run_one(config, layout, setting, "Pick up the peg with your fingertips and insert it into the hole",
                     config.main_task.trial_timeout_s, true, false, run);
    if (!r) return r.error();
    const study::Response resp = trial_response(
        config, trial->index, setting, layout,
        {r->inserted, r->time_s, r->breaks, 0, r->peak, r->mean, "", "real", std::nullopt});
    if (Status st = session->record(*trial, resp); !st) return st.error();
    ++recorded;
    say(fmt::format("  {:.1f} s{}, {} breaks; render {:.1f} ms per frame; servo {}", r->time_s,
                    r->inserted ? "" : " (timed out)", r->breaks, r->render_ms_mean, r->servo.describe()));
  }
  return recorded;
}

}  // namespace proprio::peg_in_hole
