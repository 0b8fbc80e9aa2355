#pragma once
// The link faults a device emulator injects into the reports it sends (lost,
// duplicated, corrupted and reordered reports), shared by the emulators so
// that each device's tests see the same fault model, drawn the same way.
//
// The device keeps its own fault options and statistics types; what this code
// needs of them:
//   Faults: drop_probability, duplicate_probability, corrupt_probability, reorder_probability
//   Stats:  reports_sent, dropped, duplicated, corrupted, reordered (counters)
//   Report: send_ns, bytes (a std::array)
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"

namespace proprio::hid {

// The emulator's seed sub-streams (mix_seed) 1 to 4 are these faults'; a
// device's own random effects start at this one.
inline constexpr std::uint64_t kFirstDeviceFaultStream = 5;

template <typename Report>
class EmulatorLinkFaults {
 public:
  explicit EmulatorLinkFaults(std::uint64_t seed)
      : drop_rng_(mix_seed(seed, 1)),
        duplicate_rng_(mix_seed(seed, 2)),
        corrupt_rng_(mix_seed(seed, 3)),
        reorder_rng_(mix_seed(seed, 4)) {}

  // Sends one report through the faults, appending what leaves the device.
  template <typename Faults, typename Stats>
  void send(const Report& report, const Faults& f, Stats& stats, std::vector<Report>& out) {
    // One draw per report from each stream, whatever the outcome (switching
    // one fault off leaves the others' draws unchanged).
    const bool drop = drop_rng_.uniform01() < f.drop_probability;
    const bool duplicate = duplicate_rng_.uniform01() < f.duplicate_probability;
    const bool corrupt = corrupt_rng_.uniform01() < f.corrupt_probability;
    const bool reorder = reorder_rng_.uniform01() < f.reorder_probability;
    const std::uint64_t corrupt_byte = corrupt_rng_.below(report.bytes.size());
    const std::uint64_t corrupt_bit = corrupt_rng_.below(8);
    if (drop) {
      ++stats.dropped;
      return;
    }
    Report r = report;
    if (corrupt) {
      r.bytes[corrupt_byte] ^= static_cast<std::uint8_t>(1u << corrupt_bit);
      ++stats.corrupted;
    }
    if (reorder && !held_) {
      held_ = r;
      ++stats.reordered;
      return;
    }
    out.push_back(r);
    ++stats.reports_sent;
    if (duplicate) {
      out.push_back(r);
      ++stats.reports_sent;
      ++stats.duplicated;
    }
    if (held_) {
      held_->send_ns = r.send_ns;
      out.push_back(*held_);
      ++stats.reports_sent;
      held_.reset();
    }
  }

  // Sends a report still held back for reordering (end of a session).
  template <typename Stats>
  void flush(Stats& stats, std::vector<Report>& out) {
    if (!held_) return;
    out.push_back(*held_);
    ++stats.reports_sent;
    held_.reset();
  }

  // The device lost power: a report held back in its buffer is gone.
  void discard_held() noexcept { held_.reset(); }

 private:
  Rng drop_rng_, duplicate_rng_, corrupt_rng_, reorder_rng_;
  std::optional<Report> held_;
};

// Checks an emulator's fault option: `who` names the emulator ("glove
// emulator"), `name` the option under faults.
inline Status check_fault_probability(std::string_view who, const char* name, double p) {
  if (!(p >= 0.0 && p <= 1.0)) {
    return make_error(Errc::invalid_argument, std::string(who) + ": faults." + name + " = " + std::to_string(p) +
                                                  " is not a probability; use a value from 0 to 1");
  }
  return {};
}

// Checks an emulator's unplug list (each outage has at_ns and duration_ns).
template <typename Outage>
Status check_fault_outages(std::string_view who, const std::vector<Outage>& unplugs) {
  for (std::size_t i = 0; i < unplugs.size(); ++i) {
    if (unplugs[i].duration_ns <= 0) {
      return make_error(Errc::invalid_argument, std::string(who) + ": faults.unplugs[" + std::to_string(i) +
                                                    "] has duration " + std::to_string(unplugs[i].duration_ns) +
                                                    " ns; an outage must last longer than 0");
    }
  }
  return {};
}

// A device's free-running µs counter at true time t_ns, counting from
// boot_value_us at boot_ns with a crystal clock_error_ppm off; wraps at 2^32
// like the register.
inline std::uint32_t emulated_counter_us(TimeNs boot_ns, TimeNs t_ns, std::uint32_t boot_value_us,
                                         double clock_error_ppm) noexcept {
  if (t_ns <= boot_ns) return boot_value_us;
  // The counter ticks every device µs; truncate as a hardware counter does.
  const double device_us = static_cast<double>(t_ns - boot_ns) * (1.0 + clock_error_ppm * 1e-6) * 1e-3;
  const auto ticks = static_cast<std::uint64_t>(std::floor(device_us));
  return static_cast<std::uint32_t>(boot_value_us + ticks);
}

}  // namespace proprio::hid
