// proprio glove list|monitor|emulate: the USB HID IMU glove (protocol in
// docs/glove-hid-protocol.md).
//   list     HID devices with the glove's VID/PID (or all of them)
//   monitor  open a glove (or a capture file), decode, print rates, loss and
//            per-IMU statistics; rides through unplugging and replugging
//   emulate  write the reports an emulated glove sends for a simulated hand
//            to a file that `monitor --from-file` reads
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "hid_monitor_common.hpp"
#include "proprio/core/file_io.hpp"
#include "progress.hpp"
#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/log.hpp"
#include "proprio/imu_glove_board/imu_glove_device.hpp"
#include "proprio/imu_glove_board/imu_glove_emulator.hpp"
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/imu_glove_board/imu_glove_stream.hpp"
#include "proprio/hid/capture_file.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/sim/hand_motion.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/subjects.hpp"

namespace proprio::cli {

namespace {

using namespace proprio::devices;


constexpr HidBoardKind kGloveKind{"glove", "glove", kImuGloveUsbVendorId, kImuGloveUsbProductId, kImuGloveHidUsagePage};

// ---------------------------------------------------------------------------
// monitor

struct MonitorArgs : HidMonitorArgs {
  MonitorArgs() : HidMonitorArgs(kGloveKind) {}
  double rate_hz = 100.0;
  std::string from_file;
};

struct LastValues {
  bool seen = false;
  Vec3 accel = Vec3::Zero();
  Vec3 gyro = Vec3::Zero();
};

double percent(std::uint64_t part, std::uint64_t whole) {
  return whole == 0 ? 0.0 : 100.0 * static_cast<double>(part) / static_cast<double>(whole);
}

// The per-IMU table and totals both monitor modes end with. span_s: the
// device time the samples cover (rates are per device second).
void print_summary(const ImuGloveStreamStats& s, double span_s, const std::array<LastValues, kImuGloveMaxImus>& last) {
  const std::uint64_t expected = s.accepted + s.late + s.lost;
  std::printf("\nreports: %llu read, %llu accepted, %llu lost (%.2f%%), %llu duplicate, %llu late, %llu undecodable",
              static_cast<unsigned long long>(s.reports), static_cast<unsigned long long>(s.accepted),
              static_cast<unsigned long long>(s.lost), percent(s.lost, expected),
              static_cast<unsigned long long>(s.duplicates), static_cast<unsigned long long>(s.late),
              static_cast<unsigned long long>(s.decode_errors));
  if (s.other_reports) std::printf(", %llu other", static_cast<unsigned long long>(s.other_reports));
  if (s.accepted == 0) {
    std::printf("\nno IMU data\n");
    return;
  }
  std::printf("\ndevice: %u IMUs, tick period %.1f us, %llu restart(s), %llu overrun tick(s), %llu sequence wrap(s), "
              "%llu timestamp wrap(s)\n",
              s.imu_total, s.tick_period_us, static_cast<unsigned long long>(s.device_resets),
              static_cast<unsigned long long>(s.device_overruns), static_cast<unsigned long long>(s.sequence_wraps),
              static_cast<unsigned long long>(s.timestamp_wraps));
  if (s.decode_errors) {
    std::printf("undecodable by reason:");
    for (std::size_t c = 1; c < kImuGloveDecodeErrcCount; ++c) {
      if (s.decode_errors_by_code[c]) {
        std::printf(" %s %llu", to_string(static_cast<ImuGloveDecodeErrc>(c)),
                    static_cast<unsigned long long>(s.decode_errors_by_code[c]));
      }
    }
    std::printf("\nlast: %s\n", describe(s.last_decode_error).c_str());
  }
  std::printf("\n%-4s %9s %8s %7s %8s %8s %7s  %-26s %s\n", "IMU", "good", "rate Hz", "stale", "acc sat", "gyr sat",
              "errors", "last accel m/s^2", "last gyro rad/s");
  for (std::size_t i = 0; i < kImuGloveMaxImus; ++i) {
    const ImuGloveImuStats& m = s.imus[i];
    if (m.good + m.rejected == 0) continue;
    char accel[64] = "-", gyro[64] = "-";
    if (last[i].seen) {
      std::snprintf(accel, sizeof accel, "%7.2f %7.2f %7.2f", last[i].accel.x(), last[i].accel.y(), last[i].accel.z());
      std::snprintf(gyro, sizeof gyro, "%6.2f %6.2f %6.2f", last[i].gyro.x(), last[i].gyro.y(), last[i].gyro.z());
    }
    std::printf("%-4zu %9llu %8.1f %7llu %8llu %8llu %7llu  %-26s %s\n", i, static_cast<unsigned long long>(m.good),
                span_s > 0 ? static_cast<double>(m.good + m.rejected) / span_s : 0.0,
                static_cast<unsigned long long>(m.stale), static_cast<unsigned long long>(m.accel_saturated),
                static_cast<unsigned long long>(m.gyro_saturated), static_cast<unsigned long long>(m.sensor_error),
                accel, gyro);
  }
}

// A capture file: report after report as hid_read returns them, read by
// hid::CaptureReader, which resynchronises after damage (capture_file.hpp).
int monitor_file(const MonitorArgs& a) {
  ImuGloveStreamOptions so;
  so.nominal_rate_hz = a.rate_hz;
  ImuGloveStreamDecoder decoder(so);
  std::array<ImuGloveSample, kImuGloveImusPerReport> out;
  std::array<LastValues, kImuGloveMaxImus> last{};
  // Device time covered, summed over epochs (a restart starts a new timeline).
  double span_s = 0.0;
  bool in_epoch = false;
  std::int64_t epoch_first_us = 0, epoch_last_us = 0;
  std::uint32_t epoch = 0;
  hid::CaptureReaderOptions ro;
  ro.max_bytes = kMaxCaptureBytes;
  const auto read = hid::read_capture_file(a.from_file, {&report_size_for_id}, ro, [&](const hid::CaptureFrame& f) {
    const auto r = decoder.push(f.bytes, out);
    if (r.verdict != ImuGloveReportVerdict::accepted) return;
    if (!in_epoch || r.epoch != epoch) {
      if (in_epoch) span_s += static_cast<double>(epoch_last_us - epoch_first_us) * 1e-6;
      in_epoch = true;
      epoch = r.epoch;
      epoch_first_us = epoch_last_us = r.device_time_us;
    }
    epoch_last_us = std::max(epoch_last_us, r.device_time_us);
    for (std::size_t i = 0; i < r.sample_count; ++i) {
      auto& l = last[out[i].imu.sensor_id];
      l = {true, out[i].imu.accel_mps2, out[i].imu.gyro_radps};
    }
  });
  if (!read) {
    return logger().error("{}; pass a file written by 'proprio glove emulate --out'", read.error().message), 1;
  }
  if (in_epoch) span_s += static_cast<double>(epoch_last_us - epoch_first_us) * 1e-6;
  const ImuGloveStreamStats& s = decoder.stats();
  // A tick's span is one period longer than first-to-last.
  if (s.accepted > 0) span_s += s.tick_period_us * 1e-6 * static_cast<double>(s.device_resets + 1);
  std::printf("%s: %zu bytes, %.2f s of device time", a.from_file.c_str(),
              static_cast<std::size_t>(read->bytes_consumed), span_s);
  if (read->skipped_bytes) {
    std::printf(", %llu bytes skipped to resynchronise", static_cast<unsigned long long>(read->skipped_bytes));
  }
  std::printf("\n");
  print_summary(s, span_s, last);
  return s.accepted > 0 ? 0 : 1;
}

int monitor_live(const MonitorArgs& a) {
  auto selected = monitor_selector(a);
  if (!selected) return report_error(selected.error());
  const hid::HidDeviceSelector& sel = *selected;
  ImuGloveDeviceOptions o;
  o.stream.nominal_rate_hz = a.rate_hz;
  ImuGloveDevice device(std::make_unique<hid::HidapiTransport>(sel), o);
  device.set_state_callback([](hid::LinkState state, std::string_view detail) {
    // On the reader thread; stdout is line-buffered per call.
    std::printf("[%s] %.*s\n", to_string(state), static_cast<int>(detail.size()), detail.data());
    std::fflush(stdout);
  });
  if (a.seconds > 0) {
    std::printf("monitoring %s for %g s (Ctrl-C stops early)\n", sel.describe().c_str(), a.seconds);
  } else {
    std::printf("monitoring %s (Ctrl-C to stop)\n", sel.describe().c_str());
  }
  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  if (auto s = device.start(); !s) {
    std::signal(SIGINT, previous);
    return logger().error("{}", s.error().message), 1;
  }
  const auto start = std::chrono::steady_clock::now();
  auto next_print = start + std::chrono::duration<double>(a.interval_s);
  std::array<LastValues, kImuGloveMaxImus> last{};
  ImuGloveDeviceStats prev = device.stats();
  auto prev_time = start;
  ImuGloveSample sample;
  while (!g_sigint_stop.load()) {
    while (device.pop(sample)) last[sample.imu.sensor_id % kImuGloveMaxImus] = {true, sample.imu.accel_mps2, sample.imu.gyro_radps};
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = std::chrono::duration<double>(now - start).count();
    if (a.seconds > 0 && elapsed >= a.seconds) break;
    if (now >= next_print) {
      const ImuGloveDeviceStats st = device.stats();
      const double dt = std::chrono::duration<double>(now - prev_time).count();
      const auto d = [&](std::uint64_t cur, std::uint64_t old) { return static_cast<double>(cur - old); };
      const double lat_n = d(st.excess_latency_count, prev.excess_latency_count);
      const double lat_avg_ms =
          lat_n > 0 ? (st.excess_latency_sum_ns - prev.excess_latency_sum_ns) / lat_n * 1e-6 : 0.0;
      std::printf("%7.1fs %-12s %6.1f reports/s %7.1f samples/s  lost %llu  dup %llu  late %llu  bad %llu  "
                  "rejected %llu  restarts %llu  clock %s %+.1f ppm  latency above floor %.2f ms\n",
                  elapsed, to_string(st.state), d(st.reports_read, prev.reports_read) / dt,
                  d(st.samples_delivered, prev.samples_delivered) / dt,
                  static_cast<unsigned long long>(st.stream.lost - prev.stream.lost),
                  static_cast<unsigned long long>(st.stream.duplicates - prev.stream.duplicates),
                  static_cast<unsigned long long>(st.stream.late - prev.stream.late),
                  static_cast<unsigned long long>(st.stream.decode_errors - prev.stream.decode_errors),
                  static_cast<unsigned long long>(st.samples_rejected - prev.samples_rejected),
                  static_cast<unsigned long long>(st.stream.device_resets), st.clock_locked ? "locked" : "unlocked",
                  st.clock_skew_ppm, lat_avg_ms);
      std::fflush(stdout);
      prev = st;
      prev_time = now;
      next_print += std::chrono::duration<double>(a.interval_s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  device.stop();
  std::signal(SIGINT, previous);
  const ImuGloveDeviceStats st = device.stats();
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("\n%.1f s: %llu connect(s), %llu disconnect(s), %llu failed open(s); %llu samples delivered, %llu "
              "rejected, %llu dropped at a full queue; clock %+.2f ppm, %llu re-lock(s), time clamps %llu, "
              "latency above floor: mean %.2f ms, max %.2f ms",
              elapsed, static_cast<unsigned long long>(st.connects), static_cast<unsigned long long>(st.disconnects),
              static_cast<unsigned long long>(st.open_failures), static_cast<unsigned long long>(st.samples_delivered),
              static_cast<unsigned long long>(st.samples_rejected), static_cast<unsigned long long>(st.queue_overruns),
              st.clock_skew_ppm, static_cast<unsigned long long>(st.clock_relocks),
              static_cast<unsigned long long>(st.time_clamps),
              st.excess_latency_count ? st.excess_latency_sum_ns / static_cast<double>(st.excess_latency_count) * 1e-6 : 0.0,
              static_cast<double>(st.excess_latency_max_ns) * 1e-6);
  if (st.have_info) {
    std::printf("\nfirmware %u.%u.%u, %u IMUs at %u Hz, %s, %s", st.info.firmware[0], st.info.firmware[1],
                st.info.firmware[2], st.info.imu_count, st.info.rate_hz, to_string(st.info.accel_range),
                to_string(st.info.gyro_range));
  }
  print_summary(st.stream, elapsed, last);
  if (st.stream.accepted == 0) {
    logger().error("no IMU data received from {}", sel.describe());
    return 1;
  }
  return 0;
}

// ---------------------------------------------------------------------------
// emulate

struct EmulateArgs {
  std::string out;
  double seconds = 10.0;
  std::uint64_t seed = 1;
  int subject = 3;
  std::string protocol = "free-motion";
  std::string hand = "right";
  int rate_hz = 100;
  BoardEmulatorFaultArgs link;
  double stale = 0.0;
  bool force = false;
};

int run_emulate(const EmulateArgs& a) {
  if (!a.force && std::filesystem::exists(a.out)) {
    return logger().error("{} exists; pass --force to overwrite it", a.out), 1;
  }
  auto subject = sim::sim_subject(a.subject);
  if (!subject) return logger().error("{}", subject.error().message), 1;
  auto shape = subject->shape();
  if (!shape) return logger().error("{}", shape.error().message), 1;
  sim::HandMotionOptions mo;
  mo.protocol = *sim::parse_motion_protocol(a.protocol);  // CLI11 checked the name
  mo.hand = *parse_handedness(a.hand);
  mo.seed = mix_seed(a.seed, 1);
  sim::HandMotionGenerator motion(HandModel(*shape), mo);
  sim::ImuNoiseOptions no;
  no.sample_rate_hz = a.rate_hz;
  auto imu = sim::ImuSimulator::create(motion, ImuGloveDescription::vist_default().place_imus(*shape, mo.hand), no,
                                       mix_seed(a.seed, 2));
  if (!imu) return logger().error("{}", imu.error().message), 1;

  ImuGloveEmulatorOptions eo;
  eo.imu_count = static_cast<std::uint8_t>(imu->imu_count());
  eo.rate_hz = static_cast<std::uint16_t>(a.rate_hz);
  eo.seed = mix_seed(a.seed, 3);
  apply_board_emulator_faults(a.link, eo);
  eo.faults.stale_probability = a.stale;
  auto emulator = ImuGloveEmulator::create(eo);
  if (!emulator) return logger().error("{}", emulator.error().message), 1;

  if (auto s = check_output_path(a.out, "capture file"); !s) return report_error(s.error());
  std::ofstream file(a.out, std::ios::binary | std::ios::trunc);
  if (!file) return logger().error("cannot write {}: {}", a.out, std::strerror(errno)), 1;
  logger().info("{}", subject->describe());
  logger().info("IMUs: {}", imu->describe());
  const auto ticks = static_cast<std::int64_t>(a.seconds * a.rate_hz);
  ProgressBar progress("glove emulate", a.seconds, "s emulated");
  std::vector<ImuGloveEmulatedReport> reports;
  std::vector<ImuSample> samples;
  std::uint64_t bytes = 0;
  auto write = [&] {
    for (const auto& r : reports) file.write(reinterpret_cast<const char*>(r.bytes.data()), r.bytes.size());
    bytes += reports.size() * kImuGloveDataReportSize;
    reports.clear();
  };
  for (std::int64_t k = 0; k < ticks; ++k) {
    const TimeNs t = imu->next_nominal_time_ns();
    samples.clear();
    for (const sim::ImuReading& r : imu->next()) samples.push_back(r.sample);
    if (auto s = emulator->tick(t, samples, reports); !s) return logger().error("{}", s.error().message), 1;
    write();
    progress.update(ns_to_seconds(t));
  }
  emulator->flush(reports);
  write();
  progress.finish();
  file.close();
  if (!file) return logger().error("writing {} failed", a.out), 1;
  const ImuGloveEmulatorStats& st = emulator->stats();
  std::printf("wrote %s: %llu reports (%llu bytes), %lld ticks of %zu IMUs at %d Hz (%.1f s), seed %llu\n",
              a.out.c_str(), static_cast<unsigned long long>(st.reports_sent), static_cast<unsigned long long>(bytes),
              static_cast<long long>(ticks), imu->imu_count(), a.rate_hz, a.seconds,
              static_cast<unsigned long long>(a.seed));
  std::printf("faults: %llu dropped, %llu duplicated, %llu corrupted, %llu reordered, %llu stale samples, %llu "
              "unpowered ticks, %llu boot(s); %llu saturated samples\n",
              static_cast<unsigned long long>(st.dropped), static_cast<unsigned long long>(st.duplicated),
              static_cast<unsigned long long>(st.corrupted), static_cast<unsigned long long>(st.reordered),
              static_cast<unsigned long long>(st.stale_samples), static_cast<unsigned long long>(st.ticks_unpowered),
              static_cast<unsigned long long>(st.boots), static_cast<unsigned long long>(st.saturated_samples));
  return 0;
}

}  // namespace

void add_glove_command(CLI::App& app, int& exit_code) {
  CLI::App* glove = add_command(app, "glove");
  glove->require_subcommand(1);

  add_hid_list_command(*glove, kGloveKind, "List HID devices with the glove's USB IDs (or all with --all).",
                       "List every HID device, not just gloves", exit_code);

  auto mon = std::make_shared<MonitorArgs>();
  CLI::App* mon_cmd = glove->add_subcommand(
      "monitor",
      "Open a glove, decode its reports and print, every --interval, the report and sample rates, lost, duplicate, "
      "late and undecodable reports, rejected samples, restarts and the clock alignment; at the end, per-IMU "
      "statistics. Keeps going through unplugging and replugging. With --from-file, decodes a capture written by "
      "'glove emulate' instead (rates are then per second of device time). Exit status 1 if no IMU data arrived.");
  add_hid_monitor_options(*mon_cmd, *mon, "Open the glove with this USB serial number (e.g. left vs right)");
  mon_cmd->add_option("--rate", mon->rate_hz, "Tick rate to assume until the glove's own is measured, Hz")
      ->check(CLI::Range(1.0, static_cast<double>(kImuGloveMaxRateHz)))
      ->capture_default_str();
  mon_cmd->add_option("--from-file", mon->from_file, "Decode this capture file instead of a live glove")
      ->check(CLI::ExistingFile);
  mon_cmd->callback([mon, &exit_code] { exit_code = mon->from_file.empty() ? monitor_live(*mon) : monitor_file(*mon); });

  auto emu = std::make_shared<EmulateArgs>();
  CLI::App* emu_cmd = glove->add_subcommand(
      "emulate",
      "Simulate a hand wearing the glove (IMU simulator with datasheet noise) and write the exact HID input reports "
      "the glove would send, back to back, to --out; 'proprio glove monitor --from-file' decodes it. Faults can be "
      "injected; the same seed gives the same bytes.");
  emu_cmd->add_option("--out", emu->out, "File to write (raw 64-byte reports)")->required();
  emu_cmd->add_option("--seconds", emu->seconds, "Duration to emulate, s")
      ->check(CLI::Range(0.0, 24.0 * 3600.0))
      ->capture_default_str();
  emu_cmd->add_option("--seed", emu->seed, "Random seed for the motion, the IMU noise and the faults")
      ->capture_default_str();
  emu_cmd->add_option("--subject", emu->subject, "Simulated subject 0-14")
      ->check(CLI::Range(0, sim::kSimSubjectCount - 1))
      ->capture_default_str();
  emu_cmd->add_option("--protocol", emu->protocol, "Hand motion (see proprio sim-hand --help)")
      ->check(CLI::IsMember(sim::motion_protocol_names()))
      ->capture_default_str();
  emu_cmd->add_option("--hand", emu->hand, "Which hand")->check(CLI::IsMember({"left", "right"}))->capture_default_str();
  emu_cmd->add_option("--rate", emu->rate_hz, "IMU sample rate, Hz")
      ->check(CLI::Range(1, static_cast<int>(kImuGloveMaxRateHz)))
      ->capture_default_str();
  add_board_emulator_fault_options(*emu_cmd, emu->link, "the glove");
  emu_cmd->add_option("--stale", emu->stale, "Probability, per IMU and tick, that a sample repeats the last (stale)")
      ->check(CLI::Range(0.0, 1.0));
  emu_cmd->add_flag("--force", emu->force, "Overwrite an existing file");
  emu_cmd->callback([emu, &exit_code] { exit_code = run_emulate(*emu); });
}

}  // namespace proprio::cli
