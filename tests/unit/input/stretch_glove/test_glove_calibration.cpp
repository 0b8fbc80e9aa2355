// Min-max calibration (Glauser 2019 Sec. 5.3.3), the network input grid, and
// the training-dataset files (NPY + meta.json), read back independently.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <unistd.h>

#include "proprio/stretch_glove/calibration.hpp"
#include "proprio/stretch_glove/dataset.hpp"
#include "proprio/stretch_glove/readout.hpp"
#include "proprio/sim/stretch_glove_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "support/stretch_glove.hpp"

namespace proprio::stretch_glove {
namespace {

namespace fs = std::filesystem;

using proprio::testing_support::thesis_layout;

fs::path temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("proprio_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

MinMaxCalibrator make_calibrator() {
  auto c = MinMaxCalibrator::create(thesis_layout());
  EXPECT_TRUE(c.ok()) << c.error().message;
  return std::move(*c);
}

std::vector<float> constant_frame(float v) { return std::vector<float>(thesis_layout().cell_count(), v); }

TEST(GloveCalibration, MedianFilterIgnoresASpike) {
  auto cal = make_calibrator();
  for (int i = 0; i < 60; ++i) cal.add(constant_frame(i == 30 ? 100.0f : 10.0f));
  // Then a held plateau, long enough (more than half the 20-frame window) to move the median.
  for (int i = 0; i < 12; ++i) cal.add(constant_frame(20.0f));
  for (int i = 0; i < 12; ++i) cal.add(constant_frame(5.0f));
  auto c = cal.finish("test");
  ASSERT_TRUE(c.ok()) << c.error().message;
  for (std::size_t i = 0; i < c->cell_count(); ++i) {
    EXPECT_EQ(c->max_pf[i], 20.0f);
    EXPECT_EQ(c->min_pf[i], 5.0f);
  }
  EXPECT_EQ(c->frames, 84u);
  EXPECT_EQ(c->median_frames, 20);
}

TEST(GloveCalibration, MedianOfAnEvenWindowIsTheMeanOfTheMiddleTwo) {
  auto cal = make_calibrator();
  // Window of 20: ten 4s and ten 6s -> median 5, the only median seen.
  for (int i = 0; i < 20; ++i) cal.add(constant_frame(i % 2 ? 4.0f : 6.0f));
  EXPECT_FALSE(cal.finish().ok()) << "one median gives no range yet";
  cal.add(constant_frame(6.0f));  // replaces a 6: still 5
  cal.add(constant_frame(6.0f));  // replaces a 4: eleven 6s, median 6
  auto c = cal.finish();
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->min_pf[0], 5.0f);
  EXPECT_EQ(c->max_pf[0], 6.0f);
}

TEST(GloveCalibration, NormalizeMapsMinMaxToMinusOnePlusOne) {
  MinMaxCalibration c;
  c.min_pf = {10.0f, -2.0f, 100.0f};
  c.max_pf = {20.0f, 2.0f, 100.5f};
  ASSERT_TRUE(c.validate().ok());
  EXPECT_EQ(c.normalize(std::vector<float>{10.0f, -2.0f, 100.0f}), (std::vector<float>{-1.0f, -1.0f, -1.0f}));
  EXPECT_EQ(c.normalize(std::vector<float>{20.0f, 2.0f, 100.5f}), (std::vector<float>{1.0f, 1.0f, 1.0f}));
  const auto mid = c.normalize(std::vector<float>{15.0f, 0.0f, 100.25f});
  for (float v : mid) EXPECT_NEAR(v, 0.0f, 1e-5f);
  // Outside the calibrated range: linear, then clamped at +-2.
  const auto out = c.normalize(std::vector<float>{22.5f, 100.0f, -50.0f});
  EXPECT_NEAR(out[0], 1.5f, 1e-6f);
  EXPECT_EQ(out[1], 2.0f);
  EXPECT_EQ(out[2], -2.0f);
  EXPECT_EQ(c.normalize(std::vector<float>{NAN, 0.0f, 0.0f})[0], 0.0f);
  // Against an independent double-precision evaluation.
  Rng rng(3);
  for (int i = 0; i < 1000; ++i) {
    const float x = static_cast<float>(rng.uniform(9.0, 21.0));
    const double expected = std::clamp(2.0 * (x - 10.0) / 10.0 - 1.0, -2.0, 2.0);
    EXPECT_NEAR(c.normalize(std::vector<float>{x, 0.0f, 100.0f})[0], expected, 1e-6);
  }
}

TEST(GloveCalibration, SaveLoadRoundTrip) {
  auto cal = make_calibrator();
  Rng rng(9);
  for (int i = 0; i < 200; ++i) {
    std::vector<float> f;
    for (std::size_t c = 0; c < thesis_layout().cell_count(); ++c) f.push_back(static_cast<float>(rng.uniform(5.0, 30.0)));
    cal.add(f);
  }
  auto c = cal.finish("unit test \"quoted\"", "2024-01-01");
  ASSERT_TRUE(c.ok()) << c.error().message;
  const fs::path dir = temp_dir("calib");
  const fs::path file = dir / "calibration.toml";
  ASSERT_TRUE(c->save(file).ok());
  auto back = MinMaxCalibration::load(file);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->min_pf, c->min_pf);
  EXPECT_EQ(back->max_pf, c->max_pf);
  EXPECT_EQ(back->layout_name, thesis_layout().name);
  EXPECT_EQ(back->source, "unit test \"quoted\"");
  EXPECT_EQ(back->created, "2024-01-01");
  EXPECT_EQ(back->frames, 200u);
  EXPECT_TRUE(back->check_layout(thesis_layout()).ok());
  fs::remove_all(dir);
}

TEST(GloveCalibration, CorruptedFilesGiveClearErrors) {
  MinMaxCalibration good;
  good.layout_name = "x";
  good.min_pf = {1.0f, 2.0f};
  good.max_pf = {3.0f, 4.0f};
  const std::string text = good.to_toml();
  ASSERT_TRUE(MinMaxCalibration::parse(text, "cal.toml").ok());

  auto expect_error = [](const std::string& t, const std::string& what) {
    auto r = MinMaxCalibration::parse(t, "cal.toml");
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_NE(r.error().message.find(what), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("cal.toml"), std::string::npos) << r.error().message;
  };
  expect_error("\x01\x02garbage\xff[[[", "corrupted");
  expect_error(text.substr(0, text.size() / 2), "cal.toml:");  // truncated mid-array
  std::string wrong_count = text;
  wrong_count.replace(wrong_count.find("cell_count = 2"), 14, "cell_count = 3");
  expect_error(wrong_count, "cell_count is 3");
  std::string flipped = text;
  flipped.replace(flipped.find("3.0,"), 4, "0.5,");
  expect_error(flipped, "min_pf 1.0 >= max_pf 0.5");
  std::string with_nan = text;
  with_nan.replace(with_nan.find("2.0,"), 4, "nan,");
  expect_error(with_nan, "finite");
  std::string missing = text;
  missing.erase(missing.find("cell_count"), missing.find('\n', missing.find("cell_count")) + 1 - missing.find("cell_count"));
  expect_error(missing, "cell count");

  auto nofile = MinMaxCalibration::load("/nonexistent/cal.toml");
  ASSERT_FALSE(nofile.ok());
  EXPECT_EQ(nofile.error().code, Errc::not_found);

  MinMaxCalibration other = good;
  EXPECT_FALSE(other.check_layout(thesis_layout()).ok());
}

TEST(GloveCalibration, ProgressSaysWhatToMoveMore) {
  auto cal = make_calibrator();
  const auto& L = thesis_layout();
  // Only the index finger's cells move.
  for (int i = 0; i < 200; ++i) {
    std::vector<float> f;
    for (const auto& cell : L.cells) {
      const bool index = cell.name.rfind("index_", 0) == 0;
      const double swing = index ? cell.rest_capacitance_pf * (i % 40 < 20 ? 1.0 : 2.0) : cell.rest_capacitance_pf;
      f.push_back(static_cast<float>(swing));
    }
    cal.add(f);
  }
  const CalibrationProgress p = cal.progress();
  EXPECT_EQ(p.frames, 200u);
  EXPECT_EQ(p.region_coverage[static_cast<std::size_t>(CalibrationRegion::index)], 1.0);
  EXPECT_EQ(p.region_coverage[static_cast<std::size_t>(CalibrationRegion::ring)], 0.0);
  const std::string advice = p.advice();
  EXPECT_NE(advice.find("ring"), std::string::npos) << advice;
  EXPECT_NE(advice.find("thumb"), std::string::npos) << advice;
  EXPECT_EQ(advice.find("index"), std::string::npos) << advice;
  auto c = cal.finish();
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.error().code, Errc::unavailable);
  EXPECT_NE(c.error().message.find("thumb_mcp_along"), std::string::npos) << c.error().message;
}

TEST(GloveCalibration, InvalidCellsAreNotCalibrated) {
  auto cal = make_calibrator();
  CellFrame f;
  f.cells_pf = constant_frame(10.0f);
  f.status.assign(thesis_layout().cell_count(), CellStatus::valid);
  f.status[3] = CellStatus::dead;
  for (int i = 0; i < 40; ++i) {
    f.cells_pf.assign(thesis_layout().cell_count(), i < 20 ? 10.0f : 30.0f);
    f.cells_pf[3] = 0.0f;
    cal.add(f);
  }
  const auto p = cal.progress();
  EXPECT_EQ(p.range_pf[3], 0.0);
  EXPECT_EQ(p.range_pf[4], 20.0);
}

TEST(GloveCalibration, InputGridPlacesEveryCell) {
  const InputGrid grid(thesis_layout());
  std::vector<float> normalized;
  for (std::size_t i = 0; i < thesis_layout().cell_count(); ++i) normalized.push_back(static_cast<float>(i + 1));
  std::vector<float> out(kStretchInputSize, -7.0f);
  grid.fill(normalized, out);
  std::size_t filled = 0;
  for (std::size_t i = 0; i < thesis_layout().cell_count(); ++i) {
    const auto& c = thesis_layout().cells[i];
    // NCHW with N = 1: channel (layer), then row, then column.
    EXPECT_EQ(out[static_cast<std::size_t>(c.grid_layer * 25 + c.grid_row * 5 + c.grid_col)], static_cast<float>(i + 1));
  }
  for (float v : out) filled += v != 0.0f;
  EXPECT_EQ(filled, thesis_layout().cell_count());  // and the six empty slots are 0
}

// --- dataset ---------------------------------------------------------------------

// A minimal NPY 1.0 reader, written from the format description, to check the writer.
struct RawNpy {
  std::string descr;
  bool fortran = true;
  std::vector<std::size_t> shape;
  std::vector<char> data;
};

RawNpy read_raw_npy(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  RawNpy out;
  EXPECT_GE(bytes.size(), 10u);
  if (bytes.size() < 10) return out;
  EXPECT_EQ(std::string(bytes.data(), 6), "\x93NUMPY");
  EXPECT_EQ(bytes[6], 1);
  EXPECT_EQ(bytes[7], 0);
  const std::size_t len = static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
  EXPECT_EQ((10 + len) % 64, 0u) << "numpy aligns the data to 64 bytes";
  const std::string header(bytes.data() + 10, len);
  EXPECT_EQ(header.back(), '\n');
  auto field = [&](const std::string& key) {
    const auto p = header.find("'" + key + "': ");
    EXPECT_NE(p, std::string::npos) << key;
    return p == std::string::npos ? std::string() : header.substr(p + key.size() + 4);
  };
  const std::string d = field("descr");
  out.descr = d.substr(1, d.find('\'', 1) - 1);
  out.fortran = field("fortran_order").rfind("True", 0) == 0;
  std::string s = field("shape");
  s = s.substr(1, s.find(')') - 1);
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.find_first_not_of(' ') != std::string::npos) out.shape.push_back(std::stoull(item));
  }
  out.data.assign(bytes.begin() + static_cast<std::ptrdiff_t>(10 + len), bytes.end());
  return out;
}

template <typename T>
std::vector<T> values(const RawNpy& n) {
  std::vector<T> v(n.data.size() / sizeof(T));
  std::memcpy(v.data(), n.data.data(), v.size() * sizeof(T));
  return v;
}

DatasetSession tiny_session(int subject, int session, std::size_t frames, float base) {
  DatasetSession s;
  s.subject = subject;
  s.session = session;
  s.donning = session;
  s.hand_length_m = 0.18;
  s.hand_width_m = 0.095;
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t c = 0; c < thesis_layout().cell_count(); ++c) s.cells.push_back(base + static_cast<float>(f * 100 + c));
    for (std::size_t d = 0; d < kHandDofCount; ++d) s.angles.push_back(0.01f * static_cast<float>(f * 20 + d));
    s.phase.push_back(f < frames / 2 ? 0 : 1);
  }
  s.calibration.layout_name = thesis_layout().name;
  s.calibration.min_pf.assign(thesis_layout().cell_count(), base);
  s.calibration.max_pf.assign(thesis_layout().cell_count(), base + 1.0f);
  return s;
}

TEST(GloveDataset, FilesParseBackWithShapesAndValues) {
  const fs::path dir = temp_dir("dataset");
  auto w = DatasetWriter::create(dir, thesis_layout(), 60.0, false);
  ASSERT_TRUE(w.ok()) << w.error().message;
  const auto a = tiny_session(3, 0, 5, 10.0f);
  const auto b = tiny_session(4, 1, 7, 20.0f);
  ASSERT_TRUE(w->add_session(a).ok());
  ASSERT_TRUE(w->add_session(b).ok());
  ASSERT_TRUE(w->finish("{\"tool\": \"unit test\", \"seed\": 7}").ok());

  const std::size_t C = thesis_layout().cell_count();
  const RawNpy cells = read_raw_npy(dir / "cells.npy");
  EXPECT_EQ(cells.descr, "<f4");
  EXPECT_FALSE(cells.fortran);
  EXPECT_EQ(cells.shape, (std::vector<std::size_t>{12, C}));
  std::vector<float> expected_cells = a.cells;
  expected_cells.insert(expected_cells.end(), b.cells.begin(), b.cells.end());
  EXPECT_EQ(values<float>(cells), expected_cells);

  const RawNpy angles = read_raw_npy(dir / "angles.npy");
  EXPECT_EQ(angles.shape, (std::vector<std::size_t>{12, kHandDofCount}));
  EXPECT_EQ(values<float>(angles)[5 * 20 + 3], b.angles[3]);

  const RawNpy session = read_raw_npy(dir / "session.npy");
  EXPECT_EQ(session.descr, "<i4");
  EXPECT_EQ(session.shape, (std::vector<std::size_t>{12}));
  EXPECT_EQ(values<std::int32_t>(session), (std::vector<std::int32_t>{0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1}));
  EXPECT_EQ(values<std::int32_t>(read_raw_npy(dir / "subject.npy")),
            (std::vector<std::int32_t>{3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 4}));
  const RawNpy phase = read_raw_npy(dir / "phase.npy");
  EXPECT_EQ(phase.descr, "|u1");
  EXPECT_EQ(values<std::uint8_t>(phase), (std::vector<std::uint8_t>{0, 0, 1, 1, 1, 0, 0, 0, 1, 1, 1, 1}));

  const RawNpy cmin = read_raw_npy(dir / "calib_min.npy"), cmax = read_raw_npy(dir / "calib_max.npy");
  EXPECT_EQ(cmin.shape, (std::vector<std::size_t>{2, C}));
  EXPECT_EQ(values<float>(cmin)[C], 20.0f);
  EXPECT_EQ(values<float>(cmax)[0], 11.0f);

  std::ifstream meta_in(dir / "meta.json");
  const auto meta = nlohmann::json::parse(meta_in);
  EXPECT_EQ(meta["layout"], thesis_layout().name);
  EXPECT_EQ(meta["cell_count"], C);
  EXPECT_EQ(meta["frame_rate_hz"], 60.0);
  EXPECT_EQ(meta["frames"], 12);
  EXPECT_EQ(meta["input_grid_index"].get<std::vector<int>>(), thesis_layout().input_grid_index());
  ASSERT_EQ(meta["output_grid"].size(), 25u);
  EXPECT_EQ(meta["output_grid"][0], "thumb_cmc_abduction");
  EXPECT_TRUE(meta["output_grid"][4].is_null());
  ASSERT_EQ(meta["dof_names"].size(), kHandDofCount);
  EXPECT_EQ(meta["dof_names"][5], "index_mcp_abduction");
  ASSERT_EQ(meta["sessions"].size(), 2u);
  EXPECT_EQ(meta["sessions"][1]["subject"], 4);
  EXPECT_EQ(meta["sessions"][1]["frames"], 7);
  EXPECT_EQ(meta["sessions"][1]["first_frame"], 5);
  EXPECT_EQ(meta["sessions"][1]["exploration_frames"], 3);
  EXPECT_EQ(meta["sessions"][0]["hand_width_m"], 0.095);
  EXPECT_EQ(meta["generator"]["seed"], 7);
  EXPECT_EQ(meta["cell_categories"][16], "abduction");

  // An existing dataset is kept unless overwriting is asked for.
  auto again = DatasetWriter::create(dir, thesis_layout(), 60.0, false);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message.find("--force"), std::string::npos);
  auto forced = DatasetWriter::create(dir, thesis_layout(), 60.0, true);
  ASSERT_TRUE(forced.ok()) << forced.error().message;
  EXPECT_FALSE(fs::exists(dir / "meta.json")) << "an unfinished dataset has no meta.json";
  fs::remove_all(dir);
}

TEST(GloveDataset, RejectsInconsistentSessions) {
  const fs::path dir = temp_dir("dataset_bad");
  auto w = DatasetWriter::create(dir, thesis_layout(), 60.0, false);
  ASSERT_TRUE(w.ok());
  auto s = tiny_session(0, 0, 3, 1.0f);
  s.cells.pop_back();
  EXPECT_FALSE(w->add_session(s).ok());
  auto t = tiny_session(0, 0, 3, 1.0f);
  t.calibration.max_pf[2] = 0.0f;
  const Status st = w->add_session(t);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("cell 2"), std::string::npos) << st.error().message;
  fs::remove_all(dir);
}

TEST(GloveDataset, SimulatedPipelineCalibratesIntoRange) {
  // Simulator -> read-out -> calibrator on the exploration -> normalised task
  // frames mostly inside [-1, 1].
  auto sim = sim::StretchGloveSimulator::create(thesis_layout(), *(*sim::sim_subject(5)).shape(), sim::StretchGloveSimOptions{});
  ASSERT_TRUE(sim.ok());
  sim::StretchSessionOptions so;
  so.exploration_s = 16.0;  // about ten postures: enough to span most of each cell's range
  so.task_s = 4.0;
  sim::StretchGloveSession session(std::move(*sim), so);
  auto readout = make_readout(thesis_layout());
  ASSERT_TRUE(readout.ok());
  auto cal = make_calibrator();
  CellFrame frame = readout->make_frame();
  std::vector<std::vector<float>> task;
  sim::StretchSample s;
  while (session.next(s)) {
    if (!readout->push(s.measurement.combination, s.measurement.capacitance_pf, s.measurement.time_ns, frame)) continue;
    if (!frame.all_valid()) continue;
    if (s.phase == sim::StretchPhase::exploration) {
      cal.add(frame);
    } else {
      task.push_back(frame.cells_pf);
    }
  }
  auto c = cal.finish();
  ASSERT_TRUE(c.ok()) << c.error().message;
  ASSERT_NEAR(static_cast<double>(task.size()), 4.0 * 60.0, 2.0);
  std::size_t inside = 0, total = 0;
  for (const auto& f : task) {
    for (float x : c->normalize(f)) {
      inside += x >= -1.1f && x <= 1.1f;
      ++total;
    }
  }
  EXPECT_GT(static_cast<double>(inside) / static_cast<double>(total), 0.9);
  EXPECT_GT(cal.progress().overall, 0.6) << cal.progress().advice();
}

}  // namespace
}  // namespace proprio::stretch_glove
