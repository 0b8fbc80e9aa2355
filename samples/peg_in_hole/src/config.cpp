#include "proprio/peg_in_hole/config.hpp"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <set>
#include <sstream>

#include "proprio/core/config.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::peg_in_hole {
namespace {

#define PEG_TRY(var, expr)            \
  auto var##_result = (expr);         \
  if (!var##_result) return var##_result.error(); \
  auto var = std::move(*var##_result)


Status read_double(const Config& c, const char* key, double& value, double lo, double hi) {
  auto v = c.get_double_or(key, value, lo, hi);
  if (!v) return v.error();
  value = *v;
  return {};
}

Status read_vec3(const Config& c, const char* key, Vec3& value) {
  if (!c.contains(key)) return {};
  auto v = c.get_doubles(key);
  if (!v) return v.error();
  if (v->size() != 3) {
    return make_error(Errc::parse_error, fmt::format("{}: '{}' must be [x, y, z] in metres, got {} numbers",
                                                     c.where(key), key, v->size()));
  }
  for (double x : *v) {
    if (!std::isfinite(x)) return make_error(Errc::parse_error, fmt::format("{}: '{}' must be finite", c.where(key), key));
  }
  value = Vec3((*v)[0], (*v)[1], (*v)[2]);
  return {};
}

Result<Finger> finger_from(const std::string& name) {
  if (auto f = parse_finger(name)) return *f;
  return make_error(Errc::parse_error, "unknown finger '" + name + "': use thumb, index, middle, ring or little");
}

#define PEG_CHECK(expr)            \
  do {                             \
    if (Status s_ = (expr); !s_) return s_.error(); \
  } while (0)

}  // namespace

std::string Setting::label() const {
  return fmt::format("{}HF+{}AA", haptics ? "w" : "wo", abduction ? "w" : "wo");
}

Setting setting_from_number(int number) {
  return Setting{number == 1 || number == 2, number == 1 || number == 3};
}

Status PegInHoleConfig::validate() const {
  const auto bad = [](const std::string& what) { return make_error(Errc::invalid_argument, what); };
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(peg.radius_m) || !positive(peg.length_m) || !positive(peg.mass_kg)) {
    return bad("peg.radius_m, peg.length_m and peg.mass_kg must be positive and finite");
  }
  if (!positive(peg.break_force_n) || !positive(peg.colour_scale_max_n)) {
    return bad("peg.break_force_n and peg.colour_scale_max_n must be positive");
  }
  if (!(peg.break_filter_time_constant_s >= 0.0)) return bad("peg.break_filter_time_constant_s must be >= 0");
  if (!(hole.clearance_m > 0.0) || !(hole.clearance_m < peg.radius_m)) {
    return bad(fmt::format("hole.clearance_m must be in (0, peg radius {} m)", peg.radius_m));
  }
  if (!(hole.insertion_depth_m > 0.0) || hole.insertion_depth_m > hole.plate_thickness_m + 0.5 * peg.length_m) {
    return bad("hole.insertion_depth_m must be positive and less than plate thickness + half the peg");
  }
  for (const Vec3* v : {&layout.peg_start_m, &layout.peg_start_range_m, &layout.hole_m, &layout.hole_range_m}) {
    if (!v->allFinite() || (v == &layout.peg_start_range_m || v == &layout.hole_range_m ? v->minCoeff() < 0 : false)) {
      return bad("layout positions must be finite and ranges non-negative");
    }
  }
  if (std::abs(layout.peg_start_m.y() - layout.table_height_m) > 1e-6) {
    return bad(fmt::format("layout.peg_start_m's y ({}) must equal layout.table_height_m ({}): the peg stands on the table",
                           layout.peg_start_m.y(), layout.table_height_m));
  }
  if (layout.hole_m.x() - layout.peg_start_m.x() < peg.length_m) {
    return bad("layout.hole_m must be at least one peg length to the +x side of the peg's start");
  }
  if (main_task.repetitions < 1 || main_task.familiarisation_trials < 0 ||
      main_task.familiarisation_trials >= 4 * main_task.repetitions) {
    return bad("main_task.repetitions must be >= 1 and familiarisation_trials in [0, 4 * repetitions)");
  }
  if (!positive(main_task.trial_timeout_s)) return bad("main_task.trial_timeout_s must be positive");
  if (familiarisation.spring_phase_s < 0 || familiarisation.ground_phase_s < 0) {
    return bad("familiarisation phase durations must be >= 0");
  }
  if (devices.fingers.empty() || devices.fingers.size() > kFingerCount) return bad("devices.fingers: 1 to 5 fingers");
  if (devices.emulator_substeps < 1 || devices.emulator_substeps > 1000) {
    return bad("devices.emulator_substeps must be in [1, 1000]");
  }
  if (!positive(recording.rate_hz) || recording.rate_hz > 1000.0) return bad("recording.rate_hz must be in (0, 1000]");
  if (!positive(sim_user.reach_speed_mps) || !positive(sim_user.insert_speed_mps) || !positive(sim_user.closing_speed) ||
      !positive(sim_user.guarded_speed_mps)) {
    return bad("sim_user speeds must be positive");
  }
  if (!positive(sim_user.grip_target_n)) return bad("sim_user.grip_target_n must be positive");
  return {};
}

std::string PegInHoleConfig::describe() const {
  return fmt::format(
      "peg r={:.2f} mm, h={:.1f} mm, {:.0f} g, breaks at {:.2f} N (filter {:.0f} ms); hole clearance {:.2f} mm; "
      "{} x 4 trials ({} familiarisation), timeout {:.0f} s; familiarisation {:.0f} + {:.0f} s; finger coupling "
      "{:.2f} N m/rad, device force scale {:.2f}, contact solver tolerance {:.0e}, torsional friction {}, {} emulated device substeps",
      1e3 * peg.radius_m, 1e3 * peg.length_m, 1e3 * peg.mass_kg, peg.break_force_n,
      1e3 * peg.break_filter_time_constant_s, 1e3 * hole.clearance_m, main_task.repetitions,
      main_task.familiarisation_trials, main_task.trial_timeout_s, familiarisation.spring_phase_s,
      familiarisation.ground_phase_s, devices.finger_joint_stiffness_nm_per_rad, devices.force_scale,
      devices.solver_tolerance, devices.torsional_friction ? "on" : "off", devices.emulator_substeps) +
         (tracker == SimTracker::ftm
              ? (ftm_device_leads ? "; tracked by the simulated FTM glove (device dipoles and leads)"
                                  : "; tracked by the simulated FTM glove (device dipoles only)")
              : "");
}

const char* to_string(SimTracker t) noexcept { return t == SimTracker::ftm ? "ftm" : "ideal"; }

Result<SimTracker> parse_sim_tracker(std::string_view name) {
  if (name == "ideal") return SimTracker::ideal;
  if (name == "ftm") return SimTracker::ftm;
  return make_error(Errc::invalid_argument,
                    fmt::format("tracker '{}': use 'ideal' (the commanded hand) or 'ftm' (the simulated FTM glove)", name));
}

Result<PegInHoleConfig> PegInHoleConfig::load_file(const std::filesystem::path& path) {
  auto text = read_input_file(path, "peg-in-hole config");
  if (!text) return text.error();
  return parse(*text, path.string());
}

Result<PegInHoleConfig> PegInHoleConfig::parse(const std::string& toml_text, const std::string& source_name) {
  auto root_r = Config::parse(toml_text, source_name);
  if (!root_r) return root_r.error();
  const Config& root = *root_r;
  PegInHoleConfig out;
  PEG_CHECK(root.check_keys("top level", {"study", "peg", "hole", "layout", "familiarisation", "main_task", "devices",
                                           "recording", "sim_user"}));
  const auto sub = [&](const char* name) -> Result<std::optional<Config>> {
    if (!root.contains(name)) return std::optional<Config>{};
    auto t = root.table(name);
    if (!t) return t.error();
    return std::optional<Config>(*t);
  };
  {
    PEG_TRY(t, sub("study"));
    if (t) {
      PEG_CHECK(t->check_keys("study", {"name", "seed", "tracker", "ftm_device_leads"}));
      PEG_TRY(leads, t->get_bool_or("ftm_device_leads", out.ftm_device_leads));
      out.ftm_device_leads = leads;
      PEG_TRY(name, t->get_string_or("name", out.name));
      out.name = name;
      PEG_TRY(tracker, t->get_string_or("tracker", to_string(out.tracker)));
      auto kind = parse_sim_tracker(tracker);
      if (!kind) return kind.error().with_context(source_name + ": [study] tracker");
      out.tracker = *kind;
      PEG_TRY(seed, t->get_int_or("seed", 1, 0, std::numeric_limits<std::int64_t>::max()));
      out.seed = static_cast<std::uint64_t>(seed);
    }
  }
  {
    PEG_TRY(t, sub("peg"));
    if (t) {
      PEG_CHECK(t->check_keys("peg", {"radius_m", "length_m", "mass_kg", "friction", "break_force_n",
                                        "break_filter_time_constant_s", "colour_scale_max_n", "respawn_delay_s",
                                        "respawn_dropped"}));
      PegOptions& p = out.peg;
      PEG_CHECK(read_double(*t, "radius_m", p.radius_m, 0.001, 0.2));
      PEG_CHECK(read_double(*t, "length_m", p.length_m, 0.01, 0.5));
      PEG_CHECK(read_double(*t, "mass_kg", p.mass_kg, 0.001, 5.0));
      PEG_CHECK(read_double(*t, "friction", p.friction, 0.05, 2.0));
      PEG_CHECK(read_double(*t, "break_force_n", p.break_force_n, 0.01, 100.0));
      PEG_CHECK(read_double(*t, "break_filter_time_constant_s", p.break_filter_time_constant_s, 0.0, 1.0));
      PEG_CHECK(read_double(*t, "colour_scale_max_n", p.colour_scale_max_n, 0.01, 100.0));
      PEG_CHECK(read_double(*t, "respawn_delay_s", p.respawn_delay_s, 0.0, 10.0));
      PEG_TRY(rd, t->get_bool_or("respawn_dropped", p.respawn_dropped));
      p.respawn_dropped = rd;
    }
  }
  {
    PEG_TRY(t, sub("hole"));
    if (t) {
      PEG_CHECK(t->check_keys("hole", {"clearance_m", "plate_thickness_m", "insertion_depth_m"}));
      PEG_CHECK(read_double(*t, "clearance_m", out.hole.clearance_m, 1e-5, 0.05));
      PEG_CHECK(read_double(*t, "plate_thickness_m", out.hole.plate_thickness_m, 0.005, 0.3));
      PEG_CHECK(read_double(*t, "insertion_depth_m", out.hole.insertion_depth_m, 0.001, 0.3));
    }
  }
  {
    PEG_TRY(t, sub("layout"));
    if (t) {
      PEG_CHECK(t->check_keys("layout", {"table_height_m", "peg_start_m", "peg_start_range_m", "hole_m", "hole_range_m"}));
      PEG_CHECK(read_double(*t, "table_height_m", out.layout.table_height_m, 0.0, 2.0));
      PEG_CHECK(read_vec3(*t, "peg_start_m", out.layout.peg_start_m));
      PEG_CHECK(read_vec3(*t, "peg_start_range_m", out.layout.peg_start_range_m));
      PEG_CHECK(read_vec3(*t, "hole_m", out.layout.hole_m));
      PEG_CHECK(read_vec3(*t, "hole_range_m", out.layout.hole_range_m));
    }
  }
  {
    PEG_TRY(t, sub("familiarisation"));
    if (t) {
      PEG_CHECK(t->check_keys("familiarisation", {"spring_phase_s", "ground_phase_s", "spring_anchor_m",
                                                    "spring_stiffness_n_per_m", "spring_damping_ns_per_m"}));
      FamiliarisationOptions& f = out.familiarisation;
      PEG_CHECK(read_double(*t, "spring_phase_s", f.spring_phase_s, 0.0, 3600.0));
      PEG_CHECK(read_double(*t, "ground_phase_s", f.ground_phase_s, 0.0, 3600.0));
      PEG_CHECK(read_vec3(*t, "spring_anchor_m", f.spring_anchor_m));
      PEG_CHECK(read_double(*t, "spring_stiffness_n_per_m", f.spring_stiffness_n_per_m, 0.0, 1e5));
      PEG_CHECK(read_double(*t, "spring_damping_ns_per_m", f.spring_damping_ns_per_m, 0.0, 1e4));
    }
  }
  {
    PEG_TRY(t, sub("main_task"));
    if (t) {
      PEG_CHECK(t->check_keys("main_task", {"repetitions", "familiarisation_trials", "trial_timeout_s"}));
      PEG_TRY(reps, t->get_int_or("repetitions", out.main_task.repetitions, 1, 100));
      out.main_task.repetitions = static_cast<int>(reps);
      PEG_TRY(fam, t->get_int_or("familiarisation_trials", out.main_task.familiarisation_trials, 0, 400));
      out.main_task.familiarisation_trials = static_cast<int>(fam);
      PEG_CHECK(read_double(*t, "trial_timeout_s", out.main_task.trial_timeout_s, 1.0, 3600.0));
    }
  }
  {
    PEG_TRY(t, sub("devices"));
    if (t) {
      PEG_CHECK(t->check_keys("devices", {"fingers", "model", "finger_joint_stiffness_nm_per_rad", "force_scale",
                                              "solver_tolerance", "torsional_friction",
                                              "emulator_substeps"}));
      PEG_CHECK(read_double(*t, "finger_joint_stiffness_nm_per_rad", out.devices.finger_joint_stiffness_nm_per_rad,
                            0.05, 20.0));
      PEG_CHECK(read_double(*t, "force_scale", out.devices.force_scale, 0.01, 10.0));
      PEG_CHECK(read_double(*t, "solver_tolerance", out.devices.solver_tolerance, 1e-12, 1e-3));
      PEG_TRY(substeps, t->get_int_or("emulator_substeps", out.devices.emulator_substeps, 1, 1000));
      out.devices.emulator_substeps = static_cast<int>(substeps);
      PEG_TRY(torsion, t->get_bool_or("torsional_friction", out.devices.torsional_friction));
      out.devices.torsional_friction = torsion;
      if (t->contains("fingers")) {
        PEG_TRY(names, t->get_strings("fingers"));
        out.devices.fingers.clear();
        for (const std::string& n : names) {
          auto f = finger_from(n);
          if (!f) return f.error().with_context(t->where("fingers"));
          out.devices.fingers.push_back(*f);
        }
      }
      PEG_TRY(model, t->get_string_or("model", ""));
      out.devices.model = model;
    }
  }
  {
    PEG_TRY(t, sub("recording"));
    if (t) {
      PEG_CHECK(t->check_keys("recording", {"enabled", "rate_hz"}));
      PEG_TRY(en, t->get_bool_or("enabled", out.recording.enabled));
      out.recording.enabled = en;
      PEG_CHECK(read_double(*t, "rate_hz", out.recording.rate_hz, 0.1, 1000.0));
    }
  }
  {
    PEG_TRY(t, sub("sim_user"));
    if (t) {
      SimUserOptions& s = out.sim_user;
      struct Field {
        const char* key;
        double* value;
        double lo, hi;
      };
      const Field fields[] = {
          {"hand_length_m", &s.hand_length_m, 0.12, 0.26},
          {"hand_width_m", &s.hand_width_m, 0.06, 0.13},
          {"reach_speed_mps", &s.reach_speed_mps, 0.01, 3.0},
          {"lift_height_m", &s.lift_height_m, 0.0, 0.5},
          {"rotate_duration_s", &s.rotate_duration_s, 0.05, 10.0},
          {"insert_speed_mps", &s.insert_speed_mps, 0.001, 1.0},
          {"position_noise_m", &s.position_noise_m, 0.0, 0.05},
          {"speed_noise_fraction", &s.speed_noise_fraction, 0.0, 1.0},
          {"angle_noise_rad", &s.angle_noise_rad, 0.0, 0.5},
          {"visual_position_noise_m", &s.visual_position_noise_m, 0.0, 0.05},
          {"visual_angle_noise_rad", &s.visual_angle_noise_rad, 0.0, 0.5},
          {"visual_force_noise_n", &s.visual_force_noise_n, 0.0, 10.0},
          {"haptic_force_noise_n", &s.haptic_force_noise_n, 0.0, 10.0},
          {"visual_reaction_s", &s.visual_reaction_s, 0.0, 5.0},
          {"haptic_reaction_s", &s.haptic_reaction_s, 0.0, 5.0},
          {"guarded_speed_mps", &s.guarded_speed_mps, 0.001, 1.0},
          {"grip_target_n", &s.grip_target_n, 0.01, 50.0},
          {"felt_ceiling_n", &s.felt_ceiling_n, 0.05, 50.0},
          {"grip_load_ratio", &s.grip_load_ratio, 0.0, 10.0},
          {"closing_speed", &s.closing_speed, 0.01, 10.0},
          {"feedforward_closure", &s.feedforward_closure, 0.0, 2.0},
          {"feedforward_closure_sd", &s.feedforward_closure_sd, 0.0, 2.0},
          {"index_abduction_rad", &s.index_abduction_rad, -0.5, 0.5},
          {"middle_abduction_rad", &s.middle_abduction_rad, -0.5, 0.5},
          {"thumb_cmc_flexion_deg", &s.thumb_cmc_flexion_deg, -90.0, 90.0},
          {"thumb_cmc_abduction_deg", &s.thumb_cmc_abduction_deg, -90.0, 90.0},
          {"thumb_mcp_flexion_deg", &s.thumb_mcp_flexion_deg, -90.0, 90.0},
          {"thumb_ip_flexion_deg", &s.thumb_ip_flexion_deg, -90.0, 90.0},
          {"thumb_pronation_deg", &s.thumb_pronation_deg, -180.0, 180.0},
          {"alignment_tolerance_m", &s.alignment_tolerance_m, 1e-5, 0.05},
          {"alignment_tolerance_rad", &s.alignment_tolerance_rad, 1e-4, 0.5},
      };
      std::set<std::string> known;
      for (const Field& f : fields) known.insert(f.key);
      PEG_CHECK(t->check_keys("sim_user", known));
      for (const Field& f : fields) PEG_CHECK(read_double(*t, f.key, *f.value, f.lo, f.hi));
    }
  }
  if (Status s = out.validate(); !s) return s.error().with_context(source_name);
  return out;
}

}  // namespace proprio::peg_in_hole
