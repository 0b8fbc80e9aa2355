#pragma once
// Training datasets for the stretch-glove pose network, as NumPy .npy files
// (NPY format 1.0, written here: magic, a header dict, little-endian data),
// so Python reads them with numpy.load and nothing else.
//
// A dataset is a directory:
//   meta.json        layout name, cell_count, frame_rate_hz, output_grid (25
//                    HandDof names or null, row-major), input_grid_index (44
//                    ints: layer * 25 + row * 5 + col), cell_names,
//                    cell_categories, dof_names (20, HandDof order), sessions
//                    [{subject, session, donning, frames, first_frame,
//                    exploration_frames, hand_length_m, hand_width_m}], frames,
//                    units, normalization, generator (how it was made, seed).
//                    Written last: its presence marks a complete dataset.
//   cells.npy        float32 [N, cells]  recovered capacitances (pF), as MatrixReadout outputs them
//   angles.npy       float32 [N, 20]     ground-truth joint angles (rad) at each frame's time
//   session.npy      int32   [N]         index into meta.sessions
//   subject.npy      int32   [N]         subject id
//   phase.npy        uint8   [N]         0 = calibration exploration, 1 = task motion
//   calib_min.npy    float32 [S, cells]  each session's MinMaxCalibration, from its exploration phase
//   calib_max.npy    float32 [S, cells]
// Frames are in session order; each session's frames are contiguous.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/npy_file.hpp"
#include "proprio/core/result.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_glove/calibration.hpp"

namespace proprio::stretch_glove {

using proprio::NpyType;
using proprio::NpyWriter;
using proprio::write_npy;

// One session's frames and its calibration.
struct DatasetSession {
  int subject = 0;
  int session = 0;  // the subject's session number
  int donning = 0;  // each session here is a new donning
  double hand_length_m = 0.0;
  double hand_width_m = 0.0;
  std::vector<float> cells;           // frames x cell_count, pF
  std::vector<float> angles;          // frames x 20, rad
  std::vector<std::uint8_t> phase;    // frames; 0 exploration, 1 task
  MinMaxCalibration calibration;

  std::size_t frames() const noexcept { return phase.size(); }
};

class DatasetWriter {
 public:
  // Refuses a directory that already holds a dataset unless overwrite (which
  // replaces only the dataset's own files).
  static Result<DatasetWriter> create(const std::filesystem::path& dir, const StretchGloveLayout& layout,
                                      double frame_rate_hz, bool overwrite);
  Status add_session(const DatasetSession& session);
  // generator_json: a JSON object saying how the data was made (tool,
  // options, seed), stored as meta.json's "generator".
  Status finish(const std::string& generator_json);

  std::size_t frames() const noexcept { return frames_; }
  std::size_t session_count() const noexcept { return sessions_.size(); }
  const std::filesystem::path& directory() const noexcept { return dir_; }

 private:
  DatasetWriter() = default;
  struct SessionMeta {
    int subject, session, donning;
    std::size_t frames, first_frame, exploration_frames;
    double hand_length_m, hand_width_m;
  };
  std::filesystem::path dir_;
  StretchGloveLayout layout_;
  double frame_rate_hz_ = 60.0;
  std::vector<NpyWriter> writers_;  // cells, angles, session, subject, phase
  std::vector<float> calib_min_, calib_max_;
  std::vector<SessionMeta> sessions_;
  std::size_t frames_ = 0;
  bool finished_ = false;
};

// The files a dataset consists of (meta.json last).
const std::vector<std::string>& dataset_file_names();

}  // namespace proprio::stretch_glove
