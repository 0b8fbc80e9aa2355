#pragma once
// Stretch-array datasets (issue 30): what `proprio sim-array` writes and
// `proprio train array` (tools/stretch_array) and `proprio bench array` read.
// A directory of .npy files and a meta.json written last, whose presence marks
// a complete dataset (format in docs/stretch-arrays.md):
//   cells.npy          float32 [N, C]     each cell's C/C0 from the read-out (the regressor's input)
//   markers.npy        float32 [N, M, 3]  labelled mocap markers, metres, body frame (the training target)
//   markers_truth.npy  float32 [N, M, 3]  the true marker positions (evaluation only)
//   vertices_truth.npy float32 [N, V, 3]  the reconstruction mesh's vertices, true (evaluation only)
//   pose.npy           float32 [N]        the motion's pose value (e.g. wrist angle, degrees)
//   session.npy        int32   [N]        index into meta.sessions
// Frames are in session order. Frames whose markers could not all be
// labelled are not in the dataset; each session counts them.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "proprio/core/file_io.hpp"
#include "proprio/core/npy_file.hpp"
#include "proprio/core/result.hpp"

namespace proprio::stretch_array_eval {

inline constexpr const char* kArrayDatasetFormat = "proprio-stretch-array-dataset";
inline constexpr int kArrayDatasetVersion = 1;

struct ArrayDatasetShape {
  std::string layout;
  std::vector<std::string> cell_names;
  std::vector<std::string> marker_names;
  std::size_t mesh_vertex_count = 0;
  double frame_rate_hz = 8.0;
  std::string pose_name;  // what pose.npy holds, with its unit
  // The rest shape S^0 the reconstruction deforms: the flat sheet wrapped on a
  // cylinder of this radius (the body's nominal size), 0 for flat.
  double rest_radius_m = 0.0;
};

struct ArrayDatasetSession {
  std::string name;    // "wrist-train-0"
  std::string motion;  // balloon | biceps | elbow | wrist | forearm | flat
  int donning = 0;
  std::string split = "train";  // train | test
  std::size_t frames_dropped = 0;  // frames with markers the labelling could not assign
  std::vector<float> cells;           // frames x C
  std::vector<float> markers;         // frames x M x 3
  std::vector<float> markers_truth;   // frames x M x 3
  std::vector<float> vertices_truth;  // frames x V x 3
  std::vector<float> pose;            // frames
  std::size_t frames() const noexcept { return pose.size(); }
};

class ArrayDatasetWriter {
 public:
  // Locks the folder against a second writer; refuses a folder that already
  // holds a dataset unless overwrite.
  static Result<ArrayDatasetWriter> create(const std::filesystem::path& dir, ArrayDatasetShape shape, bool overwrite);
  Status add_session(const ArrayDatasetSession& session);
  // generator_json: a JSON object saying how the data was made (tool, options, seed).
  Status finish(const std::string& generator_json);
  std::size_t frames() const noexcept { return frames_; }

 private:
  ArrayDatasetWriter() = default;
  struct SessionMeta {
    std::string name, motion, split;
    int donning;
    std::size_t first_frame, frames, dropped;
  };
  std::filesystem::path dir_;
  FolderLock lock_;
  ArrayDatasetShape shape_;
  std::vector<NpyWriter> writers_;  // cells, markers, markers_truth, vertices_truth, pose, session
  std::vector<SessionMeta> sessions_;
  std::size_t frames_ = 0;
  bool finished_ = false;
};

// A dataset read back, every array checked against meta.json and for
// non-finite values.
struct ArrayDataset {
  ArrayDatasetShape shape;
  struct Session {
    std::string name, motion, split;
    int donning = 0;
    std::size_t first_frame = 0, frames = 0, frames_dropped = 0;
  };
  std::vector<Session> sessions;
  NpyArray cells, markers, markers_truth, vertices_truth, pose, session;
  std::size_t frames() const noexcept { return pose.rows(); }
};
Result<ArrayDataset> load_array_dataset(const std::filesystem::path& dir);

const std::vector<std::string>& array_dataset_file_names();  // meta.json last

}  // namespace proprio::stretch_array_eval
