#pragma once
// The stretch glove's pose network (Glauser 2019, sec. 5.3.2), run from an
// ONNX file through OpenCV's DNN module. The network reads the normalised
// cells on the 2 x 5 x 5 input grid (NCHW float32, layer 0 = "along" cells,
// layer 1 = "across" cells, empty slots 0; calibration.hpp fills it) and
// writes joint angles in radians on the 5 x 5 output grid of the layout
// (StretchGloveLayout::output_grid; empty cells are meaningless).
//
// Models come from tools/stretch_glove/train.py (README there), which writes
// NAME.onnx plus a sidecar NAME.json: the grids the model was trained on, the
// normalisation, the model kind and its training summary. load() reads the
// sidecar when it is there and, given a layout, refuses a model trained for
// other grids: a model fed the wrong cells outputs plausible-looking nonsense.
//
// Threads. One OnnxPoseModel is used by one thread at a time (OpenCV's Net
// keeps per-forward state). Inference on these tiny inputs is 2-4x slower with
// OpenCV's worker threads than without, so load() sets OpenCV to one thread
// by default (Options::opencv_threads). cv::setNumThreads is process-wide: it
// also affects every other OpenCV user in the process (e.g. marker detection).
//
// Hot path. infer() reuses its input blob, copies 50 floats in and 25 out,
// and does not throw. It is not allocation-free: OpenCV 4.6's Net::forward
// builds small per-layer bookkeeping vectors on every call (measured with
// malloc interposition: about 200 malloc calls per U-Net frame, 75 per FCN
// frame; setInput adds 4). Avoiding that would need a hand-written inference
// engine, which Proprio does not want; so run inference on the tracker's own
// thread, never in the 1 kHz haptics loop.
#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/hand_model.hpp"
#include "proprio/core/result.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"

namespace proprio::stretch_glove {

inline constexpr int kPoseInputLayers = 2;
inline constexpr std::size_t kPoseInputSize = kPoseInputLayers * kStretchGridSize * kStretchGridSize;  // 50
inline constexpr std::size_t kPoseOutputSize = kStretchGridSize * kStretchGridSize;                    // 25

struct OnnxPoseModelOptions {
  // > 0: load() calls cv::setNumThreads(opencv_threads) (process-wide, see
  // the top of this file). 0: leave OpenCV's thread setting alone.
  int opencv_threads = 1;
  // Without a sidecar NAME.json, fail (true) or load the bare ONNX file
  // unchecked (false).
  bool require_sidecar = false;
  // Tensor names, used when the sidecar does not name them.
  std::string input_name = "stretch";
  std::string output_name = "pose";

  Status validate() const;
  std::string describe() const;
};

// What the sidecar NAME.json says (tools/stretch_glove/README.md has the format).
struct PoseModelSidecar {
  std::string layout_name;  // the layout the training data came from
  int cell_count = 0;
  std::vector<int> input_grid_index;  // per cell: layer * 25 + row * 5 + col
  std::array<std::optional<HandDof>, kStretchGridSize * kStretchGridSize> output_grid{};
  std::string input_name = "stretch";
  std::string output_name = "pose";
  std::string model_kind;  // "unet", "fcn"
  std::int64_t parameters = 0;
  // "session": inputs normalised with the wearer's own min-max calibration;
  // "global": with min-max over the training data (global_min_pf/max_pf).
  std::string calibration = "session";
  std::vector<float> global_min_pf;
  std::vector<float> global_max_pf;
  std::uint64_t seed = 0;
  double validation_mean_deg = -1.0;  // < 0: not recorded
  std::string torch_version;
  int opset = 0;
  // CRC-32 (zlib's) of the .onnx file as exported: catches weights damaged
  // in a way that still parses.
  std::optional<std::uint32_t> onnx_crc32;

  static Result<PoseModelSidecar> parse(const std::string& json_text, const std::string& source_name);
  static Result<PoseModelSidecar> load(const std::filesystem::path& path);
  // Errc::invalid_argument naming the first difference when the model was
  // trained on other grids than `layout` has.
  Status check_against(const StretchGloveLayout& layout, const std::string& source_name) const;
};

// NAME.onnx -> NAME.json
std::filesystem::path sidecar_path_for(const std::filesystem::path& onnx_path);

// Process-wide cv::setNumThreads(threads) (what Options::opencv_threads does).
void set_opencv_threads(int threads);

class OnnxPoseModel {
 public:
  using Options = OnnxPoseModelOptions;

  // Reads the ONNX file and its sidecar (if there), then runs one dry
  // inference to check that the network takes [1, 2, 5, 5] and gives 25
  // values. Errors: Errc::not_found (no file), Errc::parse_error (not a
  // readable ONNX model or sidecar, with OpenCV's reason), Errc::unsupported
  // (a network with other tensor shapes or names).
  static Result<OnnxPoseModel> load(const std::filesystem::path& onnx_path, const Options& options = {});
  // As above, and the sidecar's grids must match `layout` (a model without a
  // sidecar is accepted unchecked unless options.require_sidecar).
  static Result<OnnxPoseModel> load(const std::filesystem::path& onnx_path, const StretchGloveLayout& layout,
                                    const Options& options = {});

  OnnxPoseModel(OnnxPoseModel&&) noexcept;
  OnnxPoseModel& operator=(OnnxPoseModel&&) noexcept;
  ~OnnxPoseModel();

  // One frame: input_2x5x5 holds kPoseInputSize floats (NCHW, batch 1),
  // output_5x5 receives kPoseOutputSize angles in radians, row-major on the
  // output grid. false (output zeroed) if OpenCV failed, which a loaded model
  // does not do unless memory runs out.
  bool infer(const float* input_2x5x5, float* output_5x5) noexcept;

  const std::filesystem::path& path() const noexcept;
  const std::optional<PoseModelSidecar>& sidecar() const noexcept;
  std::string describe() const;

 private:
  struct Impl;
  explicit OnnxPoseModel(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace proprio::stretch_glove
