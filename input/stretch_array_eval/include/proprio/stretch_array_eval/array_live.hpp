#pragma once
// ArrayLiveSource: a stretch sensor array reconstructed live (issue 30), the
// chain a worn sleeve runs:
//
//   board (here: a simulated wearer + the board's firmware emulator, served
//   in real time over the HID kit's fake cable)
//   -> StretchDevice (reader thread: decode, clock sync)
//   -> StretchArrayReader (per-row parasitic subtraction, least-squares cells)
//   -> C/C0 against the rest frames -> ArrayReconstructor (ONNX regressor
//   through OpenCV DNN, then ARAP of the rest mesh) -> vertices.
//
// Threads. The wearer and the board run on the board's side of the cable: a
// wearer thread steps the elastic sheet on its body and has
// stretch_array_sim::BoardSimulator measure each plan (resistances,
// parasitics, rows at their own instants, 555 jitter, counter), one or two
// plans ahead of the clock; the emulator server's thread calls the emulator's
// provider at each measurement's instant and serves that row, so the row on
// the wire is what the board measured, less the board's own open-pads
// subtraction (the emulator quantises and flags it). Computing ahead keeps
// the simulator's cost (tens of ms a plan) from stalling the emulated board,
// which would show up as link latency no real board has; on a machine too
// slow for real time the provider waits and reports arrive late. On the host
// the StretchDevice reader thread solves cells and hands each cell frame to a
// reconstruction thread (newest wins: a frame that arrives while one is being
// reconstructed replaces the waiting one, counted as superseded). latest()
// never waits for either: it swaps out a shared pointer under a short lock.
//
// Calibration. As the host would do it: the per-row parasitics from a
// recording of the flat sheet before it is put on (BoardSimulator::
// calibrate_at_rest, then less the board's open-pads value, because the
// board subtracts that itself), and C0 as the mean cell frame over the first
// rest_s seconds of streaming, when the wearer holds still. Until then
// latest() says calibrating.
//
// A real board. Everything after the transport is the same: create_usb()
// reads a stretch board on USB (hidapi, stretch_board_selector(), or one
// hidraw node) with row parasitics the caller recorded with the sheet flat
// (StretchRowMeans + row_parasitics_at_rest in stretch_array_reader.hpp;
// there is no file format for them yet), and takes C0 over the first rest_s
// seconds after start(). It has no truth. Tested only without a board (the
// link keeps trying and latest() says so); not run against hardware.
//
// The truth. For a simulated wearer the emulator thread also records the
// sheet's true reconstruction-mesh vertices (material points, as sim-array
// writes them) several times per board frame; the reconstruction thread
// interpolates them at each frame's newest measurement and reports the mean
// vertex error. Only for display: the reconstruction never sees them.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/stretch_array_sim/array_electrical.hpp"

// Only this module's public dependencies (core, stretch_array_sim) are named
// here: the board, HID and reconstruction types stay in the source file.
namespace proprio::stretch_array_recon {
struct ReconMesh;
}

namespace proprio::stretch_array_eval {

// The cable comes out at at_ns (board time: 0 = start()) for duration_ns:
// the host's handle dies and the board loses power and boots again.
struct ArrayLiveOutage {
  TimeNs at_ns = 0;
  DurationNs duration_ns = 0;
};

struct ArrayLiveOptions {
  std::string layout_file;  // empty: prototype_92 (biceps: biceps_144), as sim-array
  std::string motion = "elbow";  // balloon | biceps | elbow | wrist | forearm
  // The regressor: an .onnx file, or a folder holding model.onnx (`proprio
  // train array`'s OUT/dnn) or dnn/model.onnx (its OUT).
  std::filesystem::path model;
  double frame_rate_hz = 8.0;  // full measurement plans per second (the board's rate is this times the rows)
  int mechanics_steps_per_frame = 4;
  double rest_s = 1.0;     // the wearer holds still this long from the start: C0 is taken there
  int truth_samples_per_frame = 8;  // true vertices recorded per board frame (display only)
  std::uint64_t seed = 1;
  stretch_array_sim::BoardOptions board;  // effects; timing.row_rate_hz is set from the rate
  std::vector<ArrayLiveOutage> unplugs;
  // The fake cable: each report arrives this long after it left the board
  // (a floor plus a uniform extra up to the jitter), as StretchServeOptions.
  DurationNs cable_latency_min_ns = 200'000;
  DurationNs cable_latency_jitter_ns = 800'000;
  // The host's driver (StretchDeviceOptions): how long one read waits (and
  // so how long stop() may take) and the reconnect backoff.
  DurationNs read_timeout_ns = 100 * kNsPerMillisecond;
  DurationNs reconnect_backoff_min_ns = 50 * kNsPerMillisecond;
  DurationNs reconnect_backoff_max_ns = 2 * kNsPerSecond;
  int arap_iterations = 4;  // local-global iterations per frame (ArrayReconstructorOptions)
  // The rest mesh S^0 ARAP deforms: wrapped on a cylinder of the body's
  // nominal rest radius (rest_shape(); what sim-array datasets carry and
  // `proprio bench array` deforms), or the flat sheet.
  bool wrapped_rest_shape = true;

  Status validate() const;
  std::string describe() const;
};

// Where the regressor file of `model` is (the rules of ArrayLiveOptions::model).
Result<std::filesystem::path> resolve_array_model(const std::filesystem::path& model);

// One reconstructed frame.
struct ArrayLiveFrame {
  std::uint64_t index = 0;       // reconstructed frames before this one
  TimeNs measured_ns = 0;        // host clock: the newest measurement in the frame
  TimeNs done_ns = 0;            // host clock: when its vertices were ready
  double latency_s = 0.0;        // done - measured
  double reconstruct_ms = 0.0;   // regressor + ARAP
  double regressor_ms = 0.0, arap_ms = 0.0;
  std::vector<Eigen::Vector3d> vertices_m;  // the reconstruction mesh's vertices (the regressor's frame)
  // Simulated wearer only: the true vertices at measured_ns and the mean
  // distance to them (NaN without truth).
  std::vector<Eigen::Vector3d> truth_m;
  double mean_error_m = 0.0;
};

struct ArrayLiveStats {
  std::string link = "stopped";        // the driver's link state: connecting, streaming, disconnected, stopped
  std::uint64_t disconnects = 0;       // times the link went from streaming to disconnected
  std::uint64_t samples = 0;           // measurements the host received
  std::uint64_t cell_frames = 0;       // solved by the read-out
  std::uint64_t frames = 0;            // reconstructed
  std::uint64_t superseded = 0;        // cell frames replaced by a newer one before reconstruction
  std::uint64_t failed = 0;            // reconstructions that errored (the last good vertices stay)
  std::uint64_t rest_frames = 0;       // cell frames averaged into C0
  std::uint64_t epochs = 0;            // board restarts the reader saw
  bool calibrating = true;             // C0 not taken yet
  double latency_mean_s = 0.0, latency_max_s = 0.0;
  double reconstruct_mean_ms = 0.0, reconstruct_max_ms = 0.0;
  double frame_rate_hz = 0.0;          // reconstructed frames per second over the last second
  // The simulated wearer and board (wearer thread): wall time per plan, and
  // how often the emulator had to wait for one (at the start, after a board
  // restart, or a machine too slow for real time).
  double simulate_mean_ms = 0.0, simulate_max_ms = 0.0;
  std::uint64_t board_waits = 0;
  std::string last_error;              // the newest failure (provider, reconstruction, calibration), empty if none
  std::string describe() const;
};

struct ArrayLiveSnapshot {
  std::shared_ptr<const ArrayLiveFrame> frame;  // null until the first reconstruction
  ArrayLiveStats stats;
};

class ArrayLiveSource {
 public:
  // Builds the layout, meshes, body, sheet, board, emulator and reconstructor
  // and calibrates (flat sheet) without starting any thread. Errors name what
  // is wrong (layout, model sizes, options).
  static Result<std::unique_ptr<ArrayLiveSource>> create_simulated(const ArrayLiveOptions& options);
  // A board on USB: options' layout_file (or the motion's shipped layout),
  // model, rest_s, driver and ARAP settings apply; the wearer, board and
  // unplug settings do not. row_parasitic_pf: per plan row (pF, after the
  // board's own subtraction), empty for none. hid_path: a hidraw node, or
  // empty for the first stretch board found.
  static Result<std::unique_ptr<ArrayLiveSource>> create_usb(const ArrayLiveOptions& options,
                                                            std::vector<double> row_parasitic_pf,
                                                            const std::string& hid_path = {});
  ~ArrayLiveSource();  // stop()s
  ArrayLiveSource(const ArrayLiveSource&) = delete;
  ArrayLiveSource& operator=(const ArrayLiveSource&) = delete;

  // Starts the board (time zero now), the reader and the reconstruction thread.
  Status start();
  // Joins every thread; within about the device's read timeout.
  void stop();

  // Any thread, never blocks on the pipeline.
  ArrayLiveSnapshot latest() const;

  // The reconstruction mesh (triangles for drawing) and the rest mesh.
  const stretch_array_recon::ReconMesh& mesh() const noexcept;
  std::size_t vertex_count() const noexcept;
  std::size_t cell_count() const noexcept;
  std::size_t marker_count() const noexcept;
  // Host time of the board's time zero (valid after start(); USB: when start() was called).
  TimeNs time_zero_ns() const;

  struct Impl;

 private:
  explicit ArrayLiveSource(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace proprio::stretch_array_eval
