#include "proprio/stretch_glove/dataset.hpp"
#include "proprio/core/file_io.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>

namespace proprio::stretch_glove {

namespace {

std::string json_string(std::string_view text) {
  std::string out = "\"";
  for (const char ch : text) {
    switch (ch) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      default:
        if (static_cast<unsigned char>(ch) < 0x20) {
          char buf[8];
          std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(ch));
          out += buf;
        } else {
          out += ch;
        }
    }
  }
  return out + "\"";
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  // Shorter text when it reads back identically.
  for (int p = 6; p < 17; ++p) {
    char s[40];
    std::snprintf(s, sizeof s, "%.*g", p, v);
    if (std::strtod(s, nullptr) == v) return s;
  }
  return buf;
}

}  // namespace

// --- dataset -----------------------------------------------------------------------------

const std::vector<std::string>& dataset_file_names() {
  static const std::vector<std::string> names = {"cells.npy",     "angles.npy",    "session.npy", "subject.npy",
                                                 "phase.npy",     "calib_min.npy", "calib_max.npy", "meta.json"};
  return names;
}

Result<DatasetWriter> DatasetWriter::create(const std::filesystem::path& dir, const StretchGloveLayout& layout,
                                            double frame_rate_hz, bool overwrite) {
  if (auto st = layout.validate(); !st) return st.error();
  if (!(frame_rate_hz > 0.0) || !std::isfinite(frame_rate_hz)) {
    return make_error(Errc::invalid_argument, "dataset frame rate must be above 0 Hz");
  }
  std::error_code ec;
  if (std::filesystem::exists(dir, ec) && !std::filesystem::is_directory(dir, ec)) {
    return make_error(Errc::invalid_argument, "'" + dir.string() + "' exists and is not a directory; choose another --out");
  }
  bool has_dataset = false;
  for (const auto& name : dataset_file_names()) has_dataset = has_dataset || std::filesystem::exists(dir / name, ec);
  if (has_dataset && !overwrite) {
    return make_error(Errc::invalid_argument, "'" + dir.string() +
                                                  "' already holds a dataset; choose another directory or pass "
                                                  "--force to replace it");
  }
  std::filesystem::create_directories(dir, ec);
  if (ec) return make_error(Errc::io_error, "cannot create dataset directory '" + dir.string() + "': " + ec.message());
  // meta.json goes first so an interrupted run never looks complete.
  std::filesystem::remove(dir / "meta.json", ec);
  for (const auto& name : dataset_file_names()) std::filesystem::remove(dir / name, ec);

  DatasetWriter d;
  d.dir_ = dir;
  d.layout_ = layout;
  d.frame_rate_hz_ = frame_rate_hz;
  struct Spec {
    const char* name;
    NpyType type;
    std::vector<std::size_t> row;
  };
  const Spec specs[] = {
      {"cells.npy", NpyType::float32, {layout.cell_count()}},
      {"angles.npy", NpyType::float32, {kHandDofCount}},
      {"session.npy", NpyType::int32, {}},
      {"subject.npy", NpyType::int32, {}},
      {"phase.npy", NpyType::uint8, {}},
  };
  for (const auto& s : specs) {
    auto w = NpyWriter::create(dir / s.name, s.type, s.row);
    if (!w) return w.error();
    d.writers_.push_back(std::move(*w));
  }
  return d;
}

Status DatasetWriter::add_session(const DatasetSession& s) {
  if (finished_) return make_error(Errc::invalid_argument, "the dataset is already finished");
  const std::size_t n = s.frames();
  const std::size_t cells = layout_.cell_count();
  if (s.cells.size() != n * cells || s.angles.size() != n * kHandDofCount) {
    return make_error(Errc::invalid_argument, "session " + std::to_string(s.session) + " of subject " +
                                                  std::to_string(s.subject) + ": " + std::to_string(n) +
                                                  " frames need " + std::to_string(n * cells) + " cell values and " +
                                                  std::to_string(n * kHandDofCount) + " angles");
  }
  if (auto st = s.calibration.validate(); !st) {
    return st.error().with_context("session " + std::to_string(s.session) + " of subject " + std::to_string(s.subject));
  }
  if (auto st = s.calibration.check_layout(layout_); !st) return st;

  const std::vector<std::int32_t> session_index(n, static_cast<std::int32_t>(sessions_.size()));
  const std::vector<std::int32_t> subject(n, static_cast<std::int32_t>(s.subject));
  Status st = writers_[0].append(std::span<const float>(s.cells));
  if (st) st = writers_[1].append(std::span<const float>(s.angles));
  if (st) st = writers_[2].append(std::span<const std::int32_t>(session_index));
  if (st) st = writers_[3].append(std::span<const std::int32_t>(subject));
  if (st) st = writers_[4].append(std::span<const std::uint8_t>(s.phase));
  if (!st) return st;

  calib_min_.insert(calib_min_.end(), s.calibration.min_pf.begin(), s.calibration.min_pf.end());
  calib_max_.insert(calib_max_.end(), s.calibration.max_pf.begin(), s.calibration.max_pf.end());
  const auto exploration = static_cast<std::size_t>(std::count(s.phase.begin(), s.phase.end(), std::uint8_t{0}));
  sessions_.push_back({s.subject, s.session, s.donning, n, frames_, exploration, s.hand_length_m, s.hand_width_m});
  frames_ += n;
  return {};
}

Status DatasetWriter::finish(const std::string& generator_json) {
  if (finished_) return {};
  for (auto& w : writers_) {
    if (auto st = w.close(); !st) return st;
  }
  const std::size_t S = sessions_.size();
  const std::size_t C = layout_.cell_count();
  if (auto st = write_npy(dir_ / "calib_min.npy", calib_min_, {S, C}); !st) return st;
  if (auto st = write_npy(dir_ / "calib_max.npy", calib_max_, {S, C}); !st) return st;

  std::ostringstream j;
  auto list = [&](auto begin, auto end, auto item) {
    j << "[";
    for (auto it = begin; it != end; ++it) j << (it == begin ? "" : ", ") << item(*it);
    j << "]";
  };
  j << "{\n";
  j << "  \"format\": \"proprio stretch-glove dataset\",\n  \"format_version\": 1,\n";
  j << "  \"layout\": " << json_string(layout_.name) << ",\n";
  j << "  \"layout_origin\": " << json_string(layout_.origin) << ",\n";
  j << "  \"cell_count\": " << C << ",\n";
  j << "  \"frame_rate_hz\": " << json_number(frame_rate_hz_) << ",\n";
  j << "  \"frames\": " << frames_ << ",\n";
  j << "  \"output_grid\": ";
  list(layout_.output_grid.begin(), layout_.output_grid.end(), [](const std::optional<HandDof>& d) {
    return d ? json_string(to_string(*d)) : std::string("null");
  });
  j << ",\n  \"input_grid_index\": ";
  const auto grid = layout_.input_grid_index();
  list(grid.begin(), grid.end(), [](int v) { return std::to_string(v); });
  j << ",\n  \"cell_names\": ";
  list(layout_.cells.begin(), layout_.cells.end(), [](const StretchCell& c) { return json_string(c.name); });
  j << ",\n  \"cell_categories\": ";
  list(layout_.cells.begin(), layout_.cells.end(),
       [](const StretchCell& c) { return json_string(to_string(c.category)); });
  j << ",\n  \"cell_directions\": ";
  list(layout_.cells.begin(), layout_.cells.end(),
       [](const StretchCell& c) { return json_string(to_string(c.direction)); });
  j << ",\n  \"dof_names\": [";
  for (std::size_t d = 0; d < kHandDofCount; ++d) j << (d ? ", " : "") << json_string(to_string(static_cast<HandDof>(d)));
  j << "],\n  \"sessions\": [";
  for (std::size_t i = 0; i < S; ++i) {
    const auto& s = sessions_[i];
    j << (i ? ",\n" : "\n") << "    {\"subject\": " << s.subject << ", \"session\": " << s.session
      << ", \"donning\": " << s.donning << ", \"frames\": " << s.frames << ", \"first_frame\": " << s.first_frame
      << ", \"exploration_frames\": " << s.exploration_frames
      << ", \"hand_length_m\": " << json_number(s.hand_length_m)
      << ", \"hand_width_m\": " << json_number(s.hand_width_m) << "}";
  }
  j << "\n  ],\n";
  j << "  \"units\": \"cells: recovered capacitance, pF; angles: radians\",\n";
  j << "  \"normalization\": \"x = 2 (c - min) / (max - min) - 1 in float32, clamped to [-2, 2]; min/max from "
       "calib_min/calib_max of the frame's session\",\n";
  j << "  \"generator\": " << (generator_json.empty() ? std::string("{}") : generator_json) << "\n";
  j << "}\n";

  if (auto st = write_file_atomic(dir_ / "meta.json", j.str(), "dataset description"); !st) return st;
  finished_ = true;
  return {};
}

}  // namespace proprio::stretch_glove
