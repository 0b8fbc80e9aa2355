#include "proprio/stretch_glove/onnx_pose_model.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <span>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include "proprio/core/recording.hpp"
#include "proprio/core/file_io.hpp"

namespace proprio::stretch_glove {
namespace {

constexpr int kGridCells = kStretchGridSize * kStretchGridSize;
constexpr const char* kRetrainHint = "export it again with tools/stretch_glove/train.py (see tools/stretch_glove/README.md)";

std::optional<HandDof> dof_from_name(const std::string& name) {
  for (std::size_t i = 0; i < kHandDofCount; ++i) {
    const auto dof = static_cast<HandDof>(i);
    if (to_string(dof) == name) return dof;
  }
  return std::nullopt;
}

std::string grid_entry_name(const std::optional<HandDof>& entry) {
  return entry ? std::string(to_string(*entry)) : std::string("empty");
}

// nlohmann reports a byte offset; users want a line and column.
std::string line_col_of(const std::string& text, std::size_t byte) {
  std::size_t line = 1;
  std::size_t col = 1;
  for (std::size_t i = 0; i < byte && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  return std::to_string(line) + ":" + std::to_string(col);
}

Error sidecar_error(const std::string& source, const std::string& what) {
  return make_error(Errc::parse_error, source + ": " + what);
}

Result<std::vector<std::uint8_t>> read_bytes(const std::filesystem::path& path) {
  // The glove's networks are a few MB; 512 MiB bounds a wrong file.
  auto text = read_input_file(path, "ONNX model", 512 * kMiB);
  if (!text) {
    if (text.error().code != Errc::not_found) return text.error();
    return make_error(Errc::not_found, text.error().message + "; " "train a model with tools/stretch_glove/train.py (see tools/stretch_glove/README.md)");
  }
  return std::vector<std::uint8_t>(text->begin(), text->end());
}

}  // namespace

// ---------------------------------------------------------------------------
// Options

Status OnnxPoseModelOptions::validate() const {
  if (opencv_threads < 0) {
    return make_error(Errc::invalid_argument,
                      "opencv_threads = " + std::to_string(opencv_threads) + ": expected 0 (leave OpenCV alone) or more");
  }
  if (input_name.empty() || output_name.empty()) {
    return make_error(Errc::invalid_argument, "input_name and output_name must not be empty");
  }
  return {};
}

std::string OnnxPoseModelOptions::describe() const {
  std::string s = "opencv_threads=";
  s += opencv_threads > 0 ? std::to_string(opencv_threads) : std::string("unchanged");
  s += " require_sidecar=";
  s += require_sidecar ? "yes" : "no";
  s += " input=" + input_name + " output=" + output_name;
  return s;
}

void set_opencv_threads(int threads) { cv::setNumThreads(threads); }

std::filesystem::path sidecar_path_for(const std::filesystem::path& onnx_path) {
  std::filesystem::path p = onnx_path;
  p.replace_extension(".json");
  return p;
}

// ---------------------------------------------------------------------------
// Sidecar

Result<PoseModelSidecar> PoseModelSidecar::parse(const std::string& json_text, const std::string& source_name) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(json_text);
  } catch (const nlohmann::json::parse_error& e) {
    return sidecar_error(source_name + ":" + line_col_of(json_text, e.byte),
                         "not valid JSON (" + std::string(e.what()) + "); " + kRetrainHint);
  }
  if (!j.is_object()) return sidecar_error(source_name, "expected a JSON object at the top level");

  PoseModelSidecar s;
  try {
    if (j.contains("format") && j["format"] != "proprio-stretch-pose-model") {
      return sidecar_error(source_name, "key 'format' is " + j["format"].dump() +
                                            ", expected \"proprio-stretch-pose-model\" (is this a model sidecar?)");
    }
    for (const char* key : {"cell_count", "input_grid_index", "output_grid"}) {
      if (!j.contains(key)) return sidecar_error(source_name, std::string("missing key '") + key + "'");
    }
    if (!j["cell_count"].is_number_integer() || j["cell_count"].get<int>() <= 0 ||
        j["cell_count"].get<int>() > static_cast<int>(kPoseInputSize)) {
      return sidecar_error(source_name, "key 'cell_count' must be an integer 1.." + std::to_string(kPoseInputSize));
    }
    s.cell_count = j["cell_count"].get<int>();
    s.layout_name = j.value("layout", std::string());

    const auto& gi = j["input_grid_index"];
    if (!gi.is_array() || gi.size() != static_cast<std::size_t>(s.cell_count)) {
      return sidecar_error(source_name, "key 'input_grid_index' must be an array of cell_count (" +
                                            std::to_string(s.cell_count) + ") integers");
    }
    for (std::size_t i = 0; i < gi.size(); ++i) {
      if (!gi[i].is_number_integer() || gi[i].get<int>() < 0 || gi[i].get<int>() >= static_cast<int>(kPoseInputSize)) {
        return sidecar_error(source_name, "input_grid_index[" + std::to_string(i) + "] = " + gi[i].dump() +
                                              ", expected an integer 0.." + std::to_string(kPoseInputSize - 1));
      }
      s.input_grid_index.push_back(gi[i].get<int>());
    }

    const auto& og = j["output_grid"];
    if (!og.is_array() || og.size() != static_cast<std::size_t>(kGridCells)) {
      return sidecar_error(source_name, "key 'output_grid' must be an array of 25 entries (row-major 5x5)");
    }
    for (std::size_t k = 0; k < og.size(); ++k) {
      if (og[k].is_null()) continue;
      if (!og[k].is_string()) {
        return sidecar_error(source_name, "output_grid[" + std::to_string(k) + "] must be a DoF name or null");
      }
      const auto dof = dof_from_name(og[k].get<std::string>());
      if (!dof) {
        return sidecar_error(source_name, "output_grid[" + std::to_string(k) + "] = " + og[k].dump() +
                                              " is not a hand DoF name (e.g. \"index_mcp_flexion\")");
      }
      s.output_grid[k] = dof;
    }

    if (j.contains("input") && j["input"].is_object()) s.input_name = j["input"].value("name", s.input_name);
    if (j.contains("output") && j["output"].is_object()) s.output_name = j["output"].value("name", s.output_name);
    if (j.contains("model") && j["model"].is_object()) {
      s.model_kind = j["model"].value("kind", std::string());
      s.parameters = j["model"].value("parameters", std::int64_t{0});
    }
    if (j.contains("normalisation") && j["normalisation"].is_object()) {
      const auto& n = j["normalisation"];
      s.calibration = n.value("calibration", s.calibration);
      if (s.calibration != "session" && s.calibration != "global") {
        return sidecar_error(source_name, "normalisation.calibration is \"" + s.calibration +
                                              "\", expected \"session\" or \"global\"");
      }
      if (s.calibration == "global") {
        if (!n.contains("global_min_pf") || !n.contains("global_max_pf")) {
          return sidecar_error(source_name, "normalisation.calibration is \"global\" but global_min_pf/global_max_pf are missing");
        }
        s.global_min_pf = n["global_min_pf"].get<std::vector<float>>();
        s.global_max_pf = n["global_max_pf"].get<std::vector<float>>();
        if (s.global_min_pf.size() != static_cast<std::size_t>(s.cell_count) ||
            s.global_max_pf.size() != static_cast<std::size_t>(s.cell_count)) {
          return sidecar_error(source_name, "normalisation.global_min_pf/global_max_pf must hold cell_count values");
        }
        for (int i = 0; i < s.cell_count; ++i) {
          const float lo = s.global_min_pf[static_cast<std::size_t>(i)];
          const float hi = s.global_max_pf[static_cast<std::size_t>(i)];
          if (!std::isfinite(lo) || !std::isfinite(hi) || !(hi > lo)) {
            return sidecar_error(source_name, "normalisation: cell " + std::to_string(i) +
                                                  " needs finite global_min_pf < global_max_pf");
          }
        }
      }
    }
    s.seed = j.value("seed", std::uint64_t{0});
    if (j.contains("validation") && j["validation"].is_object()) {
      s.validation_mean_deg = j["validation"].value("mean_deg", -1.0);
    }
    s.torch_version = j.value("torch_version", std::string());
    if (j.contains("onnx_crc32")) {
      if (!j["onnx_crc32"].is_number_unsigned() || j["onnx_crc32"].get<std::uint64_t>() > 0xffffffffu) {
        return sidecar_error(source_name, "key 'onnx_crc32' must be an unsigned 32-bit integer");
      }
      s.onnx_crc32 = j["onnx_crc32"].get<std::uint32_t>();
    }
    s.opset = j.value("opset", 0);
  } catch (const nlohmann::json::exception& e) {
    return sidecar_error(source_name, std::string("a key has the wrong type (") + e.what() + "); " + kRetrainHint);
  }
  return s;
}

Result<PoseModelSidecar> PoseModelSidecar::load(const std::filesystem::path& path) {
  auto text = read_input_file(path, "model sidecar (.json)", 16 * kMiB);
  if (!text) return text.error();
  return parse(*text, path.string());
}

Status PoseModelSidecar::check_against(const StretchGloveLayout& layout, const std::string& source_name) const {
  const std::string trained_on = layout_name.empty() ? std::string() : " (trained on layout '" + layout_name + "')";
  if (static_cast<std::size_t>(cell_count) != layout.cell_count()) {
    return make_error(Errc::invalid_argument,
                      source_name + ": the model was trained for " + std::to_string(cell_count) + " cells" + trained_on +
                          ", layout '" + layout.name + "' has " + std::to_string(layout.cell_count()) +
                          "; use a model trained on this layout");
  }
  for (std::size_t i = 0; i < layout.cells.size(); ++i) {
    const StretchCell& c = layout.cells[i];
    // The layout's input_grid_index(), spelled out so this check needs nothing but the layout's data.
    const int slot = c.grid_layer * kGridCells + c.grid_row * kStretchGridSize + c.grid_col;
    if (input_grid_index[i] != slot) {
      return make_error(Errc::invalid_argument,
                        source_name + ": input_grid_index[" + std::to_string(i) + "] = " +
                            std::to_string(input_grid_index[i]) + ", but layout '" + layout.name + "' puts cell '" +
                            c.name + "' at " + std::to_string(slot) + ": the model was trained on another glove layout" +
                            trained_on + "; use a model trained on this layout");
    }
  }
  for (std::size_t k = 0; k < output_grid.size(); ++k) {
    if (output_grid[k] != layout.output_grid[k]) {
      return make_error(Errc::invalid_argument,
                        source_name + ": output_grid[" + std::to_string(k) + "] (row " +
                            std::to_string(k / kStretchGridSize) + ", col " + std::to_string(k % kStretchGridSize) +
                            ") is " + grid_entry_name(output_grid[k]) + ", but layout '" + layout.name + "' has " +
                            grid_entry_name(layout.output_grid[k]) + trained_on +
                            "; use a model trained on this layout");
    }
  }
  return {};
}

// ---------------------------------------------------------------------------
// Model

struct OnnxPoseModel::Impl {
  std::filesystem::path path;
  std::optional<PoseModelSidecar> sidecar;
  Options options;
  std::string input_name;
  std::string output_name;
  cv::dnn::Net net;
  cv::Mat input;  // [1, 2, 5, 5], reused every call
};

OnnxPoseModel::OnnxPoseModel(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
OnnxPoseModel::OnnxPoseModel(OnnxPoseModel&&) noexcept = default;
OnnxPoseModel& OnnxPoseModel::operator=(OnnxPoseModel&&) noexcept = default;
OnnxPoseModel::~OnnxPoseModel() = default;

Result<OnnxPoseModel> OnnxPoseModel::load(const std::filesystem::path& onnx_path, const Options& options) {
  if (Status st = options.validate(); !st) return st.error();
  const std::string where = onnx_path.string();

  auto bytes = read_bytes(onnx_path);
  if (!bytes) return bytes.error();
  if (bytes->empty()) return make_error(Errc::parse_error, where + ": empty file; " + kRetrainHint);

  auto impl = std::make_unique<Impl>();
  impl->path = onnx_path;
  impl->options = options;
  impl->input_name = options.input_name;
  impl->output_name = options.output_name;

  const std::filesystem::path sidecar_path = sidecar_path_for(onnx_path);
  std::error_code ec;
  if (std::filesystem::exists(sidecar_path, ec)) {
    auto sc = PoseModelSidecar::load(sidecar_path);
    if (!sc) return sc.error();
    impl->sidecar = std::move(*sc);
    impl->input_name = impl->sidecar->input_name;
    impl->output_name = impl->sidecar->output_name;
  } else if (options.require_sidecar) {
    return make_error(Errc::not_found, where + ": its sidecar " + sidecar_path.string() +
                                           " is missing (train.py writes it next to the .onnx; copy both)");
  }

  // A file whose bytes changed since export still parses when only weights
  // were hit; the sidecar's checksum catches that.
  if (impl->sidecar && impl->sidecar->onnx_crc32) {
    const std::uint32_t want = *impl->sidecar->onnx_crc32;
    const std::uint32_t got = crc32_ieee(std::span<const std::uint8_t>(bytes->data(), bytes->size()));
    if (got != want) {
      char buf[160];
      std::snprintf(buf, sizeof buf, ": CRC-32 is %08x but its sidecar recorded %08x (%zu bytes now)", got, want,
                    bytes->size());
      return make_error(Errc::parse_error, where + buf + ": the file is corrupt or does not belong to " +
                                               sidecar_path.filename().string() + "; " + kRetrainHint);
    }
  }

  if (options.opencv_threads > 0) set_opencv_threads(options.opencv_threads);

  try {
    impl->net = cv::dnn::readNetFromONNX(reinterpret_cast<const char*>(bytes->data()), bytes->size());
  } catch (const cv::Exception& e) {
    return make_error(Errc::parse_error, where + ": OpenCV cannot read it as an ONNX model (" + e.err +
                                             "): the file is corrupt, truncated or not ONNX; " + kRetrainHint);
  }
  if (impl->net.empty()) {
    return make_error(Errc::parse_error, where + ": OpenCV read no layers from it; " + kRetrainHint);
  }
  impl->net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  impl->net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);

  // Dry run: names and shapes, and OpenCV allocates its layer buffers now
  // rather than on the first real frame.
  const int shape[] = {1, kPoseInputLayers, kStretchGridSize, kStretchGridSize};
  impl->input = cv::Mat(4, shape, CV_32F, cv::Scalar(0.0f));
  const std::string expected = "the network must take input '" + impl->input_name + "' [1, 2, 5, 5] float32 and give "
                               "output '" + impl->output_name + "' [1, 1, 5, 5]";
  cv::Mat out;
  try {
    impl->net.setInput(impl->input, impl->input_name);
    out = impl->net.forward(impl->output_name);
  } catch (const cv::Exception& e) {
    return make_error(Errc::unsupported, where + ": a dry run failed (OpenCV: " + e.err + "); " + expected);
  }
  if (out.depth() != CV_32F || out.total() != kPoseOutputSize || !out.isContinuous() ||
      (out.dims > 0 && out.size[0] != 1)) {
    std::string dims;
    for (int d = 0; d < out.dims; ++d) dims += (d ? ", " : "") + std::to_string(out.size[d]);
    return make_error(Errc::unsupported, where + ": the output has shape [" + dims + "]; " + expected);
  }
  for (std::size_t k = 0; k < kPoseOutputSize; ++k) {
    if (!std::isfinite(out.ptr<float>()[k])) {
      return make_error(Errc::parse_error, where + ": the network outputs NaN or infinity for an all-zero input "
                                                   "(corrupt weights?); " + kRetrainHint);
    }
  }
  return OnnxPoseModel(std::move(impl));
}

Result<OnnxPoseModel> OnnxPoseModel::load(const std::filesystem::path& onnx_path, const StretchGloveLayout& layout,
                                          const Options& options) {
  auto model = load(onnx_path, options);
  if (!model) return model.error();
  if (model->impl_->sidecar) {
    if (Status st = model->impl_->sidecar->check_against(layout, sidecar_path_for(onnx_path).string()); !st) {
      return st.error();
    }
  }
  return model;
}

bool OnnxPoseModel::infer(const float* input_2x5x5, float* output_5x5) noexcept {
  try {
    std::memcpy(impl_->input.ptr<float>(), input_2x5x5, kPoseInputSize * sizeof(float));
    impl_->net.setInput(impl_->input, impl_->input_name);
    const cv::Mat out = impl_->net.forward(impl_->output_name);
    std::memcpy(output_5x5, out.ptr<float>(), kPoseOutputSize * sizeof(float));
    return true;
  } catch (...) {
    std::memset(output_5x5, 0, kPoseOutputSize * sizeof(float));
    return false;
  }
}

const std::filesystem::path& OnnxPoseModel::path() const noexcept { return impl_->path; }
const std::optional<PoseModelSidecar>& OnnxPoseModel::sidecar() const noexcept { return impl_->sidecar; }

std::string OnnxPoseModel::describe() const {
  std::string s = impl_->path.string() + ": ";
  if (impl_->sidecar) {
    const PoseModelSidecar& sc = *impl_->sidecar;
    s += (sc.model_kind.empty() ? std::string("model") : sc.model_kind) + " for layout '" + sc.layout_name + "' (" +
         std::to_string(sc.cell_count) + " cells), " + std::to_string(sc.parameters) + " parameters, calibration " +
         sc.calibration + ", seed " + std::to_string(sc.seed);
    if (sc.validation_mean_deg >= 0) {
      char buf[64];
      std::snprintf(buf, sizeof buf, ", validation %.2f deg", sc.validation_mean_deg);
      s += buf;
    }
  } else {
    s += "no sidecar (grids unchecked)";
  }
  s += "; " + impl_->options.describe();
  return s;
}

}  // namespace proprio::stretch_glove
