// Fuzzes the FTM read-out board's HID protocol through the harness every
// protocol shares (protocol_fuzz_template.hpp: one report to every decoder,
// the input as a report stream, and again with CRCs recomputed): the report
// decoders, the wire-to-contract unit conversions, the emulator's command
// handler, the stream decoder and the clock alignment behind it. Seeds:
// corpus/ftm_protocol/ (regenerate with PROPRIO_REGEN_CORPUS=1, see
// tests/unit/input/ftm_board/test_ftm_board_emulator.cpp). Frames take the
// size their report ID gives; unknown IDs take 64 bytes.
#include <memory>
#include <vector>

#include "proprio/ftm_board/ftm_emulator.hpp"
#include "proprio/ftm_board/ftm_protocol.hpp"
#include "proprio/ftm_board/ftm_stream.hpp"
#include "protocol_fuzz_template.hpp"

namespace {

using namespace proprio;
using namespace proprio::devices;
using fuzz::require;

bool finite_imu(const ftm::FtmImuSample& s) {
  return s.accel_mps2.allFinite() && s.gyro_radps.allFinite() && s.mag_uT.allFinite();
}

struct FtmStream {
  using Decoder = FtmStreamDecoder;
  using Sample = FtmBoardSample;
  using Result = FtmPushResult;
  // Accepted reports move forward within their channel and epoch.
  struct State {
    std::uint32_t newest_epoch = 0;
  };
  static constexpr std::size_t kMaxSamplesPerReport = kFtmMaxSamplesPerReport;
  static bool carries_device_time(const Result& r) {
    return r.verdict == FtmReportVerdict::accepted || r.verdict == FtmReportVerdict::duplicate ||
           r.verdict == FtmReportVerdict::late;
  }
  static std::uint32_t clock_observe_us(const Result& r) { return static_cast<std::uint32_t>(r.last_device_time_us); }
  static std::uint32_t clock_map_us(const Result& r) { return static_cast<std::uint32_t>(r.device_time_us); }
  static void check_result(const Result& r, std::span<const Sample> samples, State& state) {
    require(r.verdict == FtmReportVerdict::accepted || samples.empty());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const FtmBoardSample& s = samples[i];
      if (s.event.kind == ftm::FtmEvent::Kind::imu) {
        require(r.imu && s.event.index < ftm::kFtmImuCount);
        require(finite_imu(s.event.imu));
        require(s.device_time_us == r.device_time_us && s.sequence == r.sequence);
      } else {
        require(!r.imu && s.event.index < ftm::kFtmBendCount);
        require(std::isfinite(s.event.bend.capacitance_pF) && s.event.bend.capacitance_pF >= 0.0);
        require(s.sequence == r.sequence + static_cast<std::int64_t>(i / ftm::kFtmBendCount));
        require(s.device_time_us >= r.device_time_us && s.device_time_us <= r.last_device_time_us);
      }
      require(s.event.time_ns() == 0);  // the decoder alone does not map times
    }
    if (r.verdict == FtmReportVerdict::accepted) {
      require(r.epoch >= state.newest_epoch);
      state.newest_epoch = r.epoch;
    }
    if (carries_device_time(r)) require(r.last_device_time_us >= r.device_time_us);
  }
  static void check_stats(const Decoder& decoder) {
    const FtmStreamStats& s = decoder.stats();
    require(s.accepted + s.duplicates + s.late + s.decode_errors + s.other_reports == s.reports);
    require(fuzz::sum(s.decode_errors_by_code) == s.decode_errors);
    require(s.imu_reports + s.bend_reports == s.accepted);
    require(s.imu_samples == s.imu_reports * kFtmImusPerReport);
    require(s.bend_samples <= s.bend_reports * kFtmMaxSamplesPerReport);
    require(s.imu_unusable <= s.imu_samples && s.mag_overflows <= s.imu_samples && s.mag_fresh <= s.imu_samples);
    require(s.bend_unusable <= s.bend_samples);
  }
};

// A feed with nothing to say: the emulator still ticks (stale samples).
struct FtmFuzzQuietFeed final : ftm::FtmSampleFeed {
  void advance(TimeNs, std::vector<ftm::FtmEvent>&) override {}
};

// The firmware's command handling: any bytes as commands, a few ms apart, and
// the board still reports what decodes.
void check_emulator_commands(const fuzz::Frames& commands) {
  auto emulator = FtmBoardEmulator::create({}, std::make_unique<FtmFuzzQuietFeed>());
  require(emulator.ok());
  std::vector<FtmEmulatedReport> out;
  TimeNs t = 0;
  for (const auto& command : commands) {
    const FtmCommandResult result = emulator->handle_command(command, t);
    require(static_cast<std::uint8_t>(result) <= static_cast<std::uint8_t>(FtmCommandResult::bad_report));
    t += commands.size() == 1 ? 30 * kNsPerMillisecond : 5 * kNsPerMillisecond;
    out.clear();
    emulator->advance_to(t, out);
    for (const auto& r : out) {
      require(r.bytes[0] == static_cast<std::uint8_t>(FtmReportId::imu) ? decode_ftm_imu_report(r.bytes).ok()
                                                                       : decode_ftm_bend_report(r.bytes).ok());
    }
    require(decode_ftm_info_report(emulator->info_report(t)).ok());
  }
}

struct FtmProtocol {
  static constexpr std::size_t kMaxFrames = SIZE_MAX;
  static constexpr bool kFixCrcOfShortFrames = true;
  static std::size_t frame_size(std::uint8_t id) {
    const std::size_t size = ftm_report_size_for_id(id);
    return size == 0 ? kFtmDataReportSize : size;
  }

  static void check_reports(std::span<const std::uint8_t> bytes) {
    fuzz::check_form<FtmImuReport>(
        bytes, [](auto b, auto& v) { return decode_ftm_imu_report(b, v); },
        [](const auto& v) { return encode_ftm_imu_report(v); }, fuzz::OnReject::may_write,
        [](const FtmImuReport& r) {
          require(r.first_imu == 0 || r.first_imu == 2);
          require(r.period_us > 0);
          for (const FtmImuRaw& m : r.imus) {
            require((m.status & ~ftm_wire_status::imu_mask) == 0);
            const ftm::FtmImuSample s = imu_sample_from_wire(m, r.accel_range, r.gyro_range);
            require(finite_imu(s));
            // What the host reads back quantises to the same counts, unless the
            // board said the read failed (then the values mean nothing and become zeros).
            const FtmImuRaw again = quantise_imu(s, r.accel_range, r.gyro_range);
            if (m.status & ftm::sample_status::sensor_error) {
              require(again.accel == std::array<std::int16_t, 3>{} && again.status & ftm::sample_status::sensor_error);
            } else {
              require(again.accel == m.accel && again.gyro == m.gyro);
            }
          }
        });
    fuzz::check_form<FtmBendReport>(
        bytes, [](auto b, auto& v) { return decode_ftm_bend_report(b, v); },
        [](const auto& v) { return encode_ftm_bend_report(v); }, fuzz::OnReject::may_write,
        [](const FtmBendReport& r) {
          require(r.count >= 1 && r.count <= kFtmBendSamplesPerReport);
          for (std::size_t i = 0; i < kFtmBendSamplesPerReport; ++i) {
            for (const FtmBendRaw& m : r.samples[i]) {
              if (i >= r.count) {
                require(m == FtmBendRaw{});
                continue;
              }
              const ftm::FtmBendSample s = bend_sample_from_wire(m);
              require(std::isfinite(s.capacitance_pF) && s.capacitance_pF >= 0.0);
            }
          }
        });
    fuzz::check_form<FtmDeviceInfo>(
        bytes, [](auto b, auto& v) { return decode_ftm_info_report(b, v); },
        [](const auto& v) { return encode_ftm_info_report(v); }, fuzz::OnReject::may_write,
        [](const FtmDeviceInfo& info) {
          require(info.imu_rate_hz >= kFtmMinImuRateHz && info.imu_rate_hz <= kFtmMaxImuRateHz);
          require(info.bend_rate_hz >= kFtmMinBendRateHz && info.bend_rate_hz <= kFtmMaxBendRateHz);
        });
    fuzz::check_form<FtmCommand>(
        bytes, [](auto b, auto& v) { return decode_ftm_command(b, v); },
        [](const auto& v) { return encode_ftm_command(v); }, fuzz::OnReject::may_write, [](const auto&) {});
  }
  static void check_input(std::span<const std::uint8_t> bytes) {
    check_emulator_commands({fuzz::Frame(bytes.begin(), bytes.end())});
  }

  static void check_streams(const fuzz::Frames& frames, bool crc_fixed) {
    fuzz::check_timed_stream<FtmStream>(frames);
    if (crc_fixed) check_emulator_commands(frames);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return proprio::fuzz::fuzz_protocol<FtmProtocol>(data, size);
}
