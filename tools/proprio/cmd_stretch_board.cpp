// proprio stretch-board list|monitor|emulate: the stretch glove's USB HID
// read-out board (protocol in docs/stretch-glove-hid-protocol.md).
//   list     HID devices with the board's VID/PID (or all of them)
//   monitor  open a board (or a capture file), decode, print rates, loss,
//            flagged readings and the latest capacitance of every combination;
//            rides through unplugging and replugging
//   emulate  a self-test: an emulated board with slowly varying synthetic
//            capacitances, served over the in-memory HID link in real time and
//            read by the same host code as a real board; reports what the host
//            decoded and checks it against what the board measured. With
//            --out, writes the board's reports to a capture file instead.
//            With --layout, the board serves a stretch sensor array's plan
//            (pairs and single strips, protocol 1.1) over known, slowly
//            varying cells, and the self-test also solves them back
//            (StretchArrayReader).
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "hid_monitor_common.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/log.hpp"
#include "proprio/hid/capture_file.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_board/stretch_array_reader.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"

namespace proprio::cli {

namespace {

using namespace proprio::devices;

unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }
double percent(std::uint64_t part, std::uint64_t whole) {
  return whole == 0 ? 0.0 : 100.0 * static_cast<double>(part) / static_cast<double>(whole);
}

constexpr HidBoardKind kStretchBoardKind{"stretch board", "stretch-board", kStretchUsbVendorId, kStretchUsbProductId,
                                         kStretchHidUsagePage};

// ---------------------------------------------------------------------------
// What the host saw, for all three ways of looking at a stream.

// The newest reading of every combination, for the final grid.
struct LatestValues {
  std::array<double, kStretchMaxCombinations> pf{};
  std::array<StretchMeasurementStatus, kStretchMaxCombinations> status{};
  std::array<bool, kStretchMaxCombinations> seen{};
  void add(const StretchSample& s) {
    const std::size_t c = s.combination % kStretchMaxCombinations;
    pf[c] = s.capacitance_pf;
    status[c] = s.status;
    seen[c] = true;
  }
  std::size_t count() const { return static_cast<std::size_t>(std::count(seen.begin(), seen.end(), true)); }
};

// Rows are top strips, columns bottom strips: the combination t * bottom + b.
void print_grid(const LatestValues& latest, int top, int bottom) {
  if (top <= 0 || bottom <= 0) return;
  std::printf("\nlatest capacitance per combination, pF (row = top strip, column = bottom strip; S saturated, "
              "Z below zero, N no signal, - not seen)\n     ");
  for (int b = 0; b < bottom; ++b) std::printf(" %6d", b);
  std::printf("\n");
  for (int t = 0; t < top; ++t) {
    std::printf("%4d ", t);
    for (int b = 0; b < bottom; ++b) {
      const std::size_t c = static_cast<std::size_t>(t * bottom + b);
      if (c >= kStretchMaxCombinations || !latest.seen[c]) {
        std::printf(" %6s", "-");
        continue;
      }
      switch (latest.status[c]) {
        case StretchMeasurementStatus::ok: std::printf(" %6.1f", latest.pf[c]); break;
        case StretchMeasurementStatus::saturated: std::printf(" %6s", "S"); break;
        case StretchMeasurementStatus::below_zero: std::printf(" %6s", "Z"); break;
        case StretchMeasurementStatus::no_signal: std::printf(" %6s", "N"); break;
      }
    }
    std::printf("\n");
  }
  // Protocol 1.1's single-strip rows follow the pairs: top strips, then bottom strips.
  const std::size_t pairs = static_cast<std::size_t>(top * bottom);
  const std::size_t rows = stretch_row_count(static_cast<std::size_t>(top), static_cast<std::size_t>(bottom), true);
  if (rows > kStretchMaxCombinations ||
      std::none_of(latest.seen.begin() + static_cast<std::ptrdiff_t>(pairs),
                   latest.seen.begin() + static_cast<std::ptrdiff_t>(rows), [](bool b) { return b; })) {
    return;
  }
  for (const bool top_layer : {true, false}) {
    std::printf("%s strips alone, pF:", top_layer ? "top   " : "bottom");
    const std::size_t first = top_layer ? pairs : pairs + static_cast<std::size_t>(top);
    const std::size_t n = static_cast<std::size_t>(top_layer ? top : bottom);
    for (std::size_t c = first; c < first + n; ++c) {
      if (!latest.seen[c]) {
        std::printf(" %6s", "-");
      } else if (latest.status[c] == StretchMeasurementStatus::ok) {
        std::printf(" %6.1f", latest.pf[c]);
      } else {
        std::printf(" %6s", to_string(latest.status[c]));
      }
    }
    std::printf("\n");
  }
}

// The totals every mode ends with. span_s: the device time the measurements
// cover (rates are per device second).
void print_summary(const StretchStreamStats& s, double span_s) {
  const std::uint64_t expected = s.measurements + s.lost;
  std::printf("\nreports: %llu read, %llu accepted, %llu duplicate, %llu late, %llu undecodable",
              ull(s.reports), ull(s.accepted), ull(s.duplicates), ull(s.late), ull(s.decode_errors));
  if (s.other_reports) std::printf(", %llu other", ull(s.other_reports));
  if (s.wrong_layout) std::printf(", %llu refused (wrong strip counts)", ull(s.wrong_layout));
  if (s.accepted == 0) {
    std::printf("\nno measurements\n");
    return;
  }
  std::printf("\nmeasurements: %llu received (%.1f/s), %llu lost (%.2f%%) in %llu gap(s); flagged: %llu saturated, "
              "%llu below zero, %llu no signal\n",
              ull(s.measurements), span_s > 0 ? static_cast<double>(s.measurements) / span_s : 0.0, ull(s.lost),
              percent(s.lost, expected), ull(s.gaps), ull(s.by_status[1]), ull(s.by_status[2]),
              ull(s.by_status[3]));
  std::printf("board: %u x %u strips%s (%zu combinations), measurement period %.2f us (%.1f/s), %llu restart(s), "
              "%llu overrun report(s), %llu sequence wrap(s), %llu timestamp wrap(s)\n",
              s.top_strips, s.bottom_strips, s.single_strips ? " and single strips" : "",
              stretch_row_count(s.top_strips, s.bottom_strips, s.single_strips), s.measurement_period_us,
              1e6 / s.measurement_period_us, ull(s.device_resets), ull(s.device_overruns), ull(s.sequence_wraps),
              ull(s.timestamp_wraps));
  if (s.decode_errors) {
    std::printf("undecodable by reason:");
    for (std::size_t c = 1; c < kStretchDecodeErrcCount; ++c) {
      if (s.decode_errors_by_code[c]) {
        std::printf(" %s %llu", to_string(static_cast<StretchDecodeErrc>(c)), ull(s.decode_errors_by_code[c]));
      }
    }
    std::printf("\nlast: %s\n", describe(s.last_decode_error).c_str());
  }
  if (s.measurements_flagged()) {
    // The few combinations that account for most flagged readings point at a broken lead or a shorted cell.
    std::vector<std::size_t> worst;
    for (std::size_t c = 0; c < kStretchMaxCombinations; ++c) {
      if (s.flagged_by_combination[c]) worst.push_back(c);
    }
    std::sort(worst.begin(), worst.end(), [&](std::size_t a, std::size_t b) {
      return s.flagged_by_combination[a] > s.flagged_by_combination[b];
    });
    std::printf("most flagged combinations (top strip, bottom strip: count):");
    for (std::size_t i = 0; i < worst.size() && i < 8; ++i) {
      const std::size_t c = worst[i];
      std::printf(" (%zu, %zu: %u)", c / std::max<std::size_t>(s.bottom_strips, 1),
                  c % std::max<std::size_t>(s.bottom_strips, 1), s.flagged_by_combination[c]);
    }
    std::printf("\n");
  }
}

// ---------------------------------------------------------------------------
// monitor

struct MonitorArgs : HidMonitorArgs {
  MonitorArgs() : HidMonitorArgs(kStretchBoardKind) {}
  double rate_hz = kStretchDefaultRateHz;
  int top_strips = 0;
  int bottom_strips = 0;
  std::string from_file;
};

StretchStreamOptions stream_options(const MonitorArgs& a) {
  StretchStreamOptions so;
  so.nominal_rate_hz = a.rate_hz;
  so.expected_top_strips = static_cast<std::uint8_t>(a.top_strips);
  so.expected_bottom_strips = static_cast<std::uint8_t>(a.bottom_strips);
  return so;
}

// A capture file: report after report as hid_read returns them, read by
// hid::CaptureReader, which resynchronises after damage (capture_file.hpp).
int monitor_file(const MonitorArgs& a) {
  StretchStreamDecoder decoder(stream_options(a));
  std::array<StretchSample, kStretchMeasurementsPerReport> out;
  LatestValues latest;
  // Device time covered, summed over epochs (a restart starts a new timeline).
  double span_s = 0.0;
  bool in_epoch = false;
  std::int64_t epoch_first_us = 0, epoch_last_us = 0;
  std::uint32_t epoch = 0;
  hid::CaptureReaderOptions ro;
  ro.max_bytes = kMaxCaptureBytes;
  const auto read =
      hid::read_capture_file(a.from_file, {&stretch_report_size_for_id}, ro, [&](const hid::CaptureFrame& f) {
        const auto r = decoder.push(f.bytes, out);
        if (r.verdict != StretchReportVerdict::accepted) return;
        if (!in_epoch || r.epoch != epoch) {
          if (in_epoch) span_s += static_cast<double>(epoch_last_us - epoch_first_us) * 1e-6;
          in_epoch = true;
          epoch = r.epoch;
          epoch_first_us = r.device_time_us;
          epoch_last_us = r.last_device_time_us;
        }
        epoch_last_us = std::max(epoch_last_us, r.last_device_time_us);
        for (std::size_t i = 0; i < r.sample_count; ++i) latest.add(out[i]);
      });
  if (!read) {
    return logger().error("{}; pass a file written by 'proprio stretch-board emulate --out' or captured with "
                          "'cat /dev/hidrawN'",
                          read.error().message),
           1;
  }
  if (in_epoch) span_s += static_cast<double>(epoch_last_us - epoch_first_us) * 1e-6;
  const StretchStreamStats& s = decoder.stats();
  // A measurement's span is one period longer than first-to-last.
  if (s.accepted > 0) span_s += s.measurement_period_us * 1e-6 * static_cast<double>(s.device_resets + 1);
  std::printf("%s: %zu bytes, %.2f s of device time", a.from_file.c_str(),
              static_cast<std::size_t>(read->bytes_consumed), span_s);
  if (read->skipped_bytes) std::printf(", %llu bytes skipped to resynchronise", ull(read->skipped_bytes));
  std::printf("\n");
  print_summary(s, span_s);
  print_grid(latest, s.top_strips, s.bottom_strips);
  return s.accepted > 0 ? 0 : 1;
}

// Per interval: what changed since the last line.
void print_status_line(double elapsed, const StretchDeviceStats& st, const StretchDeviceStats& prev, double dt,
                       const LatestValues& latest) {
  const auto d = [&](std::uint64_t cur, std::uint64_t old) { return static_cast<double>(cur - old); };
  const double lat_n = d(st.excess_latency_count, prev.excess_latency_count);
  const double lat_avg_ms = lat_n > 0 ? (st.excess_latency_sum_ns - prev.excess_latency_sum_ns) / lat_n * 1e-6 : 0.0;
  double lo = 0.0, hi = 0.0;
  bool any = false;
  for (std::size_t c = 0; c < kStretchMaxCombinations; ++c) {
    if (!latest.seen[c] || latest.status[c] != StretchMeasurementStatus::ok) continue;
    lo = any ? std::min(lo, latest.pf[c]) : latest.pf[c];
    hi = any ? std::max(hi, latest.pf[c]) : latest.pf[c];
    any = true;
  }
  std::printf("%7.1fs %-12s %5.1f reports/s %7.1f meas/s  lost %llu  dup %llu  late %llu  bad %llu  flagged %llu  "
              "restarts %llu  clock %s %+.1f ppm  latency above floor %.2f ms  latest %.1f-%.1f pF over %zu "
              "combinations\n",
              elapsed, to_string(st.state), d(st.reports_read, prev.reports_read) / dt,
              d(st.stream.measurements, prev.stream.measurements) / dt, ull(st.stream.lost - prev.stream.lost),
              ull(st.stream.duplicates - prev.stream.duplicates), ull(st.stream.late - prev.stream.late),
              ull(st.stream.decode_errors - prev.stream.decode_errors),
              ull(st.stream.measurements_flagged() - prev.stream.measurements_flagged()),
              ull(st.stream.device_resets), st.clock_locked ? "locked" : "unlocked", st.clock_skew_ppm, lat_avg_ms, lo,
              hi, latest.count());
  std::fflush(stdout);
}

void print_device_totals(const StretchDeviceStats& st, double elapsed) {
  std::printf("\n%.1f s: %llu connect(s), %llu disconnect(s), %llu failed open(s); %llu measurements delivered, "
              "%llu rejected (flagged), %llu dropped at a full queue; clock %+.2f ppm, %llu re-lock(s), time clamps "
              "%llu, latency above floor: mean %.2f ms, max %.2f ms",
              elapsed, ull(st.connects), ull(st.disconnects), ull(st.open_failures), ull(st.samples_delivered),
              ull(st.samples_rejected), ull(st.queue_overruns), st.clock_skew_ppm, ull(st.clock_relocks),
              ull(st.time_clamps),
              st.excess_latency_count ? st.excess_latency_sum_ns / static_cast<double>(st.excess_latency_count) * 1e-6
                                      : 0.0,
              static_cast<double>(st.excess_latency_max_ns) * 1e-6);
  if (st.have_info) {
    std::printf("\nfirmware %u.%u.%u, %u x %u strips%s at %u measurements/s, full scale %.3f pF, parasitic %.3f pF "
                "subtracted",
                st.info.firmware[0], st.info.firmware[1], st.info.firmware[2], st.info.top_strips,
                st.info.bottom_strips, st.info.single_strips ? " and single strips" : "", st.info.rate_hz, stretch_count_to_pf(st.info.full_scale_ff),
                stretch_count_to_pf(st.info.parasitic_ff));
  }
}

// Runs a started device until `seconds` (0: Ctrl-C), printing a line every
// interval; per_sample sees every measurement on this thread.
template <typename PerSample>
double watch(StretchDevice& device, double seconds, double interval_s, LatestValues& latest, PerSample&& per_sample) {
  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  const auto start = std::chrono::steady_clock::now();
  auto next_print = start + std::chrono::duration<double>(interval_s);
  StretchDeviceStats prev = device.stats();
  auto prev_time = start;
  StretchSample sample;
  while (!g_sigint_stop.load()) {
    while (device.pop(sample)) {
      latest.add(sample);
      per_sample(sample);
    }
    const auto now = std::chrono::steady_clock::now();
    if (seconds > 0 && std::chrono::duration<double>(now - start).count() >= seconds) break;
    if (now >= next_print) {
      const StretchDeviceStats st = device.stats();
      print_status_line(std::chrono::duration<double>(now - start).count(), st, prev,
                        std::chrono::duration<double>(now - prev_time).count(), latest);
      prev = st;
      prev_time = now;
      next_print += std::chrono::duration<double>(interval_s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  device.stop();
  while (device.pop(sample)) {
    latest.add(sample);
    per_sample(sample);
  }
  std::signal(SIGINT, previous);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}


int monitor_live(const MonitorArgs& a) {
  auto selected = monitor_selector(a, stretch_board_selector());
  if (!selected) return report_error(selected.error());
  const hid::HidDeviceSelector& sel = *selected;
  StretchDeviceOptions o;
  o.stream = stream_options(a);
  StretchDevice device(std::make_unique<hid::HidapiTransport>(sel), o);
  device.set_state_callback(print_link_state);
  if (a.seconds > 0) {
    std::printf("monitoring %s for %g s (Ctrl-C stops early)\n", sel.describe().c_str(), a.seconds);
  } else {
    std::printf("monitoring %s (Ctrl-C to stop)\n", sel.describe().c_str());
  }
  if (auto s = device.start(); !s) return logger().error("{}", s.error().message), 1;
  LatestValues latest;
  const double elapsed = watch(device, a.seconds, a.interval_s, latest, [](const StretchSample&) {});
  const StretchDeviceStats st = device.stats();
  print_device_totals(st, elapsed);
  print_summary(st.stream, elapsed);
  print_grid(latest, st.stream.top_strips, st.stream.bottom_strips);
  if (st.stream.accepted == 0) {
    logger().error("no measurements received from {}", sel.describe());
    return 1;
  }
  return 0;
}

// ---------------------------------------------------------------------------
// emulate

struct EmulateArgs {
  std::string out;
  bool force = false;
  double seconds = 5.0;
  double interval_s = 1.0;
  std::uint64_t seed = 1;
  int top_strips = 13;
  int bottom_strips = 14;
  int rate_hz = kStretchDefaultRateHz;
  bool single_strips = false;
  std::string layout;  // a stretch array's layout file: serve its plan over known cells
  BoardEmulatorFaultArgs link;
  double saturate = 0.0, overrun = 0.0;
};

// Slowly varying synthetic capacitances: each combination its own level (a
// measurement sums a few cells of ~20 pF), drifting by ±5 pF at 0.1-0.4 Hz
// with its own phase, as a hand moving slowly would.
struct SyntheticProvider {
  std::size_t bottom = 14;
  double operator()(std::size_t combination, TimeNs t_ns) const {
    const double t = ns_to_seconds(t_ns);
    const double top_strip = static_cast<double>(combination / bottom);
    const double bottom_strip = static_cast<double>(combination % bottom);
    const double level = 40.0 + 3.0 * std::fmod(top_strip, 5.0) + 2.0 * std::fmod(bottom_strip, 4.0);
    const double hz = 0.1 + 0.1 * std::fmod(static_cast<double>(combination), 4.0);
    return level + 5.0 * std::sin(2.0 * M_PI * hz * t + 0.37 * static_cast<double>(combination));
  }
  static constexpr double max_slope_pf_per_s = 5.0 * 2.0 * M_PI * 0.4;
};

// What the emulated board measures: a provider, how fast its values can
// change (for the value-at-time check), and with --layout the array and its
// true cells (for the solve check).
struct EmulatedSignal {
  StretchCapacitanceProvider provider;
  double max_slope_pf_per_s = 0.0;
  std::shared_ptr<stretch_array::StripArrayLayout> layout;
  std::function<void(TimeNs, std::span<double>)> cells;
  std::vector<double> rest_pf;
};

// An array's cells: each at its rest capacitance times 1.1-1.5, breathing by
// +-2 % at 0.05-0.2 Hz with its own phase (a sleeve on a slowly moving arm).
constexpr double kCellDepth = 0.02;
constexpr double kCellMaxHz = 0.2;
Result<EmulatedSignal> signal_for(const EmulateArgs& a) {
  EmulatedSignal sig;
  if (a.layout.empty()) {
    const SyntheticProvider p{static_cast<std::size_t>(a.bottom_strips)};
    sig.provider = p;
    sig.max_slope_pf_per_s = SyntheticProvider::max_slope_pf_per_s;
    return sig;
  }
  auto layout = stretch_array::StripArrayLayout::load(a.layout);
  if (!layout) return layout.error();
  if (auto plan = stretch_array_plan(*layout); !plan) return plan.error();
  sig.layout = std::make_shared<stretch_array::StripArrayLayout>(std::move(*layout));
  sig.rest_pf = array_rest_capacitances_pf(*sig.layout);
  const std::vector<double> rest = sig.rest_pf;
  sig.cells = [rest](TimeNs t_ns, std::span<double> out) {
    const double t = ns_to_seconds(t_ns);
    for (std::size_t c = 0; c < rest.size(); ++c) {
      const double k = static_cast<double>(c);
      const double hz = 0.05 + 0.05 * std::fmod(k, 4.0);
      out[c] = rest[c] * (1.3 + 0.2 * std::sin(1.7 * k) + kCellDepth * std::sin(2.0 * M_PI * hz * t + 0.37 * k));
    }
  };
  // A row sums its cells: its slope is at most the sum of theirs.
  const Eigen::MatrixXd M = sig.layout->measurement_matrix(true);
  Eigen::VectorXd slope(static_cast<Eigen::Index>(rest.size()));
  for (std::size_t c = 0; c < rest.size(); ++c)
    slope(static_cast<Eigen::Index>(c)) = rest[c] * kCellDepth * 2.0 * M_PI * kCellMaxHz;
  sig.max_slope_pf_per_s = (M * slope).maxCoeff();
  sig.provider = stretch_array_provider(*sig.layout, sig.cells);
  return sig;
}

StretchEmulatorOptions emulator_options(const EmulateArgs& a) {
  StretchEmulatorOptions eo;
  eo.top_strips = static_cast<std::uint8_t>(a.top_strips);
  eo.bottom_strips = static_cast<std::uint8_t>(a.bottom_strips);
  eo.single_strips = a.single_strips;
  eo.rate_hz = static_cast<std::uint16_t>(a.rate_hz);
  eo.seed = a.seed;
  apply_board_emulator_faults(a.link, eo);
  eo.faults.saturate_probability = a.saturate;
  eo.faults.device_overrun_probability = a.overrun;
  return eo;
}

void print_board_faults(const StretchEmulatorStats& st) {
  std::printf("board: %llu measurements, %llu reports sent; faults: %llu dropped, %llu duplicated, %llu corrupted, "
              "%llu reordered, %llu discarded by the board (overrun), %llu saturated readings injected, %llu "
              "boot(s)\n",
              ull(st.measurements), ull(st.reports_sent), ull(st.dropped), ull(st.duplicated), ull(st.corrupted),
              ull(st.reordered), ull(st.device_overruns), ull(st.injected_saturations), ull(st.boots));
}

// Offline: the board's reports for --seconds, back to back, for 'monitor --from-file'.
int emulate_to_file(const EmulateArgs& a, const StretchEmulatorOptions& eo, const EmulatedSignal& sig) {
  if (!a.force && std::filesystem::exists(a.out)) return logger().error("{} exists; pass --force to overwrite it", a.out), 1;
  auto emulator = StretchEmulator::create(eo, sig.provider);
  if (!emulator) return logger().error("{}", emulator.error().message), 1;
  if (auto s = check_output_path(a.out, "capture file"); !s) return report_error(s.error());
  std::ofstream file(a.out, std::ios::binary | std::ios::trunc);
  if (!file) return logger().error("cannot write {}: {}", a.out, std::strerror(errno)), 1;
  std::vector<StretchEmulatedReport> reports;
  std::uint64_t bytes = 0;
  const TimeNs end = seconds_to_ns(a.seconds);
  for (TimeNs t = 0;; t += 100 * kNsPerMillisecond) {
    emulator->advance_to(std::min(t, end), reports);
    if (t >= end) emulator->flush(reports);
    for (const auto& r : reports) file.write(reinterpret_cast<const char*>(r.bytes.data()), r.bytes.size());
    bytes += reports.size() * kStretchDataReportSize;
    reports.clear();
    if (t >= end) break;
  }
  file.close();
  if (!file) return logger().error("writing {} failed", a.out), 1;
  std::printf("wrote %s: %llu bytes, %.1f s of a %d x %d strip board%s at %d measurements/s, seed %llu\n", a.out.c_str(),
              ull(bytes), a.seconds, eo.top_strips, eo.bottom_strips, eo.single_strips ? " with single strips" : "",
              a.rate_hz, ull(a.seed));
  print_board_faults(emulator->stats());
  return 0;
}

// Live: the board served over the in-memory HID link, the host reading it as a real one.
int emulate_live(const EmulateArgs& a, const StretchEmulatorOptions& eo, const EmulatedSignal& sig) {
  const StretchCapacitanceProvider& provider = sig.provider;
  auto emulator = StretchEmulator::create(eo, provider);
  if (!emulator) return logger().error("{}", emulator.error().message), 1;
  auto link = std::make_shared<hid::FakeHidLink>();
  StretchEmulatorServer server(std::move(*emulator), link);
  StretchDeviceOptions o;
  o.stream.nominal_rate_hz = a.rate_hz;
  o.stream.expected_top_strips = eo.top_strips;
  o.stream.expected_bottom_strips = eo.bottom_strips;
  o.stream.require_single_strips = eo.single_strips;
  // With --layout the host solves the array as it arrives, on the consumer side.
  std::optional<StretchArrayReader> reader;
  if (sig.layout) {
    auto r = StretchArrayReader::create(*sig.layout);
    if (!r) return logger().error("{}", r.error().message), 1;
    reader.emplace(std::move(*r));
  }
  stretch_array::CellFrame frame, last_frame;
  if (reader) frame = reader->make_frame();
  std::uint64_t frames = 0;
  double worst_cell_error = 0.0;  // relative to the cell's rest capacitance, over the last second's frames
  std::vector<double> truth(sig.rest_pf.size());
  o.reconnect_backoff_max_ns = 200 * kNsPerMillisecond;
  o.deliver_flagged = true;  // the self-test checks that flagged readings are the injected ones
  StretchDevice device(std::make_unique<hid::FakeHidTransport>(link), o);
  device.set_state_callback(print_link_state);
  std::printf("emulating a %d x %d strip board%s (%zu combinations)%s at %d measurements/s for %g s over the in-memory "
              "HID link, seed %llu\n",
              eo.top_strips, eo.bottom_strips, eo.single_strips ? " with single strips" : "", eo.combination_count(),
              sig.layout ? (" serving layout '" + sig.layout->name + "'").c_str() : "", a.rate_hz, a.seconds,
              ull(a.seed));
  if (auto s = device.start(); !s) return logger().error("{}", s.error().message), 1;
  server.start();
  // The unplugs cut the cable too: the host sees the board vanish and come back.
  for (const StretchOutage& u : eo.faults.unplugs) link->schedule_unplug(server.time_zero_ns() + u.at_ns, u.duration_ns);

  const TimeNs t0 = server.time_zero_ns();
  const double tolerance_pf = sig.max_slope_pf_per_s * 0.010 + 0.5 * kStretchPfPerCount;
  std::uint64_t checked = 0, wrong_values = 0, flagged_seen = 0, out_of_order = 0;
  double worst_error_pf = 0.0;
  TimeNs previous_time = 0;
  LatestValues latest;
  const double elapsed = watch(device, a.seconds, a.interval_s, latest, [&](const StretchSample& s) {
    if (s.time_ns <= previous_time) ++out_of_order;
    previous_time = s.time_ns;
    if (reader && reader->add(std::span<const StretchSample>(&s, 1), frame)) {
      ++frames;
      last_frame = frame;
      // After the first two seconds (cycles and the filter filled), against the cells at the frame's time.
      if (frame.all_valid() && frame.time_ns - t0 > 2 * kNsPerSecond) {
        sig.cells(frame.time_ns - t0, truth);
        for (std::size_t c = 0; c < truth.size(); ++c) {
          worst_cell_error = std::max(worst_cell_error, std::fabs(frame.cells_pf[c] - truth[c]) / sig.rest_pf[c]);
        }
      }
    }
    if (s.status != StretchMeasurementStatus::ok) {
      ++flagged_seen;
      return;
    }
    // The provider at the host's time for the measurement: right within the
    // drift over a 10 ms time error, so this checks values and times at once.
    const double error = std::fabs(s.capacitance_pf - provider(s.combination, s.time_ns - t0));
    worst_error_pf = std::max(worst_error_pf, error);
    ++checked;
    if (error > tolerance_pf) ++wrong_values;
  });
  server.stop();
  const StretchDeviceStats st = device.stats();
  const StretchEmulatorStats board = server.emulator_stats();
  const hid::FakeHidLinkStats cable = link->stats();
  print_device_totals(st, elapsed);
  print_summary(st.stream, elapsed);
  print_grid(latest, eo.top_strips, eo.bottom_strips);
  std::printf("\n");
  print_board_faults(board);

  // The self-test: what the host decoded against what the board did.
  bool pass = true;
  auto check = [&pass](bool ok, const std::string& what) {
    std::printf("  [%s] %s\n", ok ? "ok" : "FAIL", what.c_str());
    pass = pass && ok;
  };
  char line[256];
  std::printf("\nself-test:\n");
  check(checked > 0, "measurements arrived (" + std::to_string(checked) + " usable)");
  std::snprintf(line, sizeof line,
                "every usable value matches the board's at its mapped time: worst |error| %.4f pF, tolerance %.4f pF "
                "(%llu beyond)",
                worst_error_pf, tolerance_pf, ull(wrong_values));
  check(wrong_values == 0, line);
  check(out_of_order == 0, "measurement times strictly increase (" + std::to_string(out_of_order) + " did not)");
  const std::size_t combinations = eo.combination_count();
  if (st.stream.measurements >= 2 * combinations) {
    check(latest.count() == combinations,
          "every combination was measured (" + std::to_string(latest.count()) + " of " + std::to_string(combinations) + ")");
  }
  // Reports the board sent, less those whose arrival fell into an unplug, all reached the decoder.
  const std::uint64_t reached = cable.delivered;
  const StretchStreamStats& s = st.stream;
  check(st.reports_read == reached && s.reports == reached,
        "every report the link delivered was decoded (" + std::to_string(s.reports) + " of " + std::to_string(reached) + ")");
  check(s.decode_errors >= board.corrupted && s.decode_errors <= board.corrupted * 2,
        "corrupted reports were caught by the CRC (" + std::to_string(s.decode_errors) + " undecodable, " +
            std::to_string(board.corrupted) + " corrupted)");
  check(flagged_seen == s.measurements_flagged() && s.by_status[1] <= board.saturated,
        "flagged readings are the board's (" + std::to_string(flagged_seen) + " flagged, " +
            std::to_string(board.saturated) + " saturated at the board)");
  const std::uint64_t restarts = board.boots - 1;
  check(s.device_resets == restarts, "board restarts recognised (" + std::to_string(s.device_resets) + " of " +
                                         std::to_string(restarts) + ")");
  if (reader && a.seconds > 3.0) {
    // A frame mixes measurements up to a cycle plus the filter window old
    // (Sec. 4.3.2), so it lags the moving cells: 2 % of C0 is several times
    // what that lag costs here, and far below what a wrong row would.
    std::snprintf(line, sizeof line,
                  "the array reader solved %llu frames; the last has %zu of %zu cells valid; worst cell error after "
                  "2 s %.3f %% of its rest capacitance (limit 2 %% without faults)",
                  ull(frames), last_frame.cells_pf.empty() ? std::size_t{0} : static_cast<std::size_t>(std::count(
                      last_frame.status.begin(), last_frame.status.end(), stretch_array::CellStatus::valid)),
                  sig.rest_pf.size(), worst_cell_error * 100.0);
    // With faults, lost and flagged rows leave older values and worse-conditioned
    // row sets in the solve: the error is reported, and only the frames are checked.
    if (eo.faults.any()) {
      std::printf("  [info] %s\n", line);
      check(frames > 0 && last_frame.all_valid(), "the array reader solved frames through the faults");
    } else {
      check(frames > 0 && last_frame.all_valid() && worst_cell_error < 0.02, line);
    }
  }
  std::printf("self-test %s\n", pass ? "PASSED" : "FAILED");
  return pass ? 0 : 1;
}

int run_emulate(const EmulateArgs& a) {
  auto sig = signal_for(a);
  if (!sig) return logger().error("{}", sig.error().message), 1;
  StretchEmulatorOptions eo = emulator_options(a);
  if (sig->layout) {
    // The layout decides the strips, and its plan has single strips.
    auto o = stretch_array_emulator_options(*sig->layout, eo);
    if (!o) return logger().error("{}", o.error().message), 1;
    eo = *o;
  }
  if (auto s = eo.validate(); !s) return logger().error("{}", s.error().message), 1;
  return a.out.empty() ? emulate_live(a, eo, *sig) : emulate_to_file(a, eo, *sig);
}

}  // namespace

void add_stretch_board_command(CLI::App& app, int& exit_code) {
  CLI::App* board = add_command(app, "stretch-board");
  board->require_subcommand(1);

  add_hid_list_command(*board, kStretchBoardKind, "List HID devices with the board's USB IDs (or all with --all).",
                       "List every HID device, not just stretch boards", exit_code);

  auto mon = std::make_shared<MonitorArgs>();
  CLI::App* mon_cmd = board->add_subcommand(
      "monitor",
      "Open a board, decode its reports and print, every --interval, the report and measurement rates, lost, "
      "duplicate, late and undecodable reports, flagged readings, restarts, the clock alignment and the range of the "
      "latest values; at the end, totals and the latest capacitance of every combination. Keeps going through "
      "unplugging and replugging. With --from-file, decodes a capture instead (rates are then per second of device "
      "time). Exit status 1 if no measurements arrived.");
  add_hid_monitor_options(*mon_cmd, *mon, "Open the board with this USB serial number");
  mon_cmd->add_option("--rate", mon->rate_hz, "Measurement rate to assume until the board's own is measured, per s")
      ->check(CLI::Range(1.0, static_cast<double>(kStretchMaxRateHz)))
      ->capture_default_str();
  mon_cmd->add_option("--top-strips", mon->top_strips,
                      "Refuse a board without this many top strips (the layout's; 0: accept any)")
      ->check(CLI::Range(0, static_cast<int>(kStretchMaxStrips)));
  mon_cmd->add_option("--bottom-strips", mon->bottom_strips,
                      "Refuse a board without this many bottom strips (0: accept any)")
      ->check(CLI::Range(0, static_cast<int>(kStretchMaxStrips)));
  mon_cmd->add_option("--from-file", mon->from_file, "Decode this capture file instead of a live board")
      ->check(CLI::ExistingFile);
  mon_cmd->callback([mon, &exit_code] { exit_code = mon->from_file.empty() ? monitor_live(*mon) : monitor_file(*mon); });

  auto emu = std::make_shared<EmulateArgs>();
  CLI::App* emu_cmd = board->add_subcommand(
      "emulate",
      "Self-test without hardware: an emulated board measures slowly varying synthetic capacitances and is served "
      "over the in-memory HID link in real time; the host code that reads a real board decodes it, prints what it "
      "saw (as monitor does) and checks it against the board: values and times, loss and fault accounting, restarts. "
      "Exit status 0 when every check passes. Faults can be injected; the same seed gives the same board. With --out, "
      "writes the board's reports to a capture file for 'monitor --from-file' instead (no real time).");
  emu_cmd->add_option("--seconds", emu->seconds, "How long to run, s")
      ->check(CLI::Range(0.1, 24.0 * 3600.0))
      ->capture_default_str();
  emu_cmd->add_option("--interval", emu->interval_s, "Seconds between status lines")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
  emu_cmd->add_option("--seed", emu->seed, "Random seed for the faults")->capture_default_str();
  emu_cmd->add_option("--top-strips", emu->top_strips, "Top-layer strips")
      ->check(CLI::Range(1, static_cast<int>(kStretchMaxStrips)))
      ->capture_default_str();
  emu_cmd->add_option("--bottom-strips", emu->bottom_strips, "Bottom-layer strips")
      ->check(CLI::Range(1, static_cast<int>(kStretchMaxStrips)))
      ->capture_default_str();
  emu_cmd->add_option("--rate", emu->rate_hz, "Measurements per second")
      ->check(CLI::Range(1, static_cast<int>(kStretchMaxRateHz)))
      ->capture_default_str();
  emu_cmd->add_flag("--single-strips", emu->single_strips,
                    "Also measure every strip alone after the pairs (protocol 1.1; a sensor array's M^II rows)");
  emu_cmd
      ->add_option("--layout", emu->layout,
                   "Serve this stretch sensor array layout (TOML, docs/stretch-arrays.md; 'proprio array layout' "
                   "writes one): its strips and single "
                   "strips over known, slowly varying cells; the self-test also solves the cells back. Overrides "
                   "--top-strips, --bottom-strips and --single-strips")
      ->check(CLI::ExistingFile);
  add_board_emulator_fault_options(*emu_cmd, emu->link, "the board");
  emu_cmd->add_option("--saturate", emu->saturate, "Probability, per measurement, of a saturated reading")
      ->check(CLI::Range(0.0, 1.0));
  emu_cmd->add_option("--overrun", emu->overrun,
                      "Probability that the board discards a report itself (transmit queue full)")
      ->check(CLI::Range(0.0, 1.0));
  emu_cmd->add_option("--out", emu->out, "Write the reports to this capture file instead of running the self-test");
  emu_cmd->add_flag("--force", emu->force, "Overwrite an existing --out file");
  emu_cmd->callback([emu, &exit_code] { exit_code = run_emulate(*emu); });
}

}  // namespace proprio::cli
