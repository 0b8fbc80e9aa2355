#pragma once
// The regressor g_theta (Glauser 2019, Sec. 4.4.2, Fig. 4.13): cell
// capacitance ratios in, marker vertex positions out, run from an ONNX file
// through OpenCV DNN (as the stretch glove runs its pose network).
//
// Contract. Input "cells": float32 [1, C], the cells' C/C0 (any
// normalisation is inside the model). Output: float32 [1, 3M], metres,
// marker-major (x, y, z of marker 0 first), the network's last output.
// An optional sidecar NAME.json next to NAME.onnx:
//   {"format": "proprio-stretch-array-regressor", "cell_count": C,
//    "marker_count": M, "kind": "dnn" | "lr" | "svm", ...}
// load() checks the sidecar against the sizes the caller expects and a dry
// run against both; tests/data/stretch_array_recon/make_models.py writes
// such files.
//
// Threads: one MarkerRegressor per thread (OpenCV's Net keeps per-forward
// state). load() sets OpenCV to one thread by default (process-wide, see
// stretch_glove/onnx_pose_model.hpp for why).
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include <Eigen/Core>

#include "proprio/core/result.hpp"

namespace proprio::stretch_array_recon {

struct MarkerRegressorOptions {
  int opencv_threads = 1;  // > 0: cv::setNumThreads (process-wide); 0: leave it
  bool require_sidecar = false;
  Status validate() const;
  std::string describe() const;
};

struct RegressorSidecar {
  std::size_t cell_count = 0, marker_count = 0;
  std::string kind;  // "dnn", "lr", "svm"
  static Result<RegressorSidecar> parse(const std::string& json_text, const std::string& source_name);
};

class MarkerRegressor {
 public:
  // expected_cells / expected_markers: 0 takes them from the sidecar (which
  // is then required).
  static Result<MarkerRegressor> load(const std::filesystem::path& onnx_path, std::size_t expected_cells,
                                      std::size_t expected_markers, const MarkerRegressorOptions& options = {});
  MarkerRegressor(MarkerRegressor&&) noexcept;
  MarkerRegressor& operator=(MarkerRegressor&&) noexcept;
  ~MarkerRegressor();

  // cells: C ratios; markers_m: resized to M x 3. Refuses NaN/inf inputs
  // and non-finite outputs.
  Status predict(const Eigen::VectorXd& cells, Eigen::MatrixX3d& markers_m);

  std::size_t cell_count() const noexcept;
  std::size_t marker_count() const noexcept;
  const std::string& kind() const noexcept;  // from the sidecar, or empty
  std::string describe() const;

 private:
  struct Impl;
  explicit MarkerRegressor(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace proprio::stretch_array_recon
