// proprio calibrate ftm: the FTM glove's per-user calibration (Lee 2021,
// §3.2.3; issue 27), guided on stdout: a figure-eight for the compasses (with
// a coverage indicator), then the three known poses, each taken once the hand
// has moved into it and held still. The solve is the library's
// (ftm::calibrate_ftm on what this command recorded); this file only guides,
// checks and reports. Three inputs: a live board (hidapi), the board emulator
// speaking the real bytes with a simulated wearer behind it (--emulate), or
// the simulated wearer alone in simulated time (--subject without --emulate).
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "hid_monitor_common.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/random.hpp"
#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm/mag_calibration.hpp"
#include "proprio/ftm_board/ftm_device.hpp"
#include "proprio/ftm_board/ftm_emulator.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::cli {

namespace calibrate_ftm {

namespace fs = std::filesystem;
using ftm::FtmEvent;

struct Args {
  int subject = -1;
  bool emulate = false;
  std::uint64_t seed = 1;
  std::vector<std::string> unplugs;
  double drop = 0.0;
  double corrupt = 0.0;
  std::string user;
  std::string out;
  std::string hand = "right";
  double hand_length_m = 0.19;
  double hand_width_m = 0.10;
  double hold_s = 2.0;
  double pose_timeout_s = 30.0;
  double figure_eight_timeout_s = 60.0;
  double min_coverage = 0.4;
  double disconnect_timeout_s = 3.0;
  double max_residual_deg = 10.0;
  double connect_timeout_s = 5.0;
  std::string vid = hex4(devices::kFtmUsbVendorId);
  std::string pid = hex4(devices::kFtmUsbProductId);
  std::string serial;
  std::string path;
  bool yes = false;
  bool force = false;
};

// The figure-eight runs at least this long, so a lucky first second does not end it.
constexpr double kMinFigureEightS = 4.0;
// Compass samples per IMU before a fit is tried (MagFitOptions' minimum, with margin).
constexpr std::size_t kMinMagSamples = 200;

// The fit's own coverage threshold is the one the wearer is shown.
ftm::MagFitOptions mag_options(const Args& a) {
  ftm::MagFitOptions o;
  o.min_coverage = a.min_coverage;
  return o;
}

// $XDG_CONFIG_HOME/proprio/ftm/[<user>_]<hand>.toml, else ~/.config/...: per user, as calibrate wrist.
Result<fs::path> default_out(const std::string& user, const std::string& hand) {
  const std::string name = (user.empty() ? std::string() : user + "_") + hand + ".toml";
  if (const char* x = std::getenv("XDG_CONFIG_HOME"); x && *x) return fs::path(x) / "proprio" / "ftm" / name;
  if (const char* h = std::getenv("HOME"); h && *h) return fs::path(h) / ".config" / "proprio" / "ftm" / name;
  return make_error(Errc::not_found,
                    "neither XDG_CONFIG_HOME nor HOME is set, so there is no per-user folder: pass --out");
}

// A user name becomes part of a file name: no separators, no dot files.
std::string check_user(const std::string& name) {
  if (name.empty() || name.size() > 64) return "1 to 64 characters";
  if (name.front() == '.') return "'" + name + "' must not start with '.'";
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
                    c == '-' || c == '.';
    if (!ok) return "'" + name + "': only letters, digits, '.', '_' and '-' (it names the file)";
  }
  return {};
}

bool finite_event(const FtmEvent& e) {
  switch (e.kind) {
    case FtmEvent::Kind::imu:
      return e.imu.accel_mps2.allFinite() && e.imu.gyro_radps.allFinite() && e.imu.mag_uT.allFinite();
    case FtmEvent::Kind::bend: return std::isfinite(e.bend.capacitance_pF);
    case FtmEvent::Kind::wrist:
      return !e.wrist.valid || (e.wrist.T_world_wrist.p.allFinite() && e.wrist.T_world_wrist.q.coeffs().allFinite());
  }
  return false;
}

bool imu_usable(const FtmEvent& e) {
  return e.kind == FtmEvent::Kind::imu && (e.imu.status & ~ftm::sample_status::mag_overflow) == 0;
}

// ---------------------------------------------------------------------------
// Where the samples come from.

class Input {
 public:
  virtual ~Input() = default;
  // Appends what has arrived; an error when the input failed.
  virtual Status pull(std::vector<FtmEvent>& out) = 0;
  virtual TimeNs now_ns() const = 0;  // the input's clock: simulated or CLOCK_MONOTONIC
  virtual bool real_time() const = 0;
  virtual void print_totals() const {}
};

// The simulated wearer in simulated time, as fast as it computes.
class SimInput final : public Input {
 public:
  explicit SimInput(std::unique_ptr<ftm_sim::FtmWearerSimulator> sim) : sim_(std::move(sim)) {}
  Status pull(std::vector<FtmEvent>& out) override {
    t_ns_ += 10 * kNsPerMillisecond;
    sim_->advance(t_ns_, out);
    return {};
  }
  TimeNs now_ns() const override { return t_ns_; }
  bool real_time() const override { return false; }

 private:
  std::unique_ptr<ftm_sim::FtmWearerSimulator> sim_;
  TimeNs t_ns_ = 0;
};

// A board (real, or the emulator over the in-memory link) read by FtmBoardDevice.
class BoardInput final : public Input {
 public:
  BoardInput(std::unique_ptr<devices::FtmBoardDevice> device, std::string what, const Args& a)
      : device_(std::move(device)), feed_(*device_), what_(std::move(what)),
        disconnect_timeout_ns_(seconds_to_ns(a.disconnect_timeout_s)),
        connect_timeout_ns_(seconds_to_ns(a.connect_timeout_s)) {}
  ~BoardInput() override {
    device_->stop();
    if (server) server->stop();
  }
  Status start() {
    device_->set_state_callback(print_link_state);
    if (auto s = device_->start(); !s) return s;
    started_ns_ = now_ns();
    return {};
  }
  Status pull(std::vector<FtmEvent>& out) override {
    const TimeNs now = now_ns();
    // A few ms behind now: a bend report that arrives after a later IMU one is not lost (FtmBoardFeed).
    const std::size_t before = out.size();
    feed_.advance(now - 20 * kNsPerMillisecond, out);
    if (out.size() > before) {
      seen_data_ = true;
      last_data_ns_ = now;
    }
    const bool streaming = device_->state() == hid::LinkState::streaming;
    if (!seen_data_) {
      if (now - started_ns_ > connect_timeout_ns_) {
        return make_error(Errc::unavailable, what_ + " sent no samples within " +
                                                 fmt_seconds(connect_timeout_ns_) +
                                                 "; is it plugged in and streaming? 'proprio ftm-board monitor' "
                                                 "shows what it sends");
      }
      return {};
    }
    if (streaming && now - last_data_ns_ < disconnect_timeout_ns_) return {};
    if (now - last_data_ns_ > disconnect_timeout_ns_) {
      return make_error(Errc::unavailable, what_ + (streaming ? " stopped sending" : " was unplugged") +
                                               " and did not come back within " + fmt_seconds(disconnect_timeout_ns_) +
                                               " (--disconnect-timeout); plug it back in and start again");
    }
    return {};
  }
  TimeNs now_ns() const override { return MonotonicClock::instance().now_ns(); }
  bool real_time() const override { return true; }
  void print_totals() const override {
    const devices::FtmDeviceStats st = device_->stats();
    std::printf("board: %llu connect(s), %llu disconnect(s); %llu IMU and %llu bend samples, %llu lost IMU and %llu "
                "lost bend samples, %llu undecodable reports, %llu restart(s), %llu dropped at a full queue\n",
                ull(st.connects), ull(st.disconnects), ull(st.stream.imu_samples), ull(st.stream.bend_samples),
                ull(st.stream.lost_imu_samples), ull(st.stream.lost_bend_samples), ull(st.stream.decode_errors),
                ull(st.stream.device_resets), ull(st.queue_overruns));
  }

  // The emulated board's side, when there is one.
  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<devices::FtmBoardEmulatorServer> server;

 private:
  static unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }
  static std::string fmt_seconds(DurationNs ns) {
    char b[32];
    std::snprintf(b, sizeof b, "%.1f s", ns_to_seconds(ns));
    return b;
  }
  std::unique_ptr<devices::FtmBoardDevice> device_;
  devices::FtmBoardFeed feed_;
  std::string what_;
  DurationNs disconnect_timeout_ns_;
  DurationNs connect_timeout_ns_;
  TimeNs started_ns_ = 0;
  TimeNs last_data_ns_ = 0;
  bool seen_data_ = false;
};

// ---------------------------------------------------------------------------
// The guided session.

class Session {
 public:
  Session(Input& input, const Args& a, bool interactive) : in_(input), a_(a), interactive_(interactive) {
    tty_out_ = ::isatty(STDOUT_FILENO) != 0;
  }

  // Pulls once (sleeping a little in real time); drops non-finite samples.
  Status step() {
    if (g_sigint_stop.load()) return make_error(Errc::unavailable, "interrupted (Ctrl-C) during " + step_name_);
    if (in_.real_time()) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    fresh_.clear();
    if (auto s = in_.pull(fresh_); !s) return s.error().with_context("during " + step_name_);
    for (const FtmEvent& e : fresh_) {
      if (!finite_event(e)) {
        ++non_finite_;
        continue;
      }
      events_.push_back(e);
    }
    return {};
  }

  // Enter on a terminal, while the board keeps being read (its queue holds ~4 s).
  Status wait_for_enter(const char* what) {
    if (!interactive_) return {};
    std::printf("%s -- press Enter when ready\n", what);
    std::fflush(stdout);
    for (;;) {
      if (auto s = step(); !s) return s;
      pollfd p{STDIN_FILENO, POLLIN, 0};
      if (::poll(&p, 1, 0) > 0) {
        char buf[256];
        const ssize_t n = ::read(STDIN_FILENO, buf, sizeof buf);
        if (n <= 0) return make_error(Errc::unavailable, "standard input closed while waiting for Enter");
        return {};
      }
    }
  }

  Status figure_eight(ftm::FtmCalibration& base) {
    std::printf("\nStep 1/4, figure-eight: swing the hand through slow figure-eights, turning it over in every "
                "direction (palm up, down, left, right, fingers up and down), away from steel and magnets.\n");
    step_name_ = "the figure-eight";
    if (auto s = wait_for_enter("Start swinging"); !s) return s;
    fe_begin_ = events_.size();
    const TimeNs t0 = in_.now_ns();
    TimeNs next_print = t0;
    TimeNs next_try = t0 + seconds_to_ns(kMinFigureEightS);
    std::array<std::vector<Vec3>, ftm::kFtmImuCount> mag;
    std::string last_fit_error;
    for (;;) {
      const std::size_t before = events_.size();
      if (auto s = step(); !s) return s;
      for (std::size_t j = before; j < events_.size(); ++j) {
        const FtmEvent& e = events_[j];
        if (imu_usable(e) && e.imu.mag_fresh && (e.imu.status & ftm::sample_status::mag_overflow) == 0) {
          mag[e.index % ftm::kFtmImuCount].push_back(e.imu.mag_uT);
        }
      }
      const TimeNs now = in_.now_ns();
      if (now < next_print && now < next_try) continue;
      std::array<double, ftm::kFtmImuCount> cov{};
      double worst = 1.0;
      std::size_t fewest = SIZE_MAX;
      for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
        cov[i] = centred_coverage(mag[i]);
        worst = std::min(worst, cov[i]);
        fewest = std::min(fewest, mag[i].size());
      }
      const double elapsed = ns_to_seconds(now - t0);
      if (now >= next_print) {
        next_print = now + (tty_out_ ? 250 : 1000) * kNsPerMillisecond;
        progress_line("  figure-eight %5.1f s  compass directions covered: dorsum %3.0f%%  thumb %3.0f%%  index "
                      "%3.0f%%  middle %3.0f%%  (need %.0f%% each)",
                      elapsed, 100 * cov[0], 100 * cov[1], 100 * cov[2], 100 * cov[3], 100 * a_.min_coverage);
      }
      if (now >= next_try && worst >= a_.min_coverage && fewest >= kMinMagSamples) {
        next_try = now + kNsPerSecond;
        fe_end_ = events_.size();
        const std::span<const FtmEvent> fe(events_.data() + fe_begin_, fe_end_ - fe_begin_);
        auto field = ftm::solve_mag_and_field(fe, base, mag_options(a_));
        if (field) {
          end_progress();
          std::printf("  figure-eight done after %.1f s: every compass covered at least %.0f%% of the directions\n",
                      elapsed, 100 * worst);
          base = std::move(*field);
          field_ = base;
          return {};
        }
        if (field.error().message != last_fit_error) {
          last_fit_error = field.error().message;
          end_progress();
          std::printf("  not yet: %s; keep swinging\n", last_fit_error.c_str());
        }
      }
      if (elapsed > a_.figure_eight_timeout_s) {
        end_progress();
        std::string msg = "the figure-eight did not calibrate the compasses within " +
                          std::to_string(static_cast<int>(a_.figure_eight_timeout_s)) + " s (--figure-eight-timeout): ";
        if (fewest < kMinMagSamples) {
          msg += "only " + std::to_string(fewest == SIZE_MAX ? 0 : fewest) +
                 " compass samples from the worst IMU (is every compass working?)";
        } else if (worst < a_.min_coverage) {
          char b[160];
          std::snprintf(b, sizeof b, "coverage too low (worst IMU %.0f%%, need %.0f%%): turn the hand through more "
                        "orientations", 100 * worst, 100 * a_.min_coverage);
          msg += b;
        } else {
          msg += last_fit_error;
        }
        return make_error(Errc::unavailable, msg);
      }
    }
  }

  Status pose(std::size_t k) {
    const auto pose = static_cast<ftm::FtmCalibrationPose>(k);
    std::printf("\nStep %zu/4, pose %zu of 3 (%s): %s\n", k + 2, k + 1, std::string(ftm::to_string(pose)).c_str(),
                std::string(ftm::instruction(pose)).c_str());
    std::printf("  %s, then hold still for %.1f s (rest the forearm on a table)\n",
                interactive_ ? "move into the pose, press Enter" : "move into the pose now", a_.hold_s);
    step_name_ = "pose " + std::to_string(k + 1) + " (" + std::string(ftm::to_string(pose)) + ")";
    const std::size_t prompt_index = events_.size();
    pose_begin_[k] = prompt_index;
    const TimeNs prompt_ns = in_.now_ns();
    if (auto s = wait_for_enter("In the pose"); !s) return s;
    // The collector sees the session from the figure-eight's start, as calibrate_ftm's will.
    ftm::FtmPoseCollector collector(pose, field_, ftm::MahonyOptions{});
    for (std::size_t j = fe_begin_; j < events_.size(); ++j) collector.push(events_[j]);
    // The still window must lie wholly after the prompt (after Enter, on a
    // terminal): a hand still holding the previous pose is not taken for the
    // next one, as long as the wearer starts moving within --hold seconds.
    // (A threshold on motion instead cannot tell a small deliberate move,
    // flat to thumb_parallel, from a held hand's tremor.)
    Motion motion;
    motion.last_ns = prompt_ns;
    for (std::size_t j = prompt_index; j < events_.size(); ++j) motion.note(events_[j]);
    const TimeNs t0 = in_.now_ns();
    const DurationNs hold_ns = seconds_to_ns(a_.hold_s);
    TimeNs next_print = t0;
    double worst_dps = 0.0;
    for (;;) {
      const std::size_t before = events_.size();
      if (auto s = step(); !s) return s;
      for (std::size_t j = before; j < events_.size(); ++j) {
        collector.push(events_[j]);
        motion.note(events_[j]);
        if (imu_usable(events_[j])) worst_dps = std::max(worst_dps, rad_to_deg(events_[j].imu.gyro_radps.norm()));
      }
      const TimeNs now = in_.now_ns();
      if (now - t0 >= hold_ns && collector.still(hold_ns)) {
        end_progress();
        pose_end_[k] = events_.size();
        std::printf("  pose %zu taken after %.1f s\n", k + 1, ns_to_seconds(now - t0));
        return {};
      }
      if (now >= next_print) {
        next_print = now + (tty_out_ ? 250 : 1000) * kNsPerMillisecond;
        const double held =
            std::min(1.0, ns_to_seconds(now - std::max(motion.last_ns, t0)) / a_.hold_s);
        const int bars = static_cast<int>(std::lround(held * 20));
        progress_line("  %s [%-20s] %3.0f%% still   peak rotation %.1f deg/s (limit %.1f)",
                      held > 0.0 ? "holding" : "moving", std::string(bars, '#').c_str(),
                      100 * held, worst_dps, rad_to_deg(ftm::FtmPoseCollector::kStillGyroRadps));
        worst_dps = 0.0;
      }
      if (ns_to_seconds(now - t0) > a_.pose_timeout_s) {
        end_progress();
        char b[320];
        std::snprintf(b, sizeof b,
                      "pose %zu (%s): the hand was not held still for %.1f s within %.0f s (--pose-timeout); %s",
                      k + 1, std::string(ftm::to_string(pose)).c_str(), a_.hold_s, a_.pose_timeout_s,
                      "every IMU's rotation must stay under 8.6 deg/s and every sensor must keep sending");
        return make_error(Errc::unavailable, b);
      }
    }
  }

  ftm::FtmCalibrationRecording recording() const {
    ftm::FtmCalibrationRecording rec;
    rec.figure_eight.assign(events_.begin() + static_cast<std::ptrdiff_t>(fe_begin_),
                            events_.begin() + static_cast<std::ptrdiff_t>(fe_end_));
    // The figure-eight's tail after the fit (the hand still swinging) belongs to pose 1's part.
    for (std::size_t k = 0; k < ftm::kFtmCalibrationPoseCount; ++k) {
      const std::size_t from = k == 0 ? fe_end_ : pose_end_[k - 1];
      rec.poses[k].assign(events_.begin() + static_cast<std::ptrdiff_t>(from),
                          events_.begin() + static_cast<std::ptrdiff_t>(pose_end_[k]));
    }
    return rec;
  }

  std::span<const FtmEvent> figure_eight_events() const {
    return {events_.data() + fe_begin_, fe_end_ - fe_begin_};
  }
  std::uint64_t non_finite() const { return non_finite_; }

 private:
  static double centred_coverage(const std::vector<Vec3>& raw) {
    if (raw.size() < 2) return 0.0;
    // What the fit will judge: its corrected samples' coverage, once a fit is possible.
    ftm::MagFitOptions any;
    any.min_coverage = 0.0;
    if (raw.size() >= kMinMagSamples) {
      if (auto fit = ftm::fit_mag_ellipsoid(raw, any)) return fit->second.coverage;
    }
    // Before that, the mid-range as a rough hard-iron estimate.
    Vec3 lo = raw.front(), hi = raw.front();
    for (const Vec3& v : raw) {
      lo = lo.cwiseMin(v);
      hi = hi.cwiseMax(v);
    }
    const Vec3 c = 0.5 * (lo + hi);
    std::vector<Vec3> d;
    d.reserve(raw.size());
    for (const Vec3& v : raw) d.push_back(v - c);
    return ftm::direction_coverage(d);
  }
  // For the progress bar: when an IMU last turned faster than the stillness limit.
  struct Motion {
    TimeNs last_ns = 0;
    void note(const FtmEvent& e) {
      if (imu_usable(e) && !(e.imu.gyro_radps.norm() < ftm::FtmPoseCollector::kStillGyroRadps)) {
        last_ns = std::max(last_ns, e.imu.time_ns);
      }
    }
  };
  template <typename... T>
  void progress_line(const char* format, T... values) {
    if (tty_out_) std::printf("\r\033[K");
    std::printf(format, values...);
    if (!tty_out_) std::printf("\n");
    open_line_ = tty_out_;
    std::fflush(stdout);
  }
  void end_progress() {
    if (open_line_) std::printf("\n");
    open_line_ = false;
  }

  Input& in_;
  const Args& a_;
  bool interactive_;
  bool tty_out_ = false;
  bool open_line_ = false;
  std::vector<FtmEvent> events_;
  std::vector<FtmEvent> fresh_;
  std::uint64_t non_finite_ = 0;
  std::string step_name_ = "the start";
  std::size_t fe_begin_ = 0;
  std::size_t fe_end_ = 0;
  std::array<std::size_t, ftm::kFtmCalibrationPoseCount> pose_begin_{};
  std::array<std::size_t, ftm::kFtmCalibrationPoseCount> pose_end_{};
  ftm::FtmCalibration field_;
};

// ---------------------------------------------------------------------------
// The result, and how well the three poses agree with it.

// Returns the worst bend sensor's RMS residual, rad.
double print_result(const ftm::FtmCalibrationOutcome& outcome, std::span<const FtmEvent> figure_eight,
                    const ftm_sim::FtmWearerSimulator* truth) {
  double worst_rms = 0.0;
  const ftm::FtmCalibration& cal = outcome.calibration;
  std::printf("\nCompasses (ellipsoid fit on the figure-eight):\n");
  for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
    std::vector<Vec3> raw;
    for (const FtmEvent& e : figure_eight) {
      if (e.kind == FtmEvent::Kind::imu && e.index == i && e.imu.mag_fresh && e.imu.status == 0) {
        raw.push_back(e.imu.mag_uT);
      }
    }
    const Vec3& h = cal.mag[i].hard_iron_uT;
    std::printf("  %-17s hard iron [%6.1f %6.1f %6.1f] uT", std::string(ftm::to_string(static_cast<ftm::FtmImu>(i))).c_str(),
                h.x(), h.y(), h.z());
    if (auto fit = ftm::fit_mag_ellipsoid(raw); fit) {
      std::printf("  field %.1f uT  residual %.2f uT rms  coverage %.0f%%  (%zu samples)\n", fit->second.field_uT,
                  fit->second.residual_rms_uT, 100 * fit->second.coverage, fit->second.samples);
    } else {
      std::printf("\n");
    }
  }
  std::printf("  field in the world: %.1f uT, dip %.1f deg\n", cal.earth_field_world_uT.norm(),
              rad_to_deg(std::asin(std::clamp(-cal.earth_field_world_uT.y() / std::max(1e-9, cal.earth_field_world_uT.norm()), -1.0, 1.0))));

  auto shape = HandShape::from_measurements(cal.hand_length_m, cal.hand_width_m);
  std::printf("\nIMU mountings (segment in IMU frame) and how far each pose's own estimate lies from them:\n");
  const std::size_t d = ftm::index_of(ftm::FtmImu::dorsum);
  for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
    const Vec3 r = rad_to_deg(1.0) * so3_log(cal.q_imu_segment[i]);
    std::printf("  %-17s rotation [%7.2f %7.2f %7.2f] deg (%.1f deg from nominal); per pose:",
                std::string(ftm::to_string(static_cast<ftm::FtmImu>(i))).c_str(), r.x(), r.y(), r.z(),
                rad_to_deg(angle_between(cal.q_imu_segment[i], Quat::Identity())));
    for (const ftm::FtmPoseCapture& c : outcome.captures) {
      Quat est;
      if (i == d) {
        if (!c.wrist_valid) {
          std::printf("  -");
          continue;
        }
        est = c.q_world_imu[d].normalized().conjugate() * c.T_world_wrist.q.normalized();
      } else {
        if (!shape) break;
        const HandModel model(*shape);
        const auto T = model.joint_poses_in_wrist(cal.hand, ftm::known_angles(c.pose, *shape));
        const Quat q_world_hand = (c.q_world_imu[d].normalized() * cal.q_imu_segment[d]).normalized();
        est = c.q_world_imu[i].normalized().conjugate() * q_world_hand *
              T[index_of(ftm::segment_of(static_cast<ftm::FtmImu>(i)))].q;
      }
      std::printf(" %5.2f", rad_to_deg(angle_between(est.normalized(), cal.q_imu_segment[i])));
    }
    std::printf(" deg%s\n", i == d && !outcome.captures[0].wrist_valid ? " (no wrist tracker: kept nominal)" : "");
  }

  std::printf("\nBend sensors, theta = beta0 + beta1 * rho, and the line's residual at each pose:\n");
  for (std::size_t b = 0; b < ftm::kFtmBendCount; ++b) {
    const auto bend = static_cast<ftm::FtmBend>(b);
    std::printf("  %-11s beta0 %8.2f deg  beta1 %7.3f deg/pF  residuals:", std::string(ftm::to_string(bend)).c_str(),
                rad_to_deg(cal.beta0_rad[b]), rad_to_deg(cal.beta1_rad_per_pF[b]));
    double ss = 0.0;
    for (const ftm::FtmPoseCapture& c : outcome.captures) {
      const double known = shape ? ftm::known_angles(c.pose, *shape)[index_of(ftm::dof_of(bend))] : 0.0;
      const double res = known - (cal.beta0_rad[b] + cal.beta1_rad_per_pF[b] * c.capacitance_pF[b]);
      ss += res * res;
      std::printf(" %+5.2f", rad_to_deg(res));
    }
    worst_rms = std::max(worst_rms, std::sqrt(ss / 3.0));
    std::printf(" deg (rms %.2f)", rad_to_deg(std::sqrt(ss / 3.0)));
    if (truth != nullptr) {
      // The simulator's linear term: C = C0 (1 + g theta) -> theta = C / (C0 g) - 1 / g.
      const double c0 = truth->bend_c0_pF()[b], g = truth->bend_gain_per_rad()[b];
      std::printf("; simulator's own: beta0 %.2f deg, beta1 %.3f deg/pF", rad_to_deg(-1.0 / g),
                  rad_to_deg(1.0 / (c0 * g)));
    }
    std::printf("\n");
  }
  std::printf("\nPoses as captured (worst IMU's gyro rms over the last 0.5 s):");
  for (const ftm::FtmPoseCapture& c : outcome.captures) {
    std::printf("  %s %.2f deg/s", std::string(ftm::to_string(c.pose)).c_str(), rad_to_deg(c.gyro_rms_radps));
  }
  std::printf("\n");
  return worst_rms;
}

// ---------------------------------------------------------------------------

Result<std::vector<devices::FtmOutage>> parse_outages(const std::vector<std::string>& specs) {
  std::vector<devices::FtmOutage> out;
  for (const std::string& s : specs) {
    auto u = parse_board_unplug(s);
    if (!u) return u.error();
    out.push_back({u->first, u->second});
  }
  return out;
}

int run(const Args& a) {
  const bool sim = a.subject >= 0;
  if (a.emulate && !sim) {
    return report_error(Error{Errc::invalid_argument,
                              "--emulate needs --subject N: the simulated wearer behind the emulated board"});
  }
  if (!a.emulate && (!a.unplugs.empty() || a.drop > 0 || a.corrupt > 0)) {
    return report_error(Error{Errc::invalid_argument, "--unplug, --drop and --corrupt are faults of --emulate"});
  }
  if (sim && (!a.path.empty() || !a.serial.empty())) {
    return report_error(Error{Errc::invalid_argument, "--path and --serial choose a real board; not with --subject"});
  }
  const Handedness hand = a.hand == "left" ? Handedness::left : Handedness::right;

  // Where it goes, checked before anyone swings a hand for it.
  fs::path out = a.out;
  if (out.empty()) {
    auto d = default_out(a.user, a.hand);
    if (!d) return report_error(d.error());
    out = *d;
  }
  if (auto s = check_output_path(out, "FTM calibration"); !s) return report_error(s.error());
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_regular_file(out, ec)) {
    return report_error(Error{Errc::invalid_argument, "cannot write the FTM calibration to '" + out.string() +
                                                          "': it exists and is not a regular file"});
  }
  if (!a.force && fs::exists(out, ec)) {
    return report_error(Error{Errc::invalid_argument,
                              "'" + out.string() + "' exists; pass --force to overwrite it (a calibration is worth "
                                                   "keeping)"});
  }
  if (out.has_parent_path() && !fs::is_directory(out.parent_path(), ec)) {
    fs::create_directories(out.parent_path(), ec);
    if (ec) {
      return report_error(Error{Errc::io_error,
                                "cannot create the folder for '" + out.string() + "': " + ec.message()});
    }
  }

  // The input, and the hand it is on.
  ftm::FtmCalibration base = ftm::nominal_ftm_calibration(hand, a.hand_length_m, a.hand_width_m);
  std::unique_ptr<Input> input;
  std::unique_ptr<ftm_sim::FtmWearerSimulator> truth;  // a second, identical wearer for the report
  std::string what;
  if (sim) {
    ftm_sim::FtmWearerOptions wo;
    wo.hand = hand;
    wo.seed = a.seed;
    wo.subject.subject_index = a.subject;
    wo.task_s = a.pose_timeout_s * 3 + a.figure_eight_timeout_s;  // the wearer outlasts every timeout
    // The simulated wearer follows its own script, not the prompts: it must
    // hold each pose long enough for a --hold window among its wobble, and
    // not so long that a second window fits before it moves on (it would be
    // taken for the next pose): hold < pose_hold_s < 2 hold.
    wo.calibration.pose_hold_s = std::clamp(1.75 * a.hold_s, 3.0, 20.0);
    if (auto s = wo.validate(); !s) return report_error(s.error());
    auto wearer = ftm_sim::FtmWearerSimulator::create(wo);
    if (!wearer) return report_error(wearer.error());
    auto twin = ftm_sim::FtmWearerSimulator::create(wo);
    if (!twin) return report_error(twin.error());
    truth = std::move(*twin);
    const HandShape& shape = (*wearer)->model().shape();
    base = ftm::nominal_ftm_calibration(hand, shape.hand_length_m, shape.hand_width_m);
    if (!a.emulate) {
      what = "simulated subject " + std::to_string(a.subject) + " (seed " + std::to_string(a.seed) +
             ", simulated time)";
      input = std::make_unique<SimInput>(std::move(*wearer));
    } else {
      auto outages = parse_outages(a.unplugs);
      if (!outages) return report_error(outages.error());
      devices::FtmEmulatorOptions eo;
      eo.seed = mix_seed(a.seed, 0xf7b0a2d);
      eo.faults.drop_probability = a.drop;
      eo.faults.corrupt_probability = a.corrupt;
      eo.faults.unplugs = *outages;
      if (auto s = eo.validate(); !s) return report_error(s.error());
      auto emulator = devices::FtmBoardEmulator::create(eo, std::move(*wearer));
      if (!emulator) return report_error(emulator.error());
      auto link = std::make_shared<hid::FakeHidLink>();
      devices::FtmServeOptions so;
      so.seed = mix_seed(a.seed, 0x11a7);
      auto server = std::make_unique<devices::FtmBoardEmulatorServer>(std::move(*emulator), link, so);
      devices::FtmDeviceOptions dopt;
      dopt.reconnect_backoff_max_ns = 200 * kNsPerMillisecond;
      auto device = std::make_unique<devices::FtmBoardDevice>(std::make_unique<hid::FakeHidTransport>(link), dopt);
      what = "the emulated board (simulated subject " + std::to_string(a.subject) + ", seed " +
             std::to_string(a.seed) + ", real time)";
      auto board = std::make_unique<BoardInput>(std::move(device), "the emulated board", a);
      board->link = link;
      board->server = std::move(server);
      if (auto s = board->start(); !s) return report_error(s.error());
      board->server->start();
      const TimeNs zero = board->server->time_zero_ns();
      for (const devices::FtmOutage& u : eo.faults.unplugs) link->schedule_unplug(zero + u.at_ns, u.duration_ns);
      input = std::move(board);
    }
  } else {
    hid::HidDeviceSelector sel = devices::ftm_board_selector();
    sel.vendor_id = parse_hex_id(a.vid);
    sel.product_id = parse_hex_id(a.pid);
    sel.serial = a.serial;
    sel.path = a.path;
    if (!a.path.empty()) {
      if (auto s = hid::check_hidraw_node(a.path); !s) return report_error(s.error());
    } else {
      auto found = hid::enumerate_hid_devices(sel.vendor_id, sel.product_id);
      if (!found) return report_error(found.error());
      if (found->empty()) {
        return report_error(Error{Errc::not_found,
                                  "no FTM board found (USB " + a.vid + ":" + a.pid +
                                      "); plug it in, check 'proprio ftm-board list', or calibrate a simulated "
                                      "wearer with --subject N"});
      }
    }
    what = sel.describe();
    devices::FtmDeviceOptions dopt;
    auto board = std::make_unique<BoardInput>(
        std::make_unique<devices::FtmBoardDevice>(std::make_unique<hid::HidapiTransport>(sel), dopt), "the board", a);
    if (auto s = board->start(); !s) return report_error(s.error());
    input = std::move(board);
  }
  base.subject = a.user;
  if (auto s = base.validate(); !s) return report_error(s.error());

  // A simulated wearer follows its script and reads no keyboard.
  const bool interactive = !sim && !a.yes && ::isatty(STDIN_FILENO) != 0;
  std::printf("Calibrating the FTM glove on the %s hand from %s; the result goes to %s.\n", a.hand.c_str(),
              what.c_str(), out.string().c_str());
  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  Session session(*input, a, interactive);
  Status status = session.figure_eight(base);
  for (std::size_t k = 0; status && k < ftm::kFtmCalibrationPoseCount; ++k) status = session.pose(k);
  std::signal(SIGINT, previous);
  input->print_totals();
  if (session.non_finite() > 0) {
    std::printf("warning: %llu non-finite sample(s) were left out\n", static_cast<unsigned long long>(session.non_finite()));
  }
  if (!status) {
    return report_error(Error{status.error().code, "calibration abandoned, nothing written: " + status.error().message});
  }

  auto outcome = ftm::calibrate_ftm(session.recording(), base, ftm::MahonyOptions{}, mag_options(a));
  if (!outcome) {
    return report_error(Error{outcome.error().code, "calibration failed, nothing written: " + outcome.error().message});
  }
  const double worst_rms = print_result(*outcome, session.figure_eight_events(), sim ? truth.get() : nullptr);
  // Three poses held as asked fit each bend sensor's line within a few
  // degrees (imperfect poses, a mildly nonlinear sensor: 0-6 deg rms on the
  // simulated wearers); tens of degrees mean a pose was taken while the hand
  // held another one.
  if (!(worst_rms <= deg_to_rad(a.max_residual_deg))) {
    char b[320];
    std::snprintf(b, sizeof b,
                  "calibration rejected, nothing written: a bend sensor's line misses the three poses by %.1f deg rms "
                  "(--max-residual %.1f): a pose was probably not held as asked (or the hand moved on too early); "
                  "calibrate again",
                  rad_to_deg(worst_rms), a.max_residual_deg);
    return report_error(Error{Errc::invalid_argument, b});
  }

  const std::string text = ftm::format_ftm_calibration(outcome->calibration);
  if (auto s = write_file_atomic(out, text, "FTM calibration", a.force); !s) return report_error(s.error());
  if (auto back = ftm::load_ftm_calibration(out); !back) {
    return report_error(Error{back.error().code, "wrote " + out.string() + ", but it does not load back: " +
                                                     back.error().message});
  }
  std::printf("\nWrote %s\n", out.string().c_str());
  std::printf("Use it: a layer [[source]] with type = \"ftm\", input = \"device\", calibration = \"%s\" "
              "(docs/ftm.md).\n",
              fs::absolute(out, ec).string().c_str());
  return 0;
}

}  // namespace calibrate_ftm

void add_calibrate_ftm_command(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<calibrate_ftm::Args>();
  // The description is the command table's (command_table.cpp): `calibrate` spans programs.
  CLI::App* cmd = add_command(app, "calibrate ftm");
  cmd->add_option("--subject", a->subject,
                  "calibrate a simulated wearer (0-14) instead of a board on USB (simulated time, no waiting)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1));
  cmd->add_flag("--emulate", a->emulate,
                "with --subject: the wearer behind the board emulator, read over the in-memory HID link in real time "
                "by the same code as a real board");
  cmd->add_option("--seed", a->seed, "simulation seed (--subject)")->capture_default_str();
  cmd->add_option("--unplug", a->unplugs, "--emulate: AT:FOR s, the board loses power at AT for FOR (repeatable)")
      ->check([](const std::string& s) { return check_board_unplug(s); });
  cmd->add_option("--drop", a->drop, "--emulate: probability that a report is lost")->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--corrupt", a->corrupt, "--emulate: probability that a report has a bit flipped")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--user", a->user,
                  "whose calibration: saved as $XDG_CONFIG_HOME/proprio/ftm/<user>_<hand>.toml (else ~/.config/...)")
      ->check([](const std::string& s) { return calibrate_ftm::check_user(s); });
  cmd->add_option("--out", a->out, "write here instead of the per-user file");
  cmd->add_option("--hand", a->hand, "which hand wears the glove")
      ->check(CLI::IsMember({"left", "right"}))
      ->capture_default_str();
  cmd->add_option("--hand-length", a->hand_length_m, "wrist crease to middle fingertip, m (a real board)")
      ->check(CLI::Range(0.12, 0.26))
      ->capture_default_str();
  cmd->add_option("--hand-width", a->hand_width_m, "across the knuckles, m (a real board)")
      ->check(CLI::Range(0.06, 0.13))
      ->capture_default_str();
  cmd->add_option("--hold", a->hold_s,
                  "how long each pose must be held still, s; without Enter, start moving into a pose within this "
                  "long of its prompt")
      ->check(CLI::Range(0.5, 10.0))
      ->capture_default_str();
  cmd->add_option("--pose-timeout", a->pose_timeout_s, "give up on a pose not held still within this long, s")
      ->check(CLI::Range(1.0, 600.0))
      ->capture_default_str();
  cmd->add_option("--figure-eight-timeout", a->figure_eight_timeout_s,
                  "give up when the compasses are not calibrated within this long, s")
      ->check(CLI::Range(5.0, 600.0))
      ->capture_default_str();
  cmd->add_option("--min-coverage", a->min_coverage,
                  "fraction of the 32 compass direction bins each IMU's corrected samples must reach in the figure-eight")
      ->check(CLI::Range(0.4, 0.95))
      ->capture_default_str();
  cmd->add_option("--max-residual", a->max_residual_deg,
                  "reject the result when a bend sensor's line misses the three poses by more than this, deg rms")
      ->check(CLI::Range(0.5, 90.0))
      ->capture_default_str();
  cmd->add_option("--disconnect-timeout", a->disconnect_timeout_s,
                  "a board silent or unplugged this long ends the calibration, s")
      ->check(CLI::Range(0.2, 60.0))
      ->capture_default_str();
  cmd->add_option("--connect-timeout", a->connect_timeout_s, "wait this long for the board's first samples, s")
      ->check(CLI::Range(0.5, 60.0))
      ->capture_default_str();
  cmd->add_option("--vid", a->vid, "USB vendor ID, hexadecimal")
      ->check([](const std::string& s) { return check_hex_id(s); })
      ->capture_default_str();
  cmd->add_option("--pid", a->pid, "USB product ID, hexadecimal")
      ->check([](const std::string& s) { return check_hex_id(s); })
      ->capture_default_str();
  cmd->add_option("--serial", a->serial, "open the board with this USB serial number");
  cmd->add_option("--path", a->path, "open this HID device node (e.g. /dev/hidraw3)");
  cmd->add_flag("--yes", a->yes, "do not wait for Enter between steps (also when standard input is not a terminal)");
  cmd->add_flag("--force", a->force, "overwrite an existing calibration");
  cmd->callback([a, &exit_code] { exit_code = calibrate_ftm::run(*a); });
}

}  // namespace proprio::cli
