#include "proprio/rig_bus/bus_bench.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <deque>
#include <set>
#include <unordered_map>

namespace proprio::rig_bus {

namespace {

double percentile_ms(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto k = static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(k, v.size() - 1)];
}

BusRecoveryStats recovery_stats(const std::vector<BusChangeRecovery>& changes, bool (*pick)(BusTruthEventKind)) {
  BusRecoveryStats s;
  std::vector<double> ms;
  for (const auto& c : changes) {
    if (!pick(c.kind)) continue;
    ++s.changes;
    if (c.recovery_ns < 0) continue;
    ++s.recovered;
    ms.push_back(static_cast<double>(c.recovery_ns) * 1e-6);
  }
  s.p50_ms = percentile_ms(ms, 0.5);
  s.p95_ms = percentile_ms(ms, 0.95);
  s.max_ms = ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end());
  return s;
}

const char* kind_name(BusTruthEventKind k) {
  switch (k) {
    case BusTruthEventKind::power_loss: return "power_loss";
    case BusTruthEventKind::unplug: return "unplug";
    case BusTruthEventKind::plug: return "plug";
    case BusTruthEventKind::reparent: return "reparent";
  }
  return "?";
}

// An unplug is only visible as silence: the allowance is the silence rule
// plus the latency target (the subtree's last messages in transit).
constexpr double kLatencyTargetMs = 50.0;
constexpr double kRecoveryTargetMs = 2000.0;

}  // namespace

Status BusBenchOptions::validate() const {
  auto bad = [](const char* what) { return make_error(Errc::invalid_argument, std::string("BusBenchOptions.") + what); };
  if (depth < 8 || depth > 64) return bad("depth must be 8 to 64 (the issue asks for >= 8)");
  if (duration_ns < kNsPerSecond || duration_ns > 100'000 * kNsPerSecond) return bad("duration_ns must be 1 s to 100000 s");
  if (!(loss_probability >= 0.0 && loss_probability < 1.0)) return bad("loss_probability must be in [0, 1)");
  if (!(corrupt_probability >= 0.0 && corrupt_probability < 1.0)) return bad("corrupt_probability must be in [0, 1)");
  if (power_loss_interval_ns < 0 || topology_change_interval_ns < 0) return bad("intervals must be 0 (off) or positive");
  if (power_loss_min_ns <= 0 || power_loss_max_ns < power_loss_min_ns) return bad("power_loss_min_ns must be positive and at most power_loss_max_ns");
  if (!(clock_skew_max_ppm >= 0.0 && clock_skew_max_ppm <= 100'000.0)) return bad("clock_skew_max_ppm must be 0 to 100000");
  if (usb_latency_ns < 0) return bad("usb_latency_ns must not be negative");
  if (check_interval_ns < 100'000 || check_interval_ns > 100 * kNsPerMillisecond) return bad("check_interval_ns must be 0.1 to 100 ms");
  if (detach_after_ns <= 0 || ghost_grace_ns < 0) return bad("detach_after_ns must be positive and ghost_grace_ns not negative");
  return {};
}

std::string BusBenchOptions::describe() const {
  char text[420];
  std::snprintf(text, sizeof text,
                "depth %d, %.0f s simulated, loss %.2f %%/hop, corruption %.2f %%/hop, power loss every %.1f s "
                "(%.0f-%.0f ms), topology change every %.1f s, skew +-%.0f ppm, USB latency %.1f ms, checks every "
                "%.1f ms, detach after %.1f s, seed %llu",
                depth, static_cast<double>(duration_ns) * 1e-9, loss_probability * 100.0, corrupt_probability * 100.0,
                static_cast<double>(power_loss_interval_ns) * 1e-9, static_cast<double>(power_loss_min_ns) * 1e-6,
                static_cast<double>(power_loss_max_ns) * 1e-6, static_cast<double>(topology_change_interval_ns) * 1e-9,
                clock_skew_max_ppm, static_cast<double>(usb_latency_ns) * 1e-6,
                static_cast<double>(check_interval_ns) * 1e-6, static_cast<double>(detach_after_ns) * 1e-9,
                static_cast<unsigned long long>(seed));
  return text;
}

BusBenchReport run_bus_bench(const BusBenchOptions& o) {
  BusBenchReport report;
  if (auto s = o.validate(); !s) {
    report.error = s.error().message;
    return report;
  }
  report.options = o.describe();
  const auto wall_start = std::chrono::steady_clock::now();

  BusTree tree = make_bench_bus_tree(o.depth, o.seed);
  // The main branch's joint at `depth` (make_bench_bus_tree puts the main
  // branch first, in depth order).
  const auto probe_index = static_cast<std::size_t>(o.depth);
  report.probe_id = tree.components[probe_index].id;
  report.probe_depth = tree.depth_of(probe_index);
  report.components = tree.components.size();

  BusEmulatorOptions eo;
  eo.seed = o.seed;
  eo.faults.loss_probability = o.loss_probability;
  eo.faults.corrupt_probability = o.corrupt_probability;
  eo.faults.clock_skew_max_ppm = o.clock_skew_max_ppm;
  eo.faults.power_loss_interval_ns = o.power_loss_interval_ns;
  eo.faults.power_loss_min_ns = o.power_loss_min_ns;
  eo.faults.power_loss_max_ns = o.power_loss_max_ns;
  eo.faults.topology_change_interval_ns = o.topology_change_interval_ns;
  eo.faults.topology_change_start_ns = o.topology_change_interval_ns / 2;
  eo.faults.protected_ids = {report.probe_id};
  auto created = RigBusEmulator::create(std::move(tree), eo, demo_bus_angles);
  if (!created) {
    report.error = created.error().message;
    return report;
  }
  RigBusEmulator& emu = *created;
  BusTrackerOptions to;
  to.detach_after_ns = o.detach_after_ns;
  RigBusHost host(to);

  std::vector<RigBusEmulatedReport> sent;
  std::deque<RigBusEmulatedReport> in_flight;
  std::vector<double> latency_ms;
  std::size_t events_seen = 0;
  std::vector<std::size_t> open_changes;  // indices into report.changes not yet recovered
  std::set<std::uint32_t> host_prev, truth_prev;
  std::unordered_map<std::uint32_t, TimeNs> truly_gone_since;
  std::set<std::uint32_t> ghost_flagged;

  for (TimeNs t = o.check_interval_ns; t <= o.duration_ns; t += o.check_interval_ns) {
    sent.clear();
    emu.advance_to(t, sent);
    for (const auto& r : sent) in_flight.push_back(r);
    while (!in_flight.empty() && in_flight.front().send_ns + o.usb_latency_ns <= t) {
      const RigBusEmulatedReport& r = in_flight.front();
      const TimeNs arrival = r.send_ns + o.usb_latency_ns;
      if (host.on_report(r.bytes, arrival)) {
        host.for_each_message_of_last_report([&](const BusMessage& m) {
          if (m.type != BusMessageType::data || m.creator_id != report.probe_id) return;
          if (const auto made = emu.creation_time_ns(m.creator_id, m.boot, m.clock_us)) {
            latency_ms.push_back(static_cast<double>(arrival - *made) * 1e-6);
          }
        });
      }
      in_flight.pop_front();
    }
    host.update(t);

    // New truth events.
    const auto& events = emu.events();
    for (; events_seen < events.size(); ++events_seen) {
      const BusTruthEvent& e = events[events_seen];
      if (e.kind == BusTruthEventKind::power_loss) {
        ++report.power_losses;
        continue;
      }
      // A change before the last was recovered ends the last one's clock.
      open_changes.clear();
      report.changes.push_back({e.at_ns, e.kind, e.component_id, -1});
      open_changes.push_back(report.changes.size() - 1);
    }

    const auto truth = emu.truth_edges();
    const auto seen = host.tracker().attached_edges(t);
    if (truth == seen) {
      for (const std::size_t i : open_changes) report.changes[i].recovery_ns = t - report.changes[i].at_ns;
      open_changes.clear();
    }

    std::set<std::uint32_t> host_now, truth_now;
    for (const auto& e : seen) host_now.insert(e.id);
    for (const auto& e : truth) truth_now.insert(e.id);
    for (const std::uint32_t id : host_prev) {
      if (!host_now.count(id) && truth_now.count(id)) ++report.false_detaches;
    }
    for (const std::uint32_t id : truth_prev) {
      if (!truth_now.count(id)) truly_gone_since[id] = t;
    }
    for (const std::uint32_t id : truth_now) {
      truly_gone_since.erase(id);
      ghost_flagged.erase(id);
    }
    for (const std::uint32_t id : host_now) {
      const auto g = truly_gone_since.find(id);
      if (g == truly_gone_since.end() || ghost_flagged.count(id)) continue;
      if (t - g->second > o.detach_after_ns + o.ghost_grace_ns) {
        ++report.ghost_components;
        ghost_flagged.insert(id);
      }
    }
    host_prev = std::move(host_now);
    truth_prev = std::move(truth_now);
  }

  report.simulated_s = static_cast<double>(o.duration_ns) * 1e-9;
  report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  // A change too close to the end to be seen through is left out rather than failed.
  while (!report.changes.empty() && report.changes.back().recovery_ns < 0 &&
         o.duration_ns - report.changes.back().at_ns < o.detach_after_ns + o.ghost_grace_ns) {
    report.changes.pop_back();
  }
  report.recovery_all = recovery_stats(report.changes, [](BusTruthEventKind) { return true; });
  report.recovery_unplug =
      recovery_stats(report.changes, [](BusTruthEventKind k) { return k == BusTruthEventKind::unplug; });
  report.recovery_plug = recovery_stats(report.changes, [](BusTruthEventKind k) { return k == BusTruthEventKind::plug; });
  report.recovery_reparent =
      recovery_stats(report.changes, [](BusTruthEventKind k) { return k == BusTruthEventKind::reparent; });
  report.latency_samples = latency_ms.size();
  report.latency_p50_ms = percentile_ms(latency_ms, 0.5);
  report.latency_p99_ms = percentile_ms(latency_ms, 0.99);
  report.latency_max_ms = latency_ms.empty() ? 0.0 : *std::max_element(latency_ms.begin(), latency_ms.end());
  report.emulator = emu.stats();
  report.host = host.stats();
  return report;
}

bool BusBenchReport::targets_met() const {
  if (!error.empty()) return false;
  const bool all_recovered = recovery_all.recovered == recovery_all.changes;
  const bool fast = recovery_plug.max_ms <= kRecoveryTargetMs && recovery_reparent.max_ms <= kRecoveryTargetMs &&
                    recovery_unplug.max_ms <= kRecoveryTargetMs + kLatencyTargetMs;
  return all_recovered && fast && false_detaches == 0 && ghost_components == 0 && latency_samples > 0 &&
         latency_p99_ms <= kLatencyTargetMs;
}

std::string BusBenchReport::summary() const {
  if (!error.empty()) return "rig bus benchmark not run: " + error;
  char buf[1400];
  std::snprintf(
      buf, sizeof buf,
      "rig bus benchmark (%s)\n"
      "  %zu components, probe joint at depth %d; %.0f s simulated in %.2f s\n"
      "  topology changes: %zu (%zu recovered); recovery p50 %.0f ms, p95 %.0f ms, max %.0f ms\n"
      "    unplug   %zu: p50 %.0f ms, max %.0f ms (silence rule %.0f ms + transit)\n"
      "    plug     %zu: p50 %.0f ms, max %.0f ms\n"
      "    reparent %zu: p50 %.0f ms, max %.0f ms\n"
      "  power losses %zu; false detaches %zu; ghost components %zu\n"
      "  latency at depth %d: %zu readings, p50 %.1f ms, p99 %.1f ms, max %.1f ms\n"
      "  messages: %llu hops, %llu lost, %llu corrupted (%llu caught by CRC), %llu queue overflows, %llu lost to "
      "power; host: %llu reports, %llu decode errors\n"
      "  targets %s",
      options.c_str(), components, probe_depth, simulated_s, wall_s, recovery_all.changes, recovery_all.recovered,
      recovery_all.p50_ms, recovery_all.p95_ms, recovery_all.max_ms, recovery_unplug.changes, recovery_unplug.p50_ms,
      recovery_unplug.max_ms, kRecoveryTargetMs, recovery_plug.changes, recovery_plug.p50_ms, recovery_plug.max_ms,
      recovery_reparent.changes, recovery_reparent.p50_ms, recovery_reparent.max_ms, power_losses, false_detaches,
      ghost_components, probe_depth, latency_samples, latency_p50_ms, latency_p99_ms, latency_max_ms,
      static_cast<unsigned long long>(emulator.hops), static_cast<unsigned long long>(emulator.lost),
      static_cast<unsigned long long>(emulator.corrupted), static_cast<unsigned long long>(emulator.crc_dropped),
      static_cast<unsigned long long>(emulator.queue_overflows), static_cast<unsigned long long>(emulator.lost_to_power),
      static_cast<unsigned long long>(host.reports), static_cast<unsigned long long>(host.decode_errors),
      targets_met() ? "met" : "NOT met");
  return buf;
}

std::string BusBenchReport::to_json() const {
  auto stats = [](const BusRecoveryStats& s) {
    char b[200];
    std::snprintf(b, sizeof b, "{\"changes\":%zu,\"recovered\":%zu,\"p50_ms\":%.3f,\"p95_ms\":%.3f,\"max_ms\":%.3f}",
                  s.changes, s.recovered, s.p50_ms, s.p95_ms, s.max_ms);
    return std::string(b);
  };
  std::string out = "{";
  if (!error.empty()) {
    std::string e;
    for (const char c : error) {
      if (c == '"' || c == '\\') e.push_back('\\');
      if (static_cast<unsigned char>(c) >= 0x20) e.push_back(c);
    }
    return out + "\"error\":\"" + e + "\"}";
  }
  char b[700];
  std::snprintf(b, sizeof b,
                "\"components\":%zu,\"probe_depth\":%d,\"simulated_s\":%.1f,\"wall_s\":%.3f,\"power_losses\":%zu,"
                "\"false_detaches\":%zu,\"ghost_components\":%zu,\"latency_samples\":%zu,\"latency_p50_ms\":%.3f,"
                "\"latency_p99_ms\":%.3f,\"latency_max_ms\":%.3f,\"messages_lost\":%llu,\"messages_corrupted\":%llu,"
                "\"queue_overflows\":%llu,\"host_decode_errors\":%llu,\"targets_met\":%s,",
                components, probe_depth, simulated_s, wall_s, power_losses, false_detaches, ghost_components,
                latency_samples, latency_p50_ms, latency_p99_ms, latency_max_ms,
                static_cast<unsigned long long>(emulator.lost), static_cast<unsigned long long>(emulator.corrupted),
                static_cast<unsigned long long>(emulator.queue_overflows),
                static_cast<unsigned long long>(host.decode_errors), targets_met() ? "true" : "false");
  out += b;
  out += "\"recovery\":" + stats(recovery_all) + ",\"recovery_unplug\":" + stats(recovery_unplug) +
         ",\"recovery_plug\":" + stats(recovery_plug) + ",\"recovery_reparent\":" + stats(recovery_reparent) +
         ",\"changes\":[";
  for (std::size_t i = 0; i < changes.size(); ++i) {
    char c[160];
    std::snprintf(c, sizeof c, "%s{\"at_s\":%.3f,\"kind\":\"%s\",\"component\":%u,\"recovery_ms\":%.3f}",
                  i ? "," : "", static_cast<double>(changes[i].at_ns) * 1e-9, kind_name(changes[i].kind),
                  changes[i].component_id,
                  changes[i].recovery_ns < 0 ? -1.0 : static_cast<double>(changes[i].recovery_ns) * 1e-6);
    out += c;
  }
  return out + "]}";
}

}  // namespace proprio::rig_bus
