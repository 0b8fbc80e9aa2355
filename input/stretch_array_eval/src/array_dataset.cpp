#include "proprio/stretch_array_eval/array_dataset.hpp"

#include <cmath>
#include <nlohmann/json.hpp>

namespace proprio::stretch_array_eval {

namespace {

Error bad_dataset(const std::filesystem::path& dir, const std::string& what) {
  return make_error(Errc::invalid_argument, "array dataset '" + dir.string() + "': " + what);
}

struct ArraySpec {
  const char* name;
  NpyType type;
};
constexpr ArraySpec kArrays[] = {{"cells.npy", NpyType::float32},         {"markers.npy", NpyType::float32},
                                 {"markers_truth.npy", NpyType::float32}, {"vertices_truth.npy", NpyType::float32},
                                 {"pose.npy", NpyType::float32},          {"session.npy", NpyType::int32}};

}  // namespace

const std::vector<std::string>& array_dataset_file_names() {
  static const std::vector<std::string> names = {"cells.npy", "markers.npy", "markers_truth.npy",
                                                 "vertices_truth.npy", "pose.npy", "session.npy", "meta.json"};
  return names;
}

Result<ArrayDatasetWriter> ArrayDatasetWriter::create(const std::filesystem::path& dir, ArrayDatasetShape shape,
                                                      bool overwrite) {
  if (shape.cell_names.empty() || shape.marker_names.empty() || shape.mesh_vertex_count == 0) {
    return bad_dataset(dir, "needs at least one cell, one marker and one mesh vertex");
  }
  if (!(shape.frame_rate_hz > 0.0) || !std::isfinite(shape.frame_rate_hz)) {
    return bad_dataset(dir, "the frame rate must be positive and finite");
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return make_error(Errc::io_error, "cannot create the dataset folder '" + dir.string() + "': " + ec.message());
  ArrayDatasetWriter w;
  auto lock = FolderLock::acquire(dir, "array dataset");
  if (!lock) return lock.error();
  w.lock_ = std::move(*lock);
  if (!overwrite && std::filesystem::exists(dir / "meta.json")) {
    return bad_dataset(dir, "already holds a dataset (meta.json); pass --force to replace it");
  }
  // An unfinished dataset must not look finished while it is rewritten.
  std::filesystem::remove(dir / "meta.json", ec);
  w.dir_ = dir;
  w.shape_ = std::move(shape);
  const std::size_t C = w.shape_.cell_names.size(), M = w.shape_.marker_names.size(), V = w.shape_.mesh_vertex_count;
  const std::vector<std::vector<std::size_t>> rows = {{C}, {M, 3}, {M, 3}, {V, 3}, {}, {}};
  for (std::size_t i = 0; i < rows.size(); ++i) {
    auto npy = NpyWriter::create(dir / kArrays[i].name, kArrays[i].type, rows[i]);
    if (!npy) return npy.error();
    w.writers_.push_back(std::move(*npy));
  }
  return w;
}

Status ArrayDatasetWriter::add_session(const ArrayDatasetSession& s) {
  if (finished_) return make_error(Errc::invalid_argument, "the array dataset is already finished");
  const std::size_t n = s.frames();
  const std::size_t C = shape_.cell_names.size(), M = shape_.marker_names.size(), V = shape_.mesh_vertex_count;
  if (s.cells.size() != n * C || s.markers.size() != n * M * 3 || s.markers_truth.size() != n * M * 3 ||
      s.vertices_truth.size() != n * V * 3) {
    return make_error(Errc::invalid_argument, "session '" + s.name + "': " + std::to_string(n) +
                                                  " frames need " + std::to_string(n * C) + " cell values, " +
                                                  std::to_string(n * M * 3) + " marker and " +
                                                  std::to_string(n * V * 3) + " vertex coordinates");
  }
  if (s.split != "train" && s.split != "test") {
    return make_error(Errc::invalid_argument, "session '" + s.name + "': split must be train or test");
  }
  const std::vector<std::int32_t> index(n, static_cast<std::int32_t>(sessions_.size()));
  Status st = writers_[0].append(std::span<const float>(s.cells));
  if (st) st = writers_[1].append(std::span<const float>(s.markers));
  if (st) st = writers_[2].append(std::span<const float>(s.markers_truth));
  if (st) st = writers_[3].append(std::span<const float>(s.vertices_truth));
  if (st) st = writers_[4].append(std::span<const float>(s.pose));
  if (st) st = writers_[5].append(std::span<const std::int32_t>(index));
  if (!st) return st;
  sessions_.push_back({s.name, s.motion, s.split, s.donning, frames_, n, s.frames_dropped});
  frames_ += n;
  return {};
}

Status ArrayDatasetWriter::finish(const std::string& generator_json) {
  if (finished_) return {};
  for (auto& w : writers_) {
    if (auto st = w.close(); !st) return st;
  }
  nlohmann::ordered_json j;
  j["format"] = kArrayDatasetFormat;
  j["version"] = kArrayDatasetVersion;
  j["layout"] = shape_.layout;
  j["cell_count"] = shape_.cell_names.size();
  j["cell_names"] = shape_.cell_names;
  j["marker_count"] = shape_.marker_names.size();
  j["marker_names"] = shape_.marker_names;
  j["mesh_vertex_count"] = shape_.mesh_vertex_count;
  j["frame_rate_hz"] = shape_.frame_rate_hz;
  j["pose_name"] = shape_.pose_name;
  j["rest_radius_m"] = shape_.rest_radius_m;
  j["frames"] = frames_;
  auto& sessions = j["sessions"] = nlohmann::ordered_json::array();
  for (const auto& s : sessions_) {
    sessions.push_back({{"name", s.name},
                        {"motion", s.motion},
                        {"donning", s.donning},
                        {"split", s.split},
                        {"first_frame", s.first_frame},
                        {"frames", s.frames},
                        {"frames_dropped", s.dropped}});
  }
  j["units"] = {{"cells", "C/C0, each cell's capacitance over its value at the session's rest frames"},
                {"markers", "metres, body frame"},
                {"pose", shape_.pose_name}};
  auto generator = nlohmann::ordered_json::parse(generator_json.empty() ? "{}" : generator_json, nullptr, false);
  j["generator"] = generator.is_discarded() ? nlohmann::ordered_json(generator_json) : generator;
  if (auto st = write_file_atomic(dir_ / "meta.json", j.dump(1) + "\n", "array dataset description"); !st) return st;
  finished_ = true;
  return {};
}

Result<ArrayDataset> load_array_dataset(const std::filesystem::path& dir) {
  auto text = read_input_file(dir / "meta.json", "array dataset description", 16 * kMiB);
  if (!text) {
    return bad_dataset(dir, "no readable meta.json (" + text.error().message +
                                "); a dataset without it was not finished");
  }
  const auto j = nlohmann::json::parse(*text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return bad_dataset(dir, "meta.json is not a JSON object");
  if (j.value("format", std::string()) != kArrayDatasetFormat) {
    return bad_dataset(dir, std::string("meta.json's format is not \"") + kArrayDatasetFormat + "\"");
  }
  if (j.value("version", 0) != kArrayDatasetVersion) {
    return bad_dataset(dir, "version " + j.value("version", nlohmann::json()).dump() + " (this build reads " +
                                std::to_string(kArrayDatasetVersion) + ")");
  }
  ArrayDataset d;
  try {
    d.shape.layout = j.at("layout").get<std::string>();
    d.shape.cell_names = j.at("cell_names").get<std::vector<std::string>>();
    d.shape.marker_names = j.at("marker_names").get<std::vector<std::string>>();
    d.shape.mesh_vertex_count = j.at("mesh_vertex_count").get<std::size_t>();
    d.shape.frame_rate_hz = j.at("frame_rate_hz").get<double>();
    d.shape.pose_name = j.value("pose_name", std::string());
    d.shape.rest_radius_m = j.value("rest_radius_m", 0.0);
    if (!std::isfinite(d.shape.rest_radius_m) || d.shape.rest_radius_m < 0.0 || d.shape.rest_radius_m > 10.0) {
      return bad_dataset(dir, "meta.json's rest_radius_m must be 0 (flat) or a radius up to 10 m");
    }
    for (const auto& s : j.at("sessions")) {
      d.sessions.push_back({s.at("name").get<std::string>(), s.at("motion").get<std::string>(),
                            s.at("split").get<std::string>(), s.at("donning").get<int>(),
                            s.at("first_frame").get<std::size_t>(), s.at("frames").get<std::size_t>(),
                            s.value("frames_dropped", std::size_t{0})});
    }
  } catch (const nlohmann::json::exception& e) {
    return bad_dataset(dir, std::string("meta.json: ") + e.what());
  }
  NpyArray* arrays[] = {&d.cells, &d.markers, &d.markers_truth, &d.vertices_truth, &d.pose, &d.session};
  for (std::size_t i = 0; i < std::size(arrays); ++i) {
    auto a = read_npy(dir / kArrays[i].name);
    if (!a) return a.error();
    if (a->type != kArrays[i].type) return bad_dataset(dir, std::string(kArrays[i].name) + " has the wrong element type");
    for (double v : a->values) {
      if (!std::isfinite(v)) return bad_dataset(dir, std::string(kArrays[i].name) + " holds NaN or infinity");
    }
    *arrays[i] = std::move(*a);
  }
  const std::size_t N = d.pose.rows(), C = d.shape.cell_names.size(), M = d.shape.marker_names.size(),
                    V = d.shape.mesh_vertex_count;
  auto expect = [&](const NpyArray& a, const char* name, std::vector<std::size_t> shape) -> Status {
    if (a.shape != shape) return bad_dataset(dir, std::string(name) + "'s shape disagrees with meta.json");
    return {};
  };
  if (auto st = expect(d.cells, "cells.npy", {N, C}); !st) return st.error();
  if (auto st = expect(d.markers, "markers.npy", {N, M, 3}); !st) return st.error();
  if (auto st = expect(d.markers_truth, "markers_truth.npy", {N, M, 3}); !st) return st.error();
  if (auto st = expect(d.vertices_truth, "vertices_truth.npy", {N, V, 3}); !st) return st.error();
  if (auto st = expect(d.session, "session.npy", {N}); !st) return st.error();
  std::size_t next = 0;
  for (std::size_t s = 0; s < d.sessions.size(); ++s) {
    if (d.sessions[s].first_frame != next) return bad_dataset(dir, "sessions are not contiguous in meta.json");
    next += d.sessions[s].frames;
    for (std::size_t f = d.sessions[s].first_frame; f < next && f < N; ++f) {
      if (d.session.values[f] != static_cast<double>(s)) return bad_dataset(dir, "session.npy disagrees with meta.json");
    }
  }
  if (next != N) return bad_dataset(dir, "meta.json's sessions hold " + std::to_string(next) + " frames, the arrays " +
                                             std::to_string(N));
  return d;
}

}  // namespace proprio::stretch_array_eval
