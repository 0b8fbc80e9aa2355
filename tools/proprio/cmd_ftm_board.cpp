// proprio ftm-board list|monitor|emulate: the FTM glove's USB HID read-out
// board (protocol in docs/ftm-hid-protocol.md), as `proprio stretch-board`
// does for the stretch glove's (what both share is in hid_monitor_common).
//   list     HID devices with the board's VID/PID (or all of them)
//   monitor  open a board, decode, print rates, loss, flagged samples and the
//            latest values of every sensor; rides through unplugging
//   emulate  a self-test: the board emulator with a simulated wearer behind
//            it, served over the in-memory HID link in real time and read by
//            the same host code as a real board; checks what the host decoded
//            against the board and the wearer
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "hid_monitor_common.hpp"
#include "proprio/core/random.hpp"
#include "proprio/ftm_board/ftm_device.hpp"
#include "proprio/ftm_board/ftm_emulator.hpp"
#include "proprio/ftm_board/ftm_protocol.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::cli {

namespace ftm_board_cmd {

using namespace proprio::devices;

unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }

constexpr HidBoardKind kFtmBoardKind{"FTM board", "ftm-board", kFtmUsbVendorId, kFtmUsbProductId, kFtmHidUsagePage};

// The newest sample of every sensor.
struct Latest {
  std::array<ftm::FtmImuSample, ftm::kFtmImuCount> imu{};
  std::array<ftm::FtmBendSample, ftm::kFtmBendCount> bend{};
  std::array<bool, ftm::kFtmImuCount + ftm::kFtmBendCount> seen{};
  void add(const ftm::FtmEvent& e) {
    if (e.kind == ftm::FtmEvent::Kind::imu && e.index < ftm::kFtmImuCount) {
      imu[e.index] = e.imu;
      seen[e.index] = true;
    } else if (e.kind == ftm::FtmEvent::Kind::bend && e.index < ftm::kFtmBendCount) {
      bend[e.index] = e.bend;
      seen[ftm::kFtmImuCount + e.index] = true;
    }
  }
};

void print_status_line(double elapsed, const FtmDeviceStats& st, const FtmDeviceStats& prev, double dt,
                       const Latest& latest) {
  const auto rate = [&](std::uint64_t cur, std::uint64_t old) { return static_cast<double>(cur - old) / dt; };
  std::printf("%7.1fs %-12s IMU %6.1f/s bend %7.1f/s  lost %llu+%llu  bad %llu  unusable %llu+%llu  restarts %llu  "
              "clock %s %+.1f ppm |",
              elapsed, hid::to_string(st.state), rate(st.stream.imu_samples, prev.stream.imu_samples),
              rate(st.stream.bend_samples, prev.stream.bend_samples),
              ull(st.stream.lost_imu_samples - prev.stream.lost_imu_samples),
              ull(st.stream.lost_bend_samples - prev.stream.lost_bend_samples),
              ull(st.stream.decode_errors - prev.stream.decode_errors),
              ull(st.stream.imu_unusable - prev.stream.imu_unusable),
              ull(st.stream.bend_unusable - prev.stream.bend_unusable), ull(st.stream.device_resets),
              st.clock_locked ? "locked" : "unlocked", st.clock_skew_ppm);
  for (std::size_t b = 0; b < ftm::kFtmBendCount; ++b) {
    if (latest.seen[ftm::kFtmImuCount + b]) std::printf(" %.1f", latest.bend[b].capacitance_pF);
    else std::printf(" -");
  }
  std::printf(" pF\n");
  std::fflush(stdout);
}

void print_totals(const FtmDeviceStats& st, double elapsed, const Latest& latest) {
  const FtmStreamStats& s = st.stream;
  std::printf("\n%.1f s: %llu connect(s), %llu disconnect(s), %llu failed open(s); %llu samples delivered, %llu "
              "dropped at a full queue, %llu time clamp(s); clock %+.2f ppm, %llu re-lock(s)\n",
              elapsed, ull(st.connects), ull(st.disconnects), ull(st.open_failures), ull(st.samples_delivered),
              ull(st.queue_overruns), ull(st.time_clamps), st.clock_skew_ppm, ull(st.clock_relocks));
  std::printf("reports: %llu read, %llu accepted (%llu IMU, %llu bend), %llu duplicate, %llu late, %llu undecodable",
              ull(st.reports_read), ull(s.accepted), ull(s.imu_reports), ull(s.bend_reports), ull(s.duplicates),
              ull(s.late), ull(s.decode_errors));
  if (s.other_reports) std::printf(", %llu other", ull(s.other_reports));
  std::printf("\nsamples: IMU %llu (%llu lost, %llu unusable, %llu fresh compass, %llu compass overflows), bend %llu "
              "(%llu lost, %llu unusable); %llu gap(s), %llu restart(s), %llu overrun report(s)\n",
              ull(s.imu_samples), ull(s.lost_imu_samples), ull(s.imu_unusable), ull(s.mag_fresh), ull(s.mag_overflows),
              ull(s.bend_samples), ull(s.lost_bend_samples), ull(s.bend_unusable), ull(s.gaps), ull(s.device_resets),
              ull(s.device_overruns));
  if (s.decode_errors) {
    std::printf("undecodable by reason:");
    for (std::size_t c = 1; c < kFtmDecodeErrcCount; ++c) {
      if (s.decode_errors_by_code[c]) {
        std::printf(" %s %llu", to_string(static_cast<FtmDecodeErrc>(c)), ull(s.decode_errors_by_code[c]));
      }
    }
    std::printf("\n");
  }
  if (st.have_info) {
    std::printf("firmware %u.%u.%u\n", st.info.firmware[0], st.info.firmware[1], st.info.firmware[2]);
  }
  std::printf("latest values:\n");
  for (std::size_t i = 0; i < ftm::kFtmImuCount; ++i) {
    const std::string name(ftm::to_string(static_cast<ftm::FtmImu>(i)));
    if (!latest.seen[i]) {
      std::printf("  %-17s -\n", name.c_str());
      continue;
    }
    const auto& m = latest.imu[i];
    std::printf("  %-17s accel [%6.2f %6.2f %6.2f] m/s^2  gyro [%7.1f %7.1f %7.1f] deg/s  compass [%6.1f %6.1f %6.1f] "
                "uT  status 0x%02x\n",
                name.c_str(), m.accel_mps2.x(), m.accel_mps2.y(), m.accel_mps2.z(), rad_to_deg(m.gyro_radps.x()),
                rad_to_deg(m.gyro_radps.y()), rad_to_deg(m.gyro_radps.z()), m.mag_uT.x(), m.mag_uT.y(), m.mag_uT.z(),
                m.status);
  }
  for (std::size_t b = 0; b < ftm::kFtmBendCount; ++b) {
    const std::string name(ftm::to_string(static_cast<ftm::FtmBend>(b)));
    if (latest.seen[ftm::kFtmImuCount + b]) {
      std::printf("  %-17s %.2f pF  status 0x%02x\n", name.c_str(), latest.bend[b].capacitance_pF,
                  latest.bend[b].status);
    } else {
      std::printf("  %-17s -\n", name.c_str());
    }
  }
}

// Runs a started device until `seconds` (0: Ctrl-C), a status line every interval; per_sample sees every sample.
template <typename PerSample>
double watch(FtmBoardDevice& device, double seconds, double interval_s, Latest& latest, PerSample&& per_sample) {
  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  const auto start = std::chrono::steady_clock::now();
  auto next_print = start + std::chrono::duration<double>(interval_s);
  FtmDeviceStats prev = device.stats();
  auto prev_time = start;
  FtmBoardSample sample;
  const auto drain = [&] {
    while (device.pop(sample)) {
      latest.add(sample.event);
      per_sample(sample);
    }
  };
  while (!g_sigint_stop.load()) {
    drain();
    const auto now = std::chrono::steady_clock::now();
    if (seconds > 0 && std::chrono::duration<double>(now - start).count() >= seconds) break;
    if (now >= next_print) {
      const FtmDeviceStats st = device.stats();
      print_status_line(std::chrono::duration<double>(now - start).count(), st, prev,
                        std::chrono::duration<double>(now - prev_time).count(), latest);
      prev = st;
      prev_time = now;
      next_print += std::chrono::duration<double>(interval_s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  device.stop();
  drain();
  std::signal(SIGINT, previous);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// ---------------------------------------------------------------------------
// monitor

int monitor_live(const HidMonitorArgs& a) {
  auto selected = monitor_selector(a, ftm_board_selector());
  if (!selected) return report_error(selected.error());
  const hid::HidDeviceSelector& sel = *selected;
  FtmBoardDevice device(std::make_unique<hid::HidapiTransport>(sel));
  device.set_state_callback(print_link_state);
  if (a.seconds > 0) {
    std::printf("monitoring %s for %g s (Ctrl-C stops early)\n", sel.describe().c_str(), a.seconds);
  } else {
    std::printf("monitoring %s (Ctrl-C to stop)\n", sel.describe().c_str());
  }
  if (auto s = device.start(); !s) return report_error(s.error());
  Latest latest;
  const double elapsed = watch(device, a.seconds, a.interval_s, latest, [](const FtmBoardSample&) {});
  const FtmDeviceStats st = device.stats();
  print_totals(st, elapsed, latest);
  if (st.stream.accepted == 0) {
    return report_error(Error{Errc::unavailable, "no samples received from " + sel.describe() +
                                                     "; 'proprio ftm-board list' shows what is plugged in"});
  }
  return 0;
}

// ---------------------------------------------------------------------------
// emulate

struct EmulateArgs {
  double seconds = 5.0;
  double interval_s = 1.0;
  int subject = 3;
  std::uint64_t seed = 1;
  BoardEmulatorFaultArgs link;
  double overrun = 0.0;
};

int run_emulate(const EmulateArgs& a) {
  ftm_sim::FtmWearerOptions wo;
  wo.seed = a.seed;
  wo.subject.subject_index = a.subject;
  wo.task_s = a.seconds + 60.0;  // the wearer outlasts the run (its calibration phases come first)
  if (auto s = wo.validate(); !s) return report_error(s.error());
  auto wearer = ftm_sim::FtmWearerSimulator::create(wo);
  if (!wearer) return report_error(wearer.error());
  // A twin of the wearer (same options, same samples) to check the host's values against.
  auto twin = ftm_sim::FtmWearerSimulator::create(wo);
  if (!twin) return report_error(twin.error());

  FtmEmulatorOptions eo;
  eo.seed = mix_seed(a.seed, 0xf7b0a2d);
  apply_board_emulator_faults(a.link, eo);
  eo.faults.device_overrun_probability = a.overrun;
  if (auto s = eo.validate(); !s) return report_error(s.error());
  auto emulator = FtmBoardEmulator::create(eo, std::move(*wearer));
  if (!emulator) return report_error(emulator.error());
  auto link = std::make_shared<hid::FakeHidLink>();
  FtmServeOptions so;
  so.seed = mix_seed(a.seed, 0x11a7);
  FtmBoardEmulatorServer server(std::move(*emulator), link, so);
  FtmDeviceOptions o;
  o.reconnect_backoff_max_ns = 200 * kNsPerMillisecond;
  FtmBoardDevice device(std::make_unique<hid::FakeHidTransport>(link), o);
  device.set_state_callback(print_link_state);
  std::printf("emulating an FTM board (4 IMUs at %u/s, 3 bend sensors at %u/s) worn by simulated subject %d for %g s "
              "over the in-memory HID link, seed %llu\n",
              eo.imu_rate_hz, eo.bend_rate_hz, a.subject, a.seconds, ull(a.seed));
  if (auto s = device.start(); !s) return report_error(s.error());
  server.start();
  const TimeNs t0 = server.time_zero_ns();
  for (const FtmOutage& u : eo.faults.unplugs) link->schedule_unplug(t0 + u.at_ns, u.duration_ns);

  // Bend values against the wearer's noise-free capacitance at the host's time
  // for the sample: the sensor's noise (0.05 pF), its 20 ms low-pass lag while
  // the finger moves and the quantisation stay well inside this.
  constexpr double kBendTolerancePf = 2.0;
  std::array<TimeNs, ftm::kFtmImuCount + ftm::kFtmBendCount> last_ns{};
  std::uint64_t out_of_order = 0, bend_checked = 0, bend_wrong = 0, imu_ok = 0, imu_implausible = 0;
  double worst_bend_pf = 0.0;
  Latest latest;
  const double elapsed = watch(device, a.seconds, a.interval_s, latest, [&](const FtmBoardSample& s) {
    const ftm::FtmEvent& e = s.event;
    const std::size_t k = e.kind == ftm::FtmEvent::Kind::imu ? e.index : ftm::kFtmImuCount + e.index;
    if (k >= last_ns.size()) return;
    if (e.time_ns() <= last_ns[k]) ++out_of_order;
    last_ns[k] = e.time_ns();
    if (e.kind == ftm::FtmEvent::Kind::bend && e.bend.status == 0) {
      const double truth = (*twin)->bend_capacitance_truth_pF(static_cast<ftm::FtmBend>(e.index), e.time_ns() - t0);
      const double err = std::fabs(e.bend.capacitance_pF - truth);
      worst_bend_pf = std::max(worst_bend_pf, err);
      ++bend_checked;
      if (!(err <= kBendTolerancePf)) ++bend_wrong;
    } else if (e.kind == ftm::FtmEvent::Kind::imu && (e.imu.status & ~ftm::sample_status::mag_overflow) == 0) {
      // A hand's IMU: gravity plus a reach's acceleration, well under the ±8 g range.
      const double g = e.imu.accel_mps2.norm();
      if (g > 2.0 && g < 40.0 && e.imu.accel_mps2.allFinite() && e.imu.gyro_radps.allFinite()) ++imu_ok;
      else ++imu_implausible;
    }
  });
  server.stop();
  const FtmDeviceStats st = device.stats();
  const FtmEmulatorStats board = server.emulator_stats();
  const hid::FakeHidLinkStats cable = link->stats();
  print_totals(st, elapsed, latest);
  std::printf("board: %llu IMU ticks, %llu bend ticks, %llu reports sent; faults: %llu dropped, %llu duplicated, %llu "
              "corrupted, %llu reordered, %llu discarded by the board (overrun), %llu boot(s)\n",
              ull(board.imu_ticks), ull(board.bend_ticks), ull(board.reports_sent), ull(board.dropped),
              ull(board.duplicated), ull(board.corrupted), ull(board.reordered), ull(board.device_overruns),
              ull(board.boots));

  bool pass = true;
  auto check = [&pass](bool ok, const std::string& what) {
    std::printf("  [%s] %s\n", ok ? "ok" : "FAIL", what.c_str());
    pass = pass && ok;
  };
  char line[256];
  std::printf("\nself-test:\n");
  check(imu_ok > 0 && bend_checked > 0, "IMU and bend samples arrived (" + std::to_string(imu_ok) + " IMU, " +
                                            std::to_string(bend_checked) + " bend usable)");
  check(imu_implausible == 0, "every usable IMU sample reads a plausible specific force (" +
                                  std::to_string(imu_implausible) + " did not)");
  std::snprintf(line, sizeof line,
                "bend values match the wearer's at their mapped time: worst |error| %.3f pF, tolerance %.1f pF "
                "(%llu beyond)",
                worst_bend_pf, kBendTolerancePf, ull(bend_wrong));
  check(bend_wrong == 0, line);
  check(out_of_order == 0, "sample times strictly increase per sensor (" + std::to_string(out_of_order) + " did not)");
  check(st.reports_read == cable.delivered, "every report the link delivered was read (" +
                                                std::to_string(st.reports_read) + " of " +
                                                std::to_string(cable.delivered) + ")");
  check(st.stream.decode_errors >= board.corrupted && st.stream.decode_errors <= board.corrupted * 2,
        "corrupted reports were caught by the CRC (" + std::to_string(st.stream.decode_errors) + " undecodable, " +
            std::to_string(board.corrupted) + " corrupted)");
  const std::uint64_t restarts = board.boots > 0 ? board.boots - 1 : 0;
  check(st.stream.device_resets == restarts, "board restarts recognised (" + std::to_string(st.stream.device_resets) +
                                                 " of " + std::to_string(restarts) + ")");
  std::printf("self-test %s\n", pass ? "PASSED" : "FAILED");
  return pass ? 0 : 1;
}

}  // namespace ftm_board_cmd

void add_ftm_board_command(CLI::App& app, int& exit_code) {
  using namespace ftm_board_cmd;
  CLI::App* board = add_command(app, "ftm-board");
  board->require_subcommand(1);

  add_hid_list_command(*board, kFtmBoardKind, "List HID devices with the FTM board's USB IDs (or all with --all).",
                       "List every HID device, not just FTM boards", exit_code);

  auto mon = std::make_shared<HidMonitorArgs>(ftm_board_cmd::kFtmBoardKind);
  CLI::App* mon_cmd = board->add_subcommand(
      "monitor",
      "Open a board, decode its reports and print, every --interval, the IMU and bend sample rates, lost samples, "
      "undecodable reports, flagged (unusable) samples, restarts, the clock alignment and the latest bend "
      "capacitances; at the end, totals and the latest values of every sensor. Keeps going through unplugging and "
      "replugging. Exit status 1 if no samples arrived.");
  add_hid_monitor_options(*mon_cmd, *mon, "Open the board with this USB serial number");
  mon_cmd->callback([mon, &exit_code] { exit_code = monitor_live(*mon); });

  auto emu = std::make_shared<ftm_board_cmd::EmulateArgs>();
  CLI::App* emu_cmd = board->add_subcommand(
      "emulate",
      "Self-test without hardware: the board emulator, worn by a simulated subject, is served over the in-memory HID "
      "link in real time; the host code that reads a real board decodes it, prints what it saw (as monitor does) and "
      "checks it: bend values against the wearer's, plausible IMU samples, times, loss and fault accounting, "
      "restarts. Exit status 0 when every check passes. The same seed gives the same board and wearer.");
  emu_cmd->add_option("--seconds", emu->seconds, "How long to run, s")
      ->check(CLI::Range(0.1, 24.0 * 3600.0))
      ->capture_default_str();
  emu_cmd->add_option("--interval", emu->interval_s, "Seconds between status lines")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
  emu_cmd->add_option("--subject", emu->subject, "Simulated wearer (0-14)")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  emu_cmd->add_option("--seed", emu->seed, "Seed of the wearer and the faults")->capture_default_str();
  add_board_emulator_fault_options(*emu_cmd, emu->link, "the board");
  emu_cmd->add_option("--overrun", emu->overrun, "Probability that the board discards a report itself")
      ->check(CLI::Range(0.0, 1.0));
  emu_cmd->callback([emu, &exit_code] { exit_code = run_emulate(*emu); });
}

}  // namespace proprio::cli
