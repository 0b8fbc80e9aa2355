// proprio record array: a stretch sensor array's session from its read-out
// board (protocol 1.1, single-strip rows; docs/stretch-arrays.md), written in
// the session recording format (docs/recording-format.md):
//   array/measurements  raw: every measurement the board delivered, flagged
//                       ones included (the packing is in the stream's meta)
//   array/cells         capacitance: the solved cells (F) at every frame; the
//                       meta holds the layout, the rest calibration (each
//                       row's parasitic and each cell's C0), so C/C0 is
//                       values / rest_pf on reading
//   events              calibration done, board restarts, unplugs, the end
// The first --rest-seconds are the rest calibration: the sleeve lies flat and
// unstretched while the rows' means give row_parasitics_at_rest(), and the
// rest frames, solved with it, give each cell's C0. Those frames are solved
// after the calibration and written too, so the cells stream covers the
// whole session.
//
// The board: a real one on USB (the same selection as `stretch-board
// monitor`), a capture file (--from-file, in the board's own time), or with
// --emulate the board emulator serving the layout over the in-memory HID link
// (the sleeve at rest, then slowly stretching, each row with a stray
// capacitance of its own for the calibration to remove).
#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "hid_monitor_common.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/core/recording.hpp"
#include "proprio/hid/capture_file.hpp"
#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_board/stretch_array_reader.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"

namespace proprio::cli {
namespace {
// Named: the devices program is a unity build, and other command files have
// file-local helpers of the same names.
namespace record_array {

using namespace proprio::devices;
namespace fs = std::filesystem;
namespace sa = proprio::stretch_array;

constexpr HidBoardKind kArrayBoardKind{"stretch board", "stretch-board", kStretchUsbVendorId, kStretchUsbProductId,
                                       kStretchHidUsagePage};

struct Args {
  Args() : hid(kArrayBoardKind) {}
  std::string layout;
  std::string out;
  bool force = false;
  double rest_s = 5.0;
  HidMonitorArgs hid;  // --vid --pid --serial --path --seconds --interval
  double connect_timeout_s = 5.0;
  double disconnect_timeout_s = 3.0;
  bool emulate = false;
  std::string emulate_layout;  // the emulated board serves this one instead (a board that does not match)
  std::string from_file;       // a capture file instead of a live board
  BoardEmulatorFaultArgs faults;
};

unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }

std::string fmt(const char* format, double v) {
  char b[64];
  std::snprintf(b, sizeof b, format, v);
  return b;
}

// The emulated sleeve: each cell at its modelled rest capacitance until
// still_s, then stretching and relaxing (C/C0 up to 1.1-1.25) at 0.1-0.3 Hz
// with its own phase; each row adds a stray capacitance of 1-5 pF of its own,
// which the rest calibration must remove.
struct EmulatedSleeve {
  sa::StripArrayLayout layout;
  std::vector<double> rest_pf;
  std::vector<double> row_parasitic_pf;
  double still_s = 0.0;

  void cells(TimeNs t_ns, std::span<double> out) const {
    const double t = ns_to_seconds(t_ns) - still_s;
    for (std::size_t c = 0; c < rest_pf.size(); ++c) {
      const double k = static_cast<double>(c);
      const double depth = 0.1 + 0.15 * (0.5 + 0.5 * std::sin(2.3 * k));
      const double hz = 0.1 + 0.05 * std::fmod(k, 5.0);
      // From 0 at the end of the still phase, so the cells leave C0 smoothly.
      const double s = t <= 0.0 ? 0.0 : 0.5 - 0.5 * std::cos(2.0 * M_PI * hz * t);
      out[c] = rest_pf[c] * (1.0 + depth * s);
    }
  }
};

// The emulated board and its link, when --emulate.
struct Emulation {
  std::shared_ptr<hid::FakeHidLink> link;
  std::unique_ptr<StretchEmulatorServer> server;
  StretchEmulatorOptions options;
};

Result<Emulation> make_emulation(const Args& a, const sa::StripArrayLayout& layout) {
  auto sleeve = std::make_shared<EmulatedSleeve>();
  if (a.emulate_layout.empty()) {
    sleeve->layout = layout;
  } else {
    auto other = sa::StripArrayLayout::load(a.emulate_layout);
    if (!other) return other.error();
    sleeve->layout = std::move(*other);
  }
  if (auto plan = stretch_array_plan(sleeve->layout); !plan) return plan.error();
  sleeve->rest_pf = array_rest_capacitances_pf(sleeve->layout);
  const std::size_t rows = static_cast<std::size_t>(sleeve->layout.measurement_matrix(true).rows());
  for (std::size_t r = 0; r < rows; ++r) {
    sleeve->row_parasitic_pf.push_back(3.0 + 2.0 * std::sin(1.3 * static_cast<double>(r)));
  }
  // Still a little past the host's rest window: it starts at the first
  // measurement, which comes a little after the emulator's time zero.
  sleeve->still_s = a.rest_s + 0.5;
  StretchEmulatorOptions base;
  base.seed = 1;
  apply_board_emulator_faults(a.faults, base);
  auto eo = stretch_array_emulator_options(sleeve->layout, base);
  if (!eo) return eo.error();
  if (auto s = eo->validate(); !s) return s.error();
  auto provider = stretch_array_provider(
      sleeve->layout, [sleeve](TimeNs t, std::span<double> out) { sleeve->cells(t, out); }, sleeve->row_parasitic_pf);
  auto emulator = StretchEmulator::create(*eo, std::move(provider));
  if (!emulator) return emulator.error();
  Emulation e;
  e.options = *eo;
  e.link = std::make_shared<hid::FakeHidLink>();
  e.server = std::make_unique<StretchEmulatorServer>(std::move(*emulator), e.link);
  return e;
}

// JSON for a stream's meta or an event. Names and paths come from the user
// and may not be UTF-8: replaced, not thrown.
std::string text(const nlohmann::json& j) { return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace); }

// array/measurements: 16 bytes per measurement, little-endian.
constexpr const char* kMeasurementPacking =
    "per measurement, 16 bytes little-endian: u16 combination (the row of the layout's measurement matrix with "
    "M^II), u8 status (0 ok, 1 saturated, 2 below zero, 3 no signal), u8 epoch (board restarts seen, mod 256), "
    "f32 capacitance pF (after the board's own parasitic subtraction), i64 time ns (time_base)";

void pack(const StretchSample& s, std::vector<std::uint8_t>& out) {
  std::uint8_t b[16];
  const std::uint16_t comb = s.combination;
  const float pf = static_cast<float>(s.capacitance_pf);
  const std::int64_t t = s.time_ns;
  static_assert(std::endian::native == std::endian::little, "the recording format is little-endian");
  std::memcpy(b, &comb, 2);
  b[2] = static_cast<std::uint8_t>(s.status);
  b[3] = static_cast<std::uint8_t>(s.epoch & 0xFFu);
  std::memcpy(b + 4, &pf, 4);
  std::memcpy(b + 8, &t, 8);
  out.insert(out.end(), b, b + 16);
}

nlohmann::json layout_meta(const sa::StripArrayLayout& layout) {
  nlohmann::json cells = nlohmann::json::array();
  for (const auto& c : layout.cells) cells.push_back(c.name);
  nlohmann::json j = {{"layout", layout.name},
                      {"top_strips", layout.top_strips.size()},
                      {"bottom_strips", layout.bottom_strips.size()},
                      {"rows", static_cast<std::size_t>(layout.measurement_matrix(true).rows())},
                      {"cells", cells}};
  return j;
}

// The recording being written: flushed every interval, closed on every way out.
class Session {
 public:
  static Result<Session> create(const Args& a, const sa::StripArrayLayout& layout, const std::string& time_base) {
    RecordingWriterOptions wo;
    wo.overwrite = a.force;
    auto w = RecordingWriter::create(a.out, wo);
    if (!w) return w.error();
    Session s(std::move(*w));
    s.time_base_ = time_base;
    nlohmann::json meta = layout_meta(layout);
    meta["packing"] = kMeasurementPacking;
    meta["time_base"] = time_base;
    meta["tool"] = "proprio record array";
    auto m = s.writer_.add_stream(StreamKind::raw, "array/measurements", text(meta));
    if (!m) return m.error();
    s.measurements_ = *m;
    auto e = s.writer_.add_stream(StreamKind::event, "events", "{\"tool\": \"proprio record array\"}");
    if (!e) return e.error();
    s.events_ = *e;
    return s;
  }

  Status add_cells_stream(const sa::StripArrayLayout& layout, std::span<const double> rest_pf,
                          std::span<const double> row_parasitic_pf, double rest_s) {
    nlohmann::json meta = layout_meta(layout);
    meta["unit"] = "F";
    meta["values"] =
        "one per layout cell, in 'cells' order; 0 where the frame could not solve the cell (unobservable or dead)";
    meta["rest_pf"] = std::vector<double>(rest_pf.begin(), rest_pf.end());
    meta["row_parasitic_pf"] = std::vector<double>(row_parasitic_pf.begin(), row_parasitic_pf.end());
    meta["rest_seconds"] = rest_s;
    meta["time_base"] = time_base_;
    meta["strain"] = "C/C0: each value over rest_pf (1e-12 F per pF)";
    meta["layout_toml"] = layout.to_toml();
    auto c = writer_.add_stream(StreamKind::capacitance, "array/cells", text(meta));
    if (!c) return c.error();
    cells_ = *c;
    return {};
  }

  Status measurements(std::span<const StretchSample> samples) {
    if (samples.empty()) return {};
    raw_.bytes.clear();
    for (const StretchSample& s : samples) pack(s, raw_.bytes);
    return writer_.write(measurements_, raw_, samples.front().time_ns);
  }
  Status cells(const sa::CellFrame& f) {
    frame_.values_F.resize(f.cells_pf.size());
    for (std::size_t c = 0; c < f.cells_pf.size(); ++c) {
      const double v = f.valid(c) ? static_cast<double>(f.cells_pf[c]) : 0.0;
      frame_.values_F[c] = std::isfinite(v) ? v * 1e-12 : 0.0;
    }
    return writer_.write(cells_, frame_, f.time_ns);
  }
  Status event(const std::string& text, TimeNs t) { return writer_.write(events_, Event{text}, t); }
  Status flush() { return writer_.flush(); }
  Status close() { return writer_.close(); }

 private:
  explicit Session(RecordingWriter w) : writer_(std::move(w)) {}
  RecordingWriter writer_;
  StreamId measurements_ = 0, cells_ = 0, events_ = 0;
  std::string time_base_;
  RawBytes raw_;
  CapacitanceFrame frame_;
};

std::string describe_plan(std::size_t top, std::size_t bottom, bool single) {
  return std::to_string(top) + " x " + std::to_string(bottom) + " strips" +
         (single ? " with single strips" : " (pairs only)");
}

// What a recording does with the board's measurements, wherever they come
// from: the rest calibration, then the calibrated solve; events for restarts.
class ArrayRecorder {
 public:
  ArrayRecorder(const Args& a, const sa::StripArrayLayout& layout, Session& session, std::size_t rows)
      : a_(a), layout_(layout), session_(session), means_(rows) {}

  // A batch of measurements in time order (one pop of the device's queue, or a capture's report).
  Status add(std::span<const StretchSample> batch) {
    if (batch.empty()) return {};
    if (measurements_ == 0) first_sample_ns_ = batch.front().time_ns;
    measurements_ += batch.size();
    if (auto s = session_.measurements(batch); !s) return s;
    for (const StretchSample& s : batch) {
      if (have_epoch_ && s.epoch != last_epoch_) {
        nlohmann::json ev = {{"event", "board restart"}, {"epoch", s.epoch}};
        if (auto st = session_.event(text(ev), s.time_ns); !st) return st;
        std::printf("the board restarted (epoch %u)\n", s.epoch);
      }
      have_epoch_ = true;
      last_epoch_ = s.epoch;
    }
    if (calibrated()) return solve(batch);
    means_.add(batch);
    rest_samples_.insert(rest_samples_.end(), batch.begin(), batch.end());
    if (batch.back().time_ns - first_sample_ns_ >= seconds_to_ns(a_.rest_s))
      return finish_calibration(batch.back().time_ns);
    return {};
  }

  bool calibrated() const { return reader_.has_value(); }
  std::uint64_t measurements() const { return measurements_; }
  std::uint64_t frames() const { return frames_; }
  std::uint64_t frames_incomplete() const { return frames_incomplete_; }

 private:
  // Feeds the calibrated reader per report-sized chunk, so a backlog still yields every frame.
  Status solve(std::span<const StretchSample> samples) {
    for (std::size_t i = 0; i < samples.size(); i += kStretchMeasurementsPerReport) {
      const std::size_t n = std::min<std::size_t>(kStretchMeasurementsPerReport, samples.size() - i);
      if (!reader_->add(samples.subspan(i, n), frame_)) continue;
      ++frames_;
      if (!frame_.all_valid()) ++frames_incomplete_;
      if (auto s = session_.cells(frame_); !s) return s;
    }
    return {};
  }

  Status finish_calibration(TimeNs now) {
    auto m = means_.means(2);
    if (!m) return m.error();
    auto p = row_parasitics_at_rest(layout_, *m);
    if (!p) return p.error();
    StretchArrayReaderOptions ro;
    ro.row_parasitic_pf = *p;
    // Each cell's C0: its mean over the rest frames solved with the calibration.
    std::vector<double> sum(layout_.cell_count(), 0.0);
    std::vector<std::size_t> count(layout_.cell_count(), 0);
    {
      auto rest_reader = StretchArrayReader::create(layout_, ro);
      if (!rest_reader) return rest_reader.error();
      sa::CellFrame f = rest_reader->make_frame();
      const std::span<const StretchSample> rest(rest_samples_);
      for (std::size_t i = 0; i < rest.size(); i += kStretchMeasurementsPerReport) {
        if (!rest_reader->add(rest.subspan(i, std::min<std::size_t>(kStretchMeasurementsPerReport, rest.size() - i)),
                              f)) {
          continue;
        }
        for (std::size_t c = 0; c < f.cells_pf.size(); ++c) {
          if (f.valid(c) && std::isfinite(f.cells_pf[c])) {
            sum[c] += f.cells_pf[c];
            ++count[c];
          }
        }
      }
    }
    std::vector<double> c0(layout_.cell_count());
    std::string unsolved;
    std::size_t missing = 0;
    for (std::size_t c = 0; c < c0.size(); ++c) {
      if (count[c] == 0) {
        if (++missing <= 8) unsolved += (unsolved.empty() ? "" : ", ") + printable(layout_.cells[c].name, 40);
        continue;
      }
      c0[c] = sum[c] / static_cast<double>(count[c]);
    }
    if (missing > 0) {
      return make_error(Errc::unavailable, "rest calibration: " + std::to_string(missing) + " of " +
                                               std::to_string(c0.size()) + " cells were never solved at rest (" +
                                               unsolved + (missing > 8 ? ", ..." : "") +
                                               "); record a longer --rest-seconds, or check those cells' leads");
    }
    auto r = StretchArrayReader::create(layout_, ro);
    if (!r) return r.error();
    reader_.emplace(std::move(*r));
    frame_ = reader_->make_frame();
    if (auto s = session_.add_cells_stream(layout_, c0, *p, a_.rest_s); !s) return s;
    // The rest frames go into the cells stream too, solved with the calibration.
    if (auto s = solve(rest_samples_); !s) return s;
    const auto [lo, hi] = std::minmax_element(p->begin(), p->end());
    nlohmann::json ev = {{"event", "calibration done"},
                         {"rest_samples", rest_samples_.size()},
                         {"row_parasitic_pf_min", *lo},
                         {"row_parasitic_pf_max", *hi}};
    if (auto s = session_.event(text(ev), now); !s) return s;
    std::printf(
        "rest calibration done from %zu measurements: row parasitics %.2f to %.2f pF, C0 %.2f to %.2f pF; "
        "recording\n",
        rest_samples_.size(), *lo, *hi, *std::min_element(c0.begin(), c0.end()),
        *std::max_element(c0.begin(), c0.end()));
    std::fflush(stdout);
    rest_samples_.clear();
    rest_samples_.shrink_to_fit();
    return {};
  }

  const Args& a_;
  const sa::StripArrayLayout& layout_;
  Session& session_;
  StretchRowMeans means_;
  std::vector<StretchSample> rest_samples_;
  std::optional<StretchArrayReader> reader_;
  sa::CellFrame frame_;
  TimeNs first_sample_ns_ = 0;
  std::uint64_t measurements_ = 0, frames_ = 0, frames_incomplete_ = 0;
  std::uint32_t last_epoch_ = 0;
  bool have_epoch_ = false;
};

std::string mismatch_text(const StretchStreamStats& st, const sa::StripArrayLayout& layout, const Args& a,
                          const StretchArrayPlan& plan) {
  return "the board measures " + describe_plan(st.top_strips, st.bottom_strips, st.single_strips) +
         ", but the layout '" + printable(layout.name) + "' (" + a.layout + ") needs " +
         describe_plan(plan.top_strips, plan.bottom_strips, true) +
         "; plug in this layout's array, pass its layout file, or update the board's firmware to protocol 1.1";
}

// Closes a recording that ended early: an event saying why, the End record,
// and the file kept when it holds anything (removed otherwise).
int end_with_error(Session& session, const Args& a, bool keep, const Error& e, TimeNs now) {
  if (keep) {
    (void)session.event(text({{"event", "recording ended"}, {"why", e.message}}), now);
    if (auto s = session.close(); !s) std::fprintf(stderr, "error: %s\n", s.error().message.c_str());
    std::fprintf(stderr, "error: %s\nthe recording up to then is in %s\n", e.message.c_str(), a.out.c_str());
    return 1;
  }
  (void)session.close();
  std::error_code ec;
  fs::remove(a.out, ec);
  return report_error(e);
}

int finish(Session& session, const Args& a, const ArrayRecorder& rec, const StretchStreamStats& stream,
           std::uint64_t disconnects, bool interrupted, TimeNs end, double elapsed_s) {
  if (!rec.calibrated()) {
    return end_with_error(
        session, a, rec.measurements() > 0,
        Error{Errc::unavailable, "the recording ended during the rest calibration (" + fmt("%.1f s", elapsed_s) +
                                     " of --rest-seconds " + fmt("%g", a.rest_s) + "): no cells were solved"},
        end);
  }
  nlohmann::json ev = {{"event", "recording end"},           {"frames", rec.frames()},
                       {"measurements", rec.measurements()}, {"rows_lost", stream.lost},
                       {"restarts", stream.device_resets},   {"interrupted", interrupted}};
  (void)session.event(text(ev), end);
  if (auto s = session.close(); !s) return report_error(s.error());
  std::printf(
      "wrote %s: %llu cell frames (%llu with a cell unsolved), %llu measurements, %llu lost, %llu flagged, "
      "%llu board restart(s), %llu disconnect(s)\n",
      a.out.c_str(), ull(rec.frames()), ull(rec.frames_incomplete()), ull(rec.measurements()), ull(stream.lost),
      ull(stream.measurements_flagged()), ull(stream.device_resets), ull(disconnects));
  return 0;
}

// A capture file (`stretch-board emulate --layout L --out F`, or a board's
// hidraw bytes): decoded as the board's reports, in device time made
// continuous across restarts (there is no host clock to map it to).
int record_from_file(const Args& a, const sa::StripArrayLayout& layout, const StretchArrayPlan& plan,
                     StretchStreamOptions so, std::size_t rows) {
  auto session = Session::create(a, layout, "device µs, continued across board restarts (from a capture file)");
  if (!session) return report_error(session.error());
  ArrayRecorder rec(a, layout, *session, rows);
  StretchStreamDecoder decoder(so);
  std::array<StretchSample, kStretchMeasurementsPerReport> out;
  std::optional<Error> failed;
  std::int64_t epoch_offset_us = 0, last_us = 0;
  std::uint32_t epoch = 0;
  hid::CaptureReaderOptions ro;
  ro.max_bytes = kMaxCaptureBytes;
  const auto read =
      hid::read_capture_file(a.from_file, {&stretch_report_size_for_id}, ro, [&](const hid::CaptureFrame& f) {
        if (failed) return;
        const auto r = decoder.push(f.bytes, out);
        if (r.verdict != StretchReportVerdict::accepted) return;
        if (r.epoch != epoch) {
          // A restart starts the device clock again: go on from the last time, one period on.
          epoch = r.epoch;
          epoch_offset_us = last_us + 1 - r.device_time_us;
        }
        for (std::size_t i = 0; i < r.sample_count; ++i) {
          out[i].time_ns = (out[i].device_time_us + epoch_offset_us) * 1000;
          last_us = std::max(last_us, out[i].device_time_us + epoch_offset_us);
        }
        if (auto s = rec.add(std::span<const StretchSample>(out.data(), r.sample_count)); !s) failed = s.error();
      });
  const StretchStreamStats& st = decoder.stats();
  const TimeNs end = last_us * 1000;
  if (!read) return end_with_error(*session, a, rec.measurements() > 0, read.error(), end);
  if (failed) return end_with_error(*session, a, rec.measurements() > 0, *failed, end);
  if (rec.measurements() == 0) {
    return end_with_error(
        *session, a, false,
        Error{Errc::invalid_argument, a.from_file + ": no measurement this layout can use" +
                                          (st.wrong_layout > 0 ? ": " + mismatch_text(st, layout, a, plan)
                                                               : std::string("; is it a stretch board capture?"))},
        end);
  }
  return finish(*session, a, rec, st, 0, false, end, ns_to_seconds(end));
}

int run(const Args& a) {
  const bool faults = !a.faults.unplugs.empty() || a.faults.drop > 0 || a.faults.duplicate > 0 ||
                      a.faults.corrupt > 0 || a.faults.reorder > 0 || a.faults.clock_ppm != 0.0 ||
                      a.faults.start_timestamp_us != 0;
  if (!a.emulate && (!a.emulate_layout.empty() || faults)) {
    return report_error(
        Error{Errc::invalid_argument,
              "--emulate-layout and the fault options (--unplug, --drop, ...) apply only to --emulate"});
  }
  if ((a.emulate || !a.from_file.empty()) && (!a.hid.path.empty() || !a.hid.serial.empty())) {
    return report_error(
        Error{Errc::invalid_argument, "--path and --serial choose a real board; not with --emulate or --from-file"});
  }
  if (a.emulate && !a.from_file.empty()) {
    return report_error(Error{Errc::invalid_argument, "--emulate and --from-file are two different boards; pick one"});
  }
  if (a.hid.seconds > 0 && a.hid.seconds <= a.rest_s) {
    return report_error(Error{Errc::invalid_argument,
                              "--seconds " + fmt("%g", a.hid.seconds) + " leaves nothing after the rest calibration (" +
                                  "--rest-seconds " + fmt("%g", a.rest_s) + "); --seconds counts the whole recording"});
  }
  auto layout = sa::StripArrayLayout::load(a.layout);
  if (!layout) return report_error(layout.error());
  auto plan = stretch_array_plan(*layout);
  if (!plan) return report_error(plan.error());
  if (auto s = check_output_path(a.out, "recording"); !s) return report_error(s.error());
  std::error_code ec;
  // A FIFO would block the writer's open until someone reads it; a device would lose the session.
  if (fs::exists(a.out, ec) && !fs::is_regular_file(a.out, ec)) {
    return report_error(Error{Errc::invalid_argument,
                              "cannot write the recording to '" + a.out + "': it exists and is not a regular file"});
  }
  if (!a.force && fs::exists(a.out, ec)) {
    return report_error(Error{Errc::invalid_argument, "'" + a.out + "' exists; pass --force to replace it"});
  }
  // A reader now, to refuse an unreadable layout before the board is opened;
  // the calibrated one comes after the rest phase.
  auto probe = StretchArrayReader::create(*layout);
  if (!probe) return report_error(probe.error());
  const std::size_t rows = probe->rows();
  if (!a.from_file.empty()) {
    // Refused before the recording is created, with the reader's messages (a FIFO, /dev/zero, a folder).
    if (auto in = open_input_file(a.from_file, "capture file"); !in) return report_error(in.error());
    if (auto s = check_output_path(a.out, "recording"); !s) return report_error(s.error());
    return record_from_file(a, *layout, *plan, probe->stream_options(), rows);
  }

  std::optional<Emulation> emulation;
  std::unique_ptr<hid::HidTransport> transport;
  std::string what;
  if (a.emulate) {
    auto e = make_emulation(a, *layout);
    if (!e) return report_error(e.error());
    emulation.emplace(std::move(*e));
    transport = std::make_unique<hid::FakeHidTransport>(emulation->link);
    what = "the emulated board";
  } else {
    auto sel = monitor_selector(a.hid, stretch_board_selector());
    if (!sel) return report_error(sel.error());
    if (a.hid.path.empty()) {
      auto found = hid::enumerate_hid_devices(sel->vendor_id, sel->product_id);
      if (!found) return report_error(found.error());
      if (found->empty()) {
        return report_error(Error{Errc::not_found, "no stretch board found (USB " + a.hid.vid + ":" + a.hid.pid +
                                                       "); plug it in, check 'proprio stretch-board list', or record "
                                                       "the emulated board with --emulate"});
      }
    }
    what = sel->describe();
    transport = std::make_unique<hid::HidapiTransport>(*sel);
  }

  StretchDeviceOptions o;
  o.stream = probe->stream_options();
  o.deliver_flagged = true;  // recorded with their status; the reader leaves them out of the solve
  if (a.emulate) o.reconnect_backoff_max_ns = 200 * kNsPerMillisecond;
  StretchDevice device(std::move(transport), o);
  device.set_state_callback(print_link_state);

  auto session = Session::create(a, *layout, "CLOCK_MONOTONIC ns");
  if (!session) return report_error(session.error());
  ArrayRecorder rec(a, *layout, *session, rows);
  const MonotonicClock& clock = MonotonicClock::instance();
  auto fail = [&](const Error& e) {
    device.stop();
    if (emulation) emulation->server->stop();
    // Nothing worth keeping before the first measurement: a failed start leaves no file behind.
    return end_with_error(*session, a, rec.measurements() > 0, e, clock.now_ns());
  };

  std::printf(
      "recording %s from %s: %s, %zu cells, %zu rows; the first %g s are the rest calibration (keep the "
      "sleeve flat and unstretched), then %s\n",
      printable(layout->name).c_str(), what.c_str(), describe_plan(plan->top_strips, plan->bottom_strips, true).c_str(),
      layout->cell_count(), rows, a.rest_s,
      a.hid.seconds > 0 ? ("until " + fmt("%g", a.hid.seconds) + " s").c_str() : "until Ctrl-C");
  std::fflush(stdout);
  if (auto s = device.start(); !s) return fail(s.error());
  if (emulation) {
    emulation->server->start();
    const TimeNs zero = emulation->server->time_zero_ns();
    for (const StretchOutage& u : emulation->options.faults.unplugs) {
      emulation->link->schedule_unplug(zero + u.at_ns, u.duration_ns);
    }
  }

  g_sigint_stop.store(false);
  auto previous = std::signal(SIGINT, on_sigint_stop);
  struct RestoreSignal {
    void (*handler)(int);
    ~RestoreSignal() { std::signal(SIGINT, handler); }
  } restore{previous};

  const TimeNs started = clock.now_ns();
  const DurationNs interval = seconds_to_ns(a.hid.interval_s);
  TimeNs next_report = started + interval;
  std::vector<StretchSample> batch;
  batch.reserve(4096);
  std::uint64_t last_disconnects = 0, last_connects = 0, prev_frames = 0;
  std::uint64_t wrong_layout_at_start = 0;  // refused reports before the recording began
  TimeNs last_data_wall = started, prev_wall = started;
  bool streaming_seen = false;
  StretchSample sample;
  while (true) {
    batch.clear();
    while (batch.size() < batch.capacity() && device.pop(sample)) batch.push_back(sample);
    const TimeNs now = clock.now_ns();
    if (!batch.empty()) {
      if (rec.measurements() == 0) wrong_layout_at_start = device.stats().stream.wrong_layout;
      last_data_wall = now;
      if (auto s = rec.add(batch); !s) return fail(s.error());
    }

    const StretchDeviceStats st = device.stats();
    if (st.state == hid::LinkState::streaming) streaming_seen = true;
    // Unplugs and returns, as events (the counters catch a change between two polls).
    if (rec.measurements() > 0 && st.disconnects != last_disconnects) {
      (void)session->event("{\"event\": \"board unplugged\"}", now);
    }
    if (rec.measurements() > 0 && st.connects != last_connects && last_connects > 0) {
      (void)session->event("{\"event\": \"board back\"}", now);
    }
    last_disconnects = st.disconnects;
    last_connects = st.connects;

    if (rec.measurements() == 0) {
      // Refused reports: another array, another layout file, or firmware without single strips.
      if (st.stream.wrong_layout >= 3) {
        return fail(Error{Errc::invalid_argument,
                          what + " does not match the layout: " + mismatch_text(st.stream, *layout, a, *plan)});
      }
      if (now - started > seconds_to_ns(a.connect_timeout_s)) {
        std::string why = what + " sent no measurement this layout can use within " +
                          fmt("%.1f s", a.connect_timeout_s) + " (--connect-timeout)";
        why += streaming_seen ? "; 'proprio stretch-board monitor' shows what it sends"
                              : "; is it plugged in? 'proprio stretch-board list' and 'monitor' check it";
        return fail(Error{Errc::unavailable, why});
      }
    } else if (now - last_data_wall > seconds_to_ns(a.disconnect_timeout_s)) {
      return fail(Error{Errc::unavailable,
                        what + (st.state == hid::LinkState::streaming ? " stopped sending" : " was unplugged") +
                            " and did not come back within " + fmt("%.1f s", a.disconnect_timeout_s) +
                            " (--disconnect-timeout)" +
                            (st.stream.wrong_layout > wrong_layout_at_start
                                 ? "; it came back as another board: " + mismatch_text(st.stream, *layout, a, *plan)
                                 : "")});
    }

    if (now >= next_report) {
      next_report += interval;
      const double dt = ns_to_seconds(now - prev_wall);
      std::printf(
          "%7.1f s %-11s %-12s %6llu frames (%4.1f/s) %8llu measurements, %llu rows lost, %llu flagged, "
          "%llu restart(s)\n",
          ns_to_seconds(now - started), rec.calibrated() ? "recording" : "calibrating", hid::to_string(st.state),
          ull(rec.frames()), dt > 0 ? static_cast<double>(rec.frames() - prev_frames) / dt : 0.0,
          ull(rec.measurements()), ull(st.stream.lost), ull(st.stream.measurements_flagged()),
          ull(st.stream.device_resets));
      std::fflush(stdout);
      prev_frames = rec.frames();
      prev_wall = now;
      if (auto s = session->flush(); !s) return fail(s.error());
    }
    if (g_sigint_stop.load()) break;
    if (a.hid.seconds > 0 && now - started >= seconds_to_ns(a.hid.seconds)) break;
    if (batch.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }

  device.stop();
  if (emulation) emulation->server->stop();
  batch.clear();
  while (device.pop(sample)) batch.push_back(sample);
  if (auto s = rec.add(batch); !s) return fail(s.error());
  const TimeNs end = clock.now_ns();
  const StretchDeviceStats st = device.stats();
  return finish(*session, a, rec, st.stream, st.disconnects, g_sigint_stop.load(), end, ns_to_seconds(end - started));
}

}  // namespace record_array
}  // namespace

void add_record_array_command(CLI::App& app, int& exit_code) {
  auto a = std::make_shared<record_array::Args>();
  CLI::App* cmd = add_command(app, "record array");
  cmd->add_option("--layout", a->layout, "The array's layout (TOML; 'proprio array layout' writes one)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Recording to write (.prec)")->required();
  cmd->add_flag("--force", a->force, "Replace an existing --out");
  cmd->add_option("--rest-seconds", a->rest_s, "The rest calibration at the start: the sleeve flat and unstretched, s")
      ->check(CLI::Range(0.5, 600.0))
      ->capture_default_str();
  add_hid_monitor_options(*cmd, a->hid, "Open the board with this USB serial number");
  cmd->add_option("--connect-timeout", a->connect_timeout_s,
                  "No usable measurement this long after the start ends it with an error, s")
      ->check(CLI::Range(0.5, 600.0))
      ->capture_default_str();
  cmd->add_option("--disconnect-timeout", a->disconnect_timeout_s,
                  "A board silent or unplugged this long ends the recording (exit status 1; the file keeps what "
                  "came before), s")
      ->check(CLI::Range(0.1, 3600.0))
      ->capture_default_str();
  cmd->add_flag("--emulate", a->emulate,
                "Record the board emulator instead of a board on USB: it serves the layout over the in-memory HID "
                "link in real time, the sleeve at rest, then slowly stretching");
  cmd->add_option("--emulate-layout", a->emulate_layout,
                  "--emulate: the emulated board serves this layout instead (a board that does not match --layout)")
      ->check(CLI::ExistingFile);
  add_board_emulator_fault_options(*cmd, a->faults, "--emulate: the board");
  cmd->add_option("--from-file", a->from_file,
                  "Record a capture file instead of a live board ('proprio stretch-board emulate --layout L --out F', "
                  "or a board's hidraw bytes); times are then the board's own clock")
      ->check(CLI::ExistingFile);
  cmd->callback([a, &exit_code] { exit_code = record_array::run(*a); });
}

}  // namespace proprio::cli
