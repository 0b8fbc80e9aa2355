#pragma once
// The FTM glove as data (Lee 2021, ch. 3, §3.2.1): which sensors it has, where
// they sit, and the samples its read-out board, its simulator and its tracker
// exchange. Everything that produces FTM data (the simulated wearer, the board
// emulator, a live board) delivers these structs; everything that consumes it
// (the tracker, the calibration, recordings) takes them. SI units throughout,
// except the compass in µT (the unit its references and gains are stated in)
// and the bend sensors in picofarads (what the capacitance read-out measures).
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "proprio/core/hand_joint.hpp"
#include "proprio/core/hand_model.hpp"
#include "proprio/core/math.hpp"
#include "proprio/core/time.hpp"

namespace proprio::ftm {

// Four MPU-9250 IMUs (accelerometer, gyro, AK8963 compass): on the dorsum of
// the hand, the thumb metacarpal and the index and middle proximal phalanges.
enum class FtmImu : std::uint8_t { dorsum = 0, thumb_metacarpal, index_proximal, middle_proximal };
inline constexpr std::size_t kFtmImuCount = 4;

// Three soft capacitive bend sensors, over the joints the IMUs cannot see.
enum class FtmBend : std::uint8_t { thumb_mcp = 0, index_pip, middle_pip };
inline constexpr std::size_t kFtmBendCount = 3;

constexpr std::size_t index_of(FtmImu i) noexcept { return static_cast<std::size_t>(i); }
constexpr std::size_t index_of(FtmBend b) noexcept { return static_cast<std::size_t>(b); }

constexpr std::string_view to_string(FtmImu i) noexcept {
  switch (i) {
    case FtmImu::dorsum: return "dorsum";
    case FtmImu::thumb_metacarpal: return "thumb_metacarpal";
    case FtmImu::index_proximal: return "index_proximal";
    case FtmImu::middle_proximal: return "middle_proximal";
  }
  return "?";
}
constexpr std::string_view to_string(FtmBend b) noexcept {
  switch (b) {
    case FtmBend::thumb_mcp: return "thumb_mcp";
    case FtmBend::index_pip: return "index_pip";
    case FtmBend::middle_pip: return "middle_pip";
  }
  return "?";
}

// The hand segment each IMU is strapped to, as a HandJoint whose frame moves
// with that bone (the dorsum is rigid with the wrist in Proprio's hand model).
constexpr HandJoint segment_of(FtmImu i) noexcept {
  switch (i) {
    case FtmImu::dorsum: return HandJoint::wrist;
    case FtmImu::thumb_metacarpal: return HandJoint::thumb_metacarpal;
    case FtmImu::index_proximal: return HandJoint::index_proximal;
    case FtmImu::middle_proximal: return HandJoint::middle_proximal;
  }
  return HandJoint::wrist;
}
// The 1-DOF joint each bend sensor spans.
constexpr HandDof dof_of(FtmBend b) noexcept {
  switch (b) {
    case FtmBend::thumb_mcp: return HandDof::thumb_mcp_flexion;
    case FtmBend::index_pip: return HandDof::index_pip_flexion;
    case FtmBend::middle_pip: return HandDof::middle_pip_flexion;
  }
  return HandDof::index_pip_flexion;
}

// The DOFs the FTM measures (IMUs and bend sensors); the thumb IP and the
// index/middle DIP come from synergies, ring and little follow their
// neighbours: those are reported valid but not tracked.
inline constexpr std::array<HandDof, 9> kFtmTrackedDofs = {
    HandDof::thumb_cmc_flexion,  HandDof::thumb_cmc_abduction,  HandDof::thumb_mcp_flexion,
    HandDof::index_mcp_flexion,  HandDof::index_mcp_abduction,  HandDof::index_pip_flexion,
    HandDof::middle_mcp_flexion, HandDof::middle_mcp_abduction, HandDof::middle_pip_flexion,
};

// Sample status bits, shared by the wire protocol, the simulator and the
// tracker. Any bit but mag_overflow makes the whole IMU sample unusable;
// mag_overflow (the AK8963's HOFL) only its compass part.
namespace sample_status {
inline constexpr std::uint8_t stale = 0x01;            // no new data since the last tick: values repeat
inline constexpr std::uint8_t accel_saturated = 0x02;  // an accelerometer axis at the rail
inline constexpr std::uint8_t gyro_saturated = 0x04;   // a gyro axis at the rail
inline constexpr std::uint8_t sensor_error = 0x08;     // bus read failed: values are zero
inline constexpr std::uint8_t mag_overflow = 0x10;     // compass overflow: mag_uT not valid
}  // namespace sample_status

// One IMU at one tick (200 Hz on the board). time_ns is the instant the sample
// describes, on the host's clock (CLOCK_MONOTONIC after clock alignment for a
// board; the simulation's clock for the simulator). Axes are the IMU's own
// (the accelerometer's; the compass's die axes are already swapped into them).
struct FtmImuSample {
  TimeNs time_ns = 0;
  Vec3 accel_mps2 = Vec3::Zero();  // specific force, gravity included
  Vec3 gyro_radps = Vec3::Zero();
  // Raw compass field, hard and soft iron included (the tracker's calibration
  // removes them). The AK8963 runs at 100 Hz at most: mag_fresh marks a new
  // sample; otherwise mag_uT repeats the last one.
  Vec3 mag_uT = Vec3::Zero();
  bool mag_fresh = false;
  std::uint8_t status = 0;  // sample_status bits
};

// One bend sensor at one tick (1 kHz on the board): its capacitance.
struct FtmBendSample {
  TimeNs time_ns = 0;
  double capacitance_pF = 0.0;
  std::uint8_t status = 0;  // sample_status::stale / sensor_error
};

// The external wrist tracker (the thesis used a VIVE tracker): the wrist's
// pose in the world, already composed with the tracker-to-wrist offset.
struct FtmWristSample {
  TimeNs time_ns = 0;
  Pose T_world_wrist;
  bool valid = false;  // false: the tracker lost tracking (dropout)
};

// One sample of any of the three kinds, as a feed delivers them in time order.
struct FtmEvent {
  enum class Kind : std::uint8_t { imu, bend, wrist };
  Kind kind = Kind::imu;
  std::uint8_t index = 0;  // index_of(FtmImu) or index_of(FtmBend); 0 for the wrist
  FtmImuSample imu;        // kind == imu
  FtmBendSample bend;      // kind == bend
  FtmWristSample wrist;    // kind == wrist
  TimeNs time_ns() const noexcept {
    return kind == Kind::imu ? imu.time_ns : kind == Kind::bend ? bend.time_ns : wrist.time_ns;
  }
};

// Anything that produces FTM samples in time order: the simulated wearer, a
// decoded board stream, a recording. One owner calls advance(); not
// thread-safe.
class FtmSampleFeed {
 public:
  virtual ~FtmSampleFeed() = default;
  // Appends to `out` every sample with time_ns <= t_ns not delivered before,
  // in time order (ties: IMUs, then bend sensors, then the wrist).
  virtual void advance(TimeNs t_ns, std::vector<FtmEvent>& out) = 0;
};

// Nominal sample rates of the read-out board.
inline constexpr double kFtmImuRateHz = 200.0;
inline constexpr double kFtmBendRateHz = 1000.0;

}  // namespace proprio::ftm
