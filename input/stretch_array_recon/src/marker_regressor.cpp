#include "proprio/stretch_array_recon/marker_regressor.hpp"

#include <cmath>
#include <cstring>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include "proprio/core/file_io.hpp"

namespace proprio::stretch_array_recon {
namespace marker_regressor_impl {

constexpr const char* kMakeHint =
    "write it again with the exporter (tests/data/stretch_array_recon/make_models.py shows the contract)";

std::filesystem::path sidecar_path_of(const std::filesystem::path& onnx) {
  std::filesystem::path p = onnx;
  p.replace_extension(".json");
  return p;
}

}  // namespace marker_regressor_impl
using namespace marker_regressor_impl;

Status MarkerRegressorOptions::validate() const {
  if (opencv_threads < 0)
    return make_error(Errc::invalid_argument, "opencv_threads must be >= 0 (0: leave OpenCV alone)");
  return {};
}

std::string MarkerRegressorOptions::describe() const {
  return "opencv_threads=" + (opencv_threads > 0 ? std::to_string(opencv_threads) : std::string("unchanged")) +
         " require_sidecar=" + (require_sidecar ? "yes" : "no");
}

Result<RegressorSidecar> RegressorSidecar::parse(const std::string& json_text, const std::string& source_name) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(json_text);
  } catch (const nlohmann::json::parse_error& e) {
    return make_error(Errc::parse_error, source_name + ": not valid JSON (" + e.what() + ")");
  }
  if (!j.is_object()) return make_error(Errc::parse_error, source_name + ": expected a JSON object");
  if (j.contains("format") && j["format"] != "proprio-stretch-array-regressor") {
    return make_error(Errc::parse_error,
                      source_name + ": 'format' is " + j["format"].dump() +
                          ", expected \"proprio-stretch-array-regressor\" (is this a regressor sidecar?)");
  }
  RegressorSidecar s;
  for (const char* key : {"cell_count", "marker_count"}) {
    if (!j.contains(key) || !j[key].is_number_unsigned() || j[key].get<std::uint64_t>() == 0 ||
        j[key].get<std::uint64_t>() > 100000) {
      return make_error(Errc::parse_error, source_name + ": '" + key + "' must be an integer 1..100000");
    }
  }
  s.cell_count = j["cell_count"].get<std::size_t>();
  s.marker_count = j["marker_count"].get<std::size_t>();
  if (j.contains("kind")) {
    if (!j["kind"].is_string()) return make_error(Errc::parse_error, source_name + ": 'kind' must be a string");
    s.kind = j["kind"].get<std::string>();
    if (s.kind != "dnn" && s.kind != "lr" && s.kind != "svm") {
      return make_error(Errc::parse_error,
                        source_name + ": 'kind' is \"" + s.kind + "\", expected \"dnn\", \"lr\" or \"svm\"");
    }
  }
  return s;
}

struct MarkerRegressor::Impl {
  std::filesystem::path path;
  MarkerRegressorOptions options;
  std::string kind;
  std::size_t cells = 0, markers = 0;
  cv::dnn::Net net;
  cv::Mat input;
};

MarkerRegressor::MarkerRegressor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MarkerRegressor::MarkerRegressor(MarkerRegressor&&) noexcept = default;
MarkerRegressor& MarkerRegressor::operator=(MarkerRegressor&&) noexcept = default;
MarkerRegressor::~MarkerRegressor() = default;

Result<MarkerRegressor> MarkerRegressor::load(const std::filesystem::path& onnx_path, std::size_t expected_cells,
                                              std::size_t expected_markers, const MarkerRegressorOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  const std::string where = onnx_path.string();
  // The thesis-sized network is ~40 MB; 512 MiB bounds a wrong file.
  auto bytes = read_input_file(onnx_path, "regressor model (.onnx)", 512 * kMiB);
  if (!bytes) return bytes.error();
  if (bytes->empty()) return make_error(Errc::parse_error, where + ": empty file; " + kMakeHint);

  auto impl = std::make_unique<Impl>();
  impl->path = onnx_path;
  impl->options = options;
  impl->cells = expected_cells;
  impl->markers = expected_markers;
  const std::filesystem::path sc_path = sidecar_path_of(onnx_path);
  std::error_code ec;
  if (std::filesystem::exists(sc_path, ec)) {
    auto text = read_input_file(sc_path, "regressor sidecar (.json)", 16 * kMiB);
    if (!text) return text.error();
    auto sc = RegressorSidecar::parse(*text, sc_path.string());
    if (!sc) return sc.error();
    impl->kind = sc->kind;
    auto check = [&](std::size_t& expected, std::size_t got, const char* what) -> Status {
      if (expected == 0) expected = got;
      if (expected != got) {
        return make_error(Errc::invalid_argument, sc_path.string() + ": the model is for " + std::to_string(got) + " " +
                                                      what + ", this sensor has " + std::to_string(expected) +
                                                      "; use a model trained for this layout and marker set");
      }
      return {};
    };
    if (Status s = check(impl->cells, sc->cell_count, "cells"); !s) return s.error();
    if (Status s = check(impl->markers, sc->marker_count, "markers"); !s) return s.error();
  } else if (options.require_sidecar || expected_cells == 0 || expected_markers == 0) {
    return make_error(
        Errc::not_found,
        where + ": its sidecar " + sc_path.string() +
            " is missing (it names the cell and marker counts; the exporter writes it next to the .onnx)");
  }

  if (options.opencv_threads > 0) cv::setNumThreads(options.opencv_threads);
  try {
    impl->net = cv::dnn::readNetFromONNX(bytes->data(), bytes->size());
  } catch (const cv::Exception& e) {
    return make_error(Errc::parse_error, where + ": OpenCV cannot read it as an ONNX model (" + e.err +
                                             "): the file is corrupt, truncated or not ONNX; " + kMakeHint);
  }
  if (impl->net.empty()) return make_error(Errc::parse_error, where + ": OpenCV read no layers from it; " + kMakeHint);
  impl->net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  impl->net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);

  // Dry run with every ratio 1 (the rest state): the shapes, and OpenCV
  // allocates its buffers now rather than on the first frame.
  impl->input = cv::Mat(1, static_cast<int>(impl->cells), CV_32F, cv::Scalar(1.0f));
  const std::string expected = "the network must take input 'cells' [1, " + std::to_string(impl->cells) +
                               "] float32 and give [1, " + std::to_string(3 * impl->markers) + "] (3 x " +
                               std::to_string(impl->markers) + " markers)";
  cv::Mat out;
  try {
    impl->net.setInput(impl->input, "cells");
    out = impl->net.forward();
  } catch (const cv::Exception& e) {
    return make_error(Errc::unsupported, where + ": a dry run failed (OpenCV: " + e.err + "); " + expected);
  }
  if (out.depth() != CV_32F || out.total() != 3 * impl->markers || !out.isContinuous()) {
    std::string dims;
    for (int d = 0; d < out.dims; ++d) dims += (d ? ", " : "") + std::to_string(out.size[d]);
    return make_error(Errc::unsupported, where + ": the output has shape [" + dims + "]; " + expected);
  }
  for (std::size_t k = 0; k < out.total(); ++k) {
    if (!std::isfinite(out.ptr<float>()[k])) {
      return make_error(Errc::parse_error,
                        where + ": the network outputs NaN or infinity at rest (corrupt weights?); " + kMakeHint);
    }
  }
  return MarkerRegressor(std::move(impl));
}

Status MarkerRegressor::predict(const Eigen::VectorXd& cells, Eigen::MatrixX3d& markers_m) {
  Impl& m = *impl_;
  if (static_cast<std::size_t>(cells.size()) != m.cells) {
    return make_error(Errc::invalid_argument, "regressor: " + std::to_string(cells.size()) +
                                                  " cell ratios, the model takes " + std::to_string(m.cells));
  }
  for (Eigen::Index i = 0; i < cells.size(); ++i) {
    if (!std::isfinite(cells(i))) {
      return make_error(Errc::invalid_argument, "regressor: cell " + std::to_string(i) +
                                                    " is NaN or infinite (a failed read-out?); skip the frame");
    }
    m.input.ptr<float>()[i] = static_cast<float>(cells(i));
  }
  cv::Mat out;
  try {
    m.net.setInput(m.input, "cells");
    out = m.net.forward();
  } catch (const cv::Exception& e) {
    return make_error(Errc::unsupported, m.path.string() + ": inference failed (OpenCV: " + e.err + ")");
  }
  markers_m.resize(static_cast<Eigen::Index>(m.markers), 3);
  const float* o = out.ptr<float>();
  for (std::size_t k = 0; k < m.markers; ++k) {
    for (int c = 0; c < 3; ++c) {
      const float v = o[3 * k + static_cast<std::size_t>(c)];
      if (!std::isfinite(v))
        return make_error(Errc::out_of_range, "regressor: marker " + std::to_string(k) + " came out NaN or infinite");
      markers_m(static_cast<Eigen::Index>(k), c) = v;
    }
  }
  return {};
}

std::size_t MarkerRegressor::cell_count() const noexcept { return impl_->cells; }
std::size_t MarkerRegressor::marker_count() const noexcept { return impl_->markers; }
const std::string& MarkerRegressor::kind() const noexcept { return impl_->kind; }

std::string MarkerRegressor::describe() const {
  return impl_->path.string() + ": " + (impl_->kind.empty() ? std::string("regressor") : impl_->kind) + ", " +
         std::to_string(impl_->cells) + " cells -> " + std::to_string(impl_->markers) + " markers; " +
         impl_->options.describe();
}

}  // namespace proprio::stretch_array_recon
