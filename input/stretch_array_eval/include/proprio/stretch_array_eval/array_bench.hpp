#pragma once
// `proprio bench array`: the stretch array's accuracy and speed on simulated
// data (issue 30). Each case says whether it ran; a case that did not run has
// no numbers. Simulated accuracy is not real-world accuracy.
//   uniaxial     a 15 x 50 mm cell in the middle of a 15 x 100 mm strip on a
//                linear stage (elastic_sheet's UniaxialStretchRig), read by
//                the board simulator with its resistances, parasitics, jitter
//                and counter; the length ratio recovered by eq. 4.2
//                (l/l0 = C/C0) against the cell's true length. The thesis:
//                0.0096 mean relative length error.
//   string_pull  a flat prototype_92 sheet pulled by strings
//                (StringPullRig), read through the whole read-out (rows at
//                their instants, the wire, parasitic subtraction, least
//                squares); each cell's C/C0 against eq. 4.8 of the true
//                triangle areas. The thesis: 7.7 % mean relative error.
//   dataset      a trained model (ONNX through OpenCV DNN) on a dataset's
//                test sessions: marker error against the true markers, and
//                the dense vertex error of the ARAP-deformed rest mesh
//                against the true sheet (which the thesis could not measure).
//   speed        one frame from readings to the deformed mesh: read-out
//                solve, regressor, ARAP, on one core.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array_sim/array_electrical.hpp"

namespace proprio::stretch_array_eval {

struct ErrorStats {
  std::size_t samples = 0;
  double mean = 0.0, std = 0.0, p95 = 0.0, max = 0.0;
  static ErrorStats of(std::vector<double> values);
};

struct UniaxialResult {
  double max_stretch = 0.0;
  std::size_t stage_positions = 0;
  ErrorStats relative_length_error;         // |l_est - l| / l
  ErrorStats relative_length_error_ideal;   // the same through an ideal board (model and solver only)
  double width_ratio_at_max = 0.0;          // the strip's mid width over its rest width at the largest stage stretch
};

struct StringPullResult {
  std::string layout;
  std::size_t frames = 0, cells = 0;
  double max_area_ratio = 0.0;
  ErrorStats relative_error;        // |C/C0 measured - eq. 4.8| / eq. 4.8, per cell and frame
  ErrorStats relative_error_ideal;  // through an ideal board
  ErrorStats relative_error_stretched;  // only cells whose eq. 4.8 ratio is above 1.05
};

// One model on one test session of a dataset.
struct ModelSessionResult {
  std::string model_kind;  // dnn | lr | svm (from its sidecar), or the file name
  std::string session;
  int donning = 0;
  std::size_t frames = 0;
  ErrorStats marker_error_mm;          // the regressor's markers against the true ones
  ErrorStats marker_error_labelled_mm; // against the labelled mocap (what the thesis could measure)
  ErrorStats vertex_error_mm;          // the ARAP-deformed mesh against the true sheet, every vertex
  ErrorStats regressor_ms, arap_ms;    // per frame, one core
};

struct DatasetBenchOptions {
  std::string dataset;      // a sim-array dataset folder
  std::string models;       // a folder with <kind>/model.onnx (train array --out), or one .onnx file
  std::string layout_file;  // when the dataset's layout is not a shipped one
  Status validate() const;
};

struct SpeedResult {
  std::string layout;
  std::size_t cells = 0, rows = 0, vertices = 0, markers = 0;
  ErrorStats solve_ms, regressor_ms, arap_ms, total_ms;  // per frame
  std::string model;
};

struct BenchArrayOptions {
  bool uniaxial = true;
  bool string_pull = true;
  double uniaxial_max_stretch = 1.6;
  int uniaxial_positions = 25;  // stage positions up and down again
  double string_pull_seconds = 30.0;
  double frame_rate_hz = 8.0;
  std::uint64_t seed = 1;
  stretch_array_sim::BoardOptions board;  // effects of the board (resistances on, as the target asks)
  Status validate() const;
};

struct BenchArrayReport {
  std::optional<UniaxialResult> uniaxial;
  std::optional<StringPullResult> string_pull;
  std::vector<ModelSessionResult> dataset;  // empty: not run
  std::string dataset_name;
  std::optional<SpeedResult> speed;
  std::string json() const;
  std::string describe() const;
};

Result<UniaxialResult> bench_uniaxial(const BenchArrayOptions& options);
Result<StringPullResult> bench_string_pull(const BenchArrayOptions& options);
// Every model of `models` on every test session of the dataset, through the
// live pipeline's code (OpenCV DNN, ARAP). The speed case times the first
// model (the DNN when there is one) with the read-out's solve on the
// dataset's layout.
Result<std::vector<ModelSessionResult>> bench_dataset(const DatasetBenchOptions& options,
                                                      std::optional<SpeedResult>* speed = nullptr);

}  // namespace proprio::stretch_array_eval
