#pragma once
// Simulated stretch-array sessions written as a dataset (`proprio sim-array`;
// format: array_dataset.hpp), through the whole chain a real capture has:
//   body proxy -> elastic sheet on it (elastic_sheet) -> what the board
//   measures, rows at their own instants, resistances, parasitics, 555 jitter
//   and counter (stretch_array_sim::BoardSimulator) -> the wire's 1 fF
//   quantisation -> parasitic subtraction and the least-squares read-out
//   (stretch_array::MatrixReadout) -> C/C0 against the session's rest frames
// and, for the training target, the markers through a simulated optical
// system (occlusion, new labels, swaps, ghosts) and the semi-automatic
// labelling (stretch_array_recon::label_markers). Frames the labelling could
// not complete are dropped and counted, as the thesis did.
//
// Each session is one donning: rest_s seconds at rest (the host takes C0
// there), then the motion. Session 0 of each split uses the nominal placement;
// a re-donned test session (redonned_test) puts the sheet on a few mm and
// degrees off. Sessions run on worker threads; the same seed gives the same
// bytes whatever the thread count.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_array_sim/array_electrical.hpp"
#include "proprio/stretch_array_sim/mocap.hpp"

namespace proprio::stretch_array_eval {

struct SimArrayOptions {
  std::string layout_file;        // empty: prototype_92 (biceps: biceps_144, the thesis's larger sleeve)
  std::string motion = "wrist";   // balloon | biceps | elbow | wrist | forearm
  int train_sessions = 1;
  double train_minutes = 4.0;     // per training session
  int test_sessions = 1;
  double test_minutes = 1.5;      // per test session
  bool redonned_test = true;      // one more test session, the sleeve put on again a little off
  double frame_rate_hz = 8.0;     // full measurement plans per second (the thesis: 8 Hz)
  int mechanics_steps_per_frame = 4;
  double rest_s = 1.0;            // still at the start of each session: C0 is taken there
  std::uint64_t seed = 1;
  stretch_array_sim::BoardOptions board;  // effects; board.timing.row_rate_hz is set from frame_rate_hz
  // The optical system runs at the frame rate here; occlusion is given in
  // time and turned into the simulator's per-frame chain: a marker is out of
  // sight this share of the time, for stretches of this mean length.
  stretch_array_sim::MocapOptions mocap;
  double occluded_share = 0.01;
  double mean_occlusion_s = 0.5;
  std::string out;
  bool force = false;
  int threads = 0;  // 0: one per core
  std::string tool = "proprio sim-array";
  std::string version;

  Status validate() const;
  std::string describe() const;
  double total_simulated_minutes() const;
};

struct SimArraySessionReport {
  std::string name;
  std::size_t frames = 0, frames_dropped = 0;
  std::size_t labels_seen = 0, labels_outlier = 0;
  double max_area_stretch = 0.0;  // the largest cell C/C0 seen (ideal)
  std::size_t damaged_cells = 0;  // over-stretched beyond the damage limit
  std::string most_missing;       // the markers most often without a label, with the share of frames
  double elapsed_s = 0.0;
};

struct SimArrayReport {
  std::size_t frames = 0, frames_dropped = 0;
  std::vector<SimArraySessionReport> sessions;
  double elapsed_s = 0.0;
  std::size_t threads = 0;
  std::string describe() const;
};

struct SimArrayCallbacks {
  std::function<void(double simulated_minutes_done)> on_progress;  // from the calling thread
};

// The array a motion is captured with: the layout file when one is given,
// else the thesis's sensors' stand-ins (biceps_144 for the biceps, prototype_92
// otherwise), checked to be readable.
Result<stretch_array::StripArrayLayout> layout_for_motion(const std::string& layout_file, const std::string& motion);

Result<SimArrayReport> write_sim_array_dataset(const SimArrayOptions& options, const SimArrayCallbacks& callbacks = {});

}  // namespace proprio::stretch_array_eval
