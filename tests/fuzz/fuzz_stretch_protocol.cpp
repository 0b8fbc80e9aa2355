// Fuzzes the stretch read-out board's HID protocol through the harness every
// protocol shares (protocol_fuzz_template.hpp: one report to every decoder,
// the input as a report stream, and again with CRCs recomputed): the report
// decoders, the emulator's command handler (pairs only, and with protocol
// 1.1's single strips), the stream decoder (also with an expected layout and
// with single strips required), the array reader behind it (a 3 x 2 grid's
// matrix read-out) and the clock alignment. Seeds:
// corpus/stretch_protocol/ (regenerate with PROPRIO_REGEN_CORPUS=1, see
// tests/unit/input/stretch_board/test_stretch_emulator.cpp). Frames take the size their report ID
// gives; unknown IDs take 64 bytes, so that every byte is consumed.
#include <vector>

#include "proprio/stretch_array/array_layout.hpp"
#include "proprio/stretch_board/stretch_array_reader.hpp"
#include "proprio/stretch_board/stretch_emulator.hpp"
#include "proprio/stretch_board/stretch_protocol.hpp"
#include "proprio/stretch_board/stretch_stream.hpp"
#include "protocol_fuzz_template.hpp"

namespace {

using namespace proprio;
using namespace proprio::devices;
using fuzz::require;

// The board's timed stream: up to 12 measurements per report, clocked on the last one.
struct StretchStream {
  using Decoder = StretchStreamDecoder;
  using Sample = StretchSample;
  using Result = StretchPushResult;
  // Accepted reports move forward within an epoch: measurement times never go back.
  struct State {
    std::int64_t newest_sequence_end = 0;
    std::uint32_t newest_epoch = 0;
    bool any = false;
  };
  static constexpr std::size_t kMaxSamplesPerReport = kStretchMeasurementsPerReport;
  static bool carries_device_time(const Result& r) {
    return r.verdict == StretchReportVerdict::accepted || r.verdict == StretchReportVerdict::duplicate ||
           r.verdict == StretchReportVerdict::late;
  }
  static std::uint32_t clock_observe_us(const Result& r) { return static_cast<std::uint32_t>(r.last_device_time_us); }
  static std::uint32_t clock_map_us(const Result& r) { return static_cast<std::uint32_t>(r.device_time_us); }
  static void check_result(const Result& r, std::span<const Sample> samples, State& state) {
    require(r.verdict == StretchReportVerdict::accepted || samples.empty());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const StretchSample& smp = samples[i];
      require(std::isfinite(smp.capacitance_pf) && smp.capacitance_pf >= 0.0);
      require(smp.combination < kStretchMaxCombinations);
      // A pair names both strips; a single-strip row (1.1) one, the other layer kStretchNoStrip.
      const bool top_ok = smp.top_strip < kStretchMaxStrips, bottom_ok = smp.bottom_strip < kStretchMaxStrips;
      require((top_ok || smp.top_strip == kStretchNoStrip) && (bottom_ok || smp.bottom_strip == kStretchNoStrip));
      require(top_ok || bottom_ok);
      require(smp.sequence == r.sequence + static_cast<std::int64_t>(i));
      if (i > 0) require(smp.device_time_us >= samples[i - 1].device_time_us);
    }
    if (r.verdict == StretchReportVerdict::accepted) {
      if (state.any && r.epoch == state.newest_epoch) require(r.sequence >= state.newest_sequence_end);
      require(r.epoch >= state.newest_epoch);
      state.newest_sequence_end = r.sequence + r.count;
      state.newest_epoch = r.epoch;
      state.any = true;
    }
    if (carries_device_time(r)) require(r.last_device_time_us >= r.device_time_us);
  }
  static void check_stats(const Decoder& decoder) {
    const StretchStreamStats& s = decoder.stats();
    require(s.accepted + s.duplicates + s.late + s.decode_errors + s.other_reports + s.wrong_layout == s.reports);
    require(fuzz::sum(s.decode_errors_by_code) == s.decode_errors);
    require(fuzz::sum(s.by_status) == s.measurements);
    require(fuzz::sum(s.flagged_by_combination) == s.measurements_flagged());
    require(s.measurements <= s.accepted * kStretchMeasurementsPerReport);
    require(std::isfinite(s.measurement_period_us) && s.measurement_period_us > 0.0);
  }
};

// The firmware's command handling: any bytes as commands, one after another
// a few milliseconds apart, and the board still measures and reports.
void check_emulator_commands(const fuzz::Frames& commands, bool single_strips) {
  StretchEmulatorOptions o;
  o.top_strips = 2;
  o.bottom_strips = 3;
  o.single_strips = single_strips;
  auto emulator = StretchEmulator::create(o, [](std::size_t c, TimeNs) { return 10.0 + static_cast<double>(c); });
  require(emulator.ok());
  std::vector<StretchEmulatedReport> out;
  TimeNs t = 0;
  for (const auto& command : commands) {
    const StretchCommandResult result = emulator->handle_command(command, t);
    require(static_cast<std::uint8_t>(result) <= static_cast<std::uint8_t>(StretchCommandResult::bad_report));
    t += commands.size() == 1 ? 30 * kNsPerMillisecond : 5 * kNsPerMillisecond;
    out.clear();
    emulator->advance_to(t, out);
    for (const auto& r : out) {
      const auto data = decode_stretch_data_report(r.bytes);
      require(data.ok() && data->single_strips() == single_strips &&
              data->combination_count() == o.combination_count());
    }
    const auto info = decode_stretch_info_report(emulator->info_report(t));
    require(info.ok() && info->single_strips == single_strips && info->combination_count() == o.combination_count());
  }
}

struct StretchProtocol {
  static constexpr std::size_t kMaxFrames = SIZE_MAX;
  static constexpr bool kFixCrcOfShortFrames = true;
  static std::size_t frame_size(std::uint8_t id) {
    const std::size_t size = stretch_report_size_for_id(id);
    return size == 0 ? kStretchDataReportSize : size;
  }

  static void check_reports(std::span<const std::uint8_t> bytes) {
    fuzz::check_form<StretchDataReport>(
        bytes, [](auto b, auto& v) { return decode_stretch_data_report(b, v); },
        [](const auto& v) { return encode_stretch_data_report(v); }, fuzz::OnReject::may_write,
        [](const StretchDataReport& data) {
          require(data.count >= 1 && data.count <= kStretchMeasurementsPerReport);
          require(data.top_strips >= 1 && data.top_strips <= kStretchMaxStrips);
          require(data.bottom_strips >= 1 && data.bottom_strips <= kStretchMaxStrips);
          require(data.combination_count() <= kStretchMaxCombinations);
          require(!data.single_strips() || (data.version & 0x0F) >= 1);
          for (std::size_t i = 0; i < kStretchMeasurementsPerReport; ++i) {
            const StretchMeasurementRaw& m = data.measurements[i];
            if (i >= data.count) {
              require(m == StretchMeasurementRaw{});
              continue;
            }
            require(m.combination < data.combination_count());
            // Single-strip rows only from a 1.1 report that says so.
            if (!data.single_strips()) require(m.combination < data.top_strips * data.bottom_strips);
            require(m.value <= kStretchMaxCapacitanceCount);
            const double pf = stretch_count_to_pf(m.value);
            require(pf >= 0.0 && pf <= kStretchWireFullScalePf);
          }
        });
    fuzz::check_form<StretchDeviceInfo>(
        bytes, [](auto b, auto& v) { return decode_stretch_info_report(b, v); },
        [](const auto& v) { return encode_stretch_info_report(v); }, fuzz::OnReject::may_write,
        [](const StretchDeviceInfo& info) {
          require(info.full_scale_ff >= 1 && info.full_scale_ff <= kStretchMaxCapacitanceCount);
          require(info.combination_count() <= kStretchMaxCombinations);
          require(!info.single_strips || (info.version & 0x0F) >= 1);
        });
    fuzz::check_form<StretchCommand>(
        bytes, [](auto b, auto& v) { return decode_stretch_command(b, v); },
        [](const auto& v) { return encode_stretch_command(v); }, fuzz::OnReject::may_write, [](const auto&) {});
  }
  // The whole input as one command.
  static void check_input(std::span<const std::uint8_t> bytes) {
    check_emulator_commands({fuzz::Frame(bytes.begin(), bytes.end())}, false);
  }

  static void check_streams(const fuzz::Frames& frames, bool crc_fixed) {
    fuzz::check_timed_stream<StretchStream>(frames);
    if (!crc_fixed) return;
    // Commands with valid CRCs get past the firmware's CRC check to its field checks.
    check_emulator_commands(frames, false);
    check_emulator_commands(frames, true);
    // A decoder told the layout: what it accepts has it, or it said wrong_layout.
    StretchStreamOptions o;
    o.expected_top_strips = 13;
    o.expected_bottom_strips = 14;
    const StretchStreamStats s = fuzz::check_timed_stream<StretchStream>(frames, o);
    require(s.accepted == 0 || (s.top_strips == 13 && s.bottom_strips == 14) || s.wrong_layout > 0);
    // One that needs single strips accepts only reports that carry them.
    StretchStreamOptions so;
    so.require_single_strips = true;
    const StretchStreamStats ss = fuzz::check_timed_stream<StretchStream>(frames, so);
    require(ss.accepted == 0 || ss.single_strips || ss.wrong_layout > 0);
    check_array_reader(frames);
  }

  // The host's array path on the stream: a 3 x 2 grid (11 rows with single
  // strips), its frames the layout's size and every row either used or not.
  static void check_array_reader(const fuzz::Frames& frames) {
    static const stretch_array::StripArrayLayout layout =
        stretch_array::StripArrayLayout::grid("fuzz", 3, 2, 0.01, 0.005);
    auto reader = StretchArrayReader::create(layout);
    require(reader.ok());
    stretch_array::CellFrame frame = reader->make_frame();
    TimeNs t = 0;
    for (const auto& f : frames) {
      t += kNsPerMillisecond;
      if (!reader->push_report(f, t, frame).frame) continue;
      require(frame.cells_pf.size() == layout.cell_count() && frame.status.size() == layout.cell_count());
      require(frame.rows_used + frame.rows_excluded == reader->rows());
      for (std::size_t c = 0; c < layout.cell_count(); ++c) {
        if (frame.valid(c)) require(std::isfinite(frame.cells_pf[c]));
      }
    }
    const StretchArrayReaderStats& rs = reader->stats();
    require(rs.measurements + rs.out_of_plan == reader->stream().stats().measurements);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return proprio::fuzz::fuzz_protocol<StretchProtocol>(data, size);
}
