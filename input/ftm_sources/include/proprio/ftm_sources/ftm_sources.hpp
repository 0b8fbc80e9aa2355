#pragma once
// The FTM glove as a live HandSource, three ways (the OpenXR layer's `ftm`
// source, `proprio run --hands ftm`):
//   sim:      the simulated wearer streamed in real time on its own thread;
//   emulated: the same wearer behind the board emulator, read by the real
//             FtmBoardDevice over the kit's fake HID link (unplugs included);
//   device:   a real board over hidapi with a calibration file.
// Sim and emulated calibrate the way a real user does: the wearer's
// figure-eight and three poses go through ftm_sim::calibrate_from_wearer
// (the real calibration) unless a calibration file is given.
//
// A board carries only the glove's IMUs and bend sensors; the wrist tracker is
// a device of its own, so the emulated source hands the wearer's wrist samples
// to the tracker beside the board's stream, as a VIVE tracker's would arrive.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/pose_history.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/ftm/ftm_hand_source.hpp"
#include "proprio/ftm_board/ftm_device.hpp"
#include "proprio/ftm_board/ftm_emulator.hpp"

namespace proprio::ftm_sources {

// Poses come at the IMU rate (200 Hz): 1024 keep the last ~5 s, as the
// default 256 keep ~4 s of a 60 Hz source (a consumer that lags, like a
// headless engine stepping its own time, still finds its instants).
inline PoseHistoryOptions ftm_default_history() {
  PoseHistoryOptions h;
  h.capacity = 1024;
  return h;
}

struct FtmSimSourceOptions {
  Handedness hand = Handedness::right;
  int subject = 3;  // simulated subject 0..sim::kSimSubjectCount-1; -1: the simulator's default measurements
  std::uint64_t seed = 1;
  double task_s = 3600.0;  // the wearer's task; after it the hand holds still
  // Empty: calibrate from the wearer's own calibration phases. Otherwise the
  // file (load_ftm_calibration) and the wearer starts with its task.
  std::filesystem::path calibration;
  bool track_abduction = true;  // false: the thesis's "without AA"
  PoseHistoryOptions history = ftm_default_history();
  // The wearer's true hand (sim::HandTruthWriter CSV) on the served poses'
  // clock and world. Empty: not written. One row every truth_every dorsum
  // IMU ticks (2: 100 Hz).
  std::filesystem::path truth_path;
  int truth_every = 2;

  Status validate() const;
  std::string describe() const;
};

struct FtmEmulatedSourceOptions {
  FtmSimSourceOptions wearer;
  // The board's faults (emulator time 0 = when the source starts). Each
  // unplug also pulls the cable, so the driver sees the board vanish.
  devices::FtmEmulatorFaults faults;
  devices::FtmServeOptions serve;
  devices::FtmDeviceOptions device;

  Status validate() const;
  std::string describe() const;
};

struct FtmDeviceSourceOptions {
  Handedness hand = Handedness::right;
  std::filesystem::path calibration;  // required (proprio calibrate ftm writes one)
  bool track_abduction = true;
  PoseHistoryOptions history = ftm_default_history();
  devices::FtmDeviceOptions device;

  Status validate() const;
  std::string describe() const;
};

struct FtmLiveStats {
  ftm::FtmSourceStats source;
  devices::FtmDeviceStats device;  // zero for the sim input
  bool have_device = false;
  TimeNs time_zero_ns = 0;  // CLOCK_MONOTONIC of the task's start (sim) or emulator time 0 (emulated)
};

// A live FTM hand source: a producer thread feeds an ftm::FtmHandSource.
// available() is true while poses keep coming (the newest under
// kFtmStaleAfterNs old), so a missing or unplugged board reads unavailable.
class FtmLiveSource : public HandSource {
 public:
  static constexpr DurationNs kFtmStaleAfterNs = 250 * kNsPerMillisecond;
  ~FtmLiveSource() override = default;
  std::string_view name() const noexcept override { return "ftm"; }
  virtual FtmLiveStats live_stats() = 0;
};

Result<std::unique_ptr<FtmLiveSource>> make_sim_ftm_source(const FtmSimSourceOptions& options,
                                                           const Clock& clock = MonotonicClock::instance());
Result<std::unique_ptr<FtmLiveSource>> make_emulated_ftm_source(const FtmEmulatedSourceOptions& options);
// Starts even with no board attached: the driver keeps looking for one.
Result<std::unique_ptr<FtmLiveSource>> make_device_ftm_source(const FtmDeviceSourceOptions& options);
// The same with any transport (tests: a fake link with nothing behind it).
Result<std::unique_ptr<FtmLiveSource>> make_board_ftm_source(std::unique_ptr<hid::HidTransport> transport,
                                                             const FtmDeviceSourceOptions& options);

}  // namespace proprio::ftm_sources
