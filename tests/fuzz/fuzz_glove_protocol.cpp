// Fuzzes the IMU glove board's HID protocol through the harness every
// protocol shares (protocol_fuzz_template.hpp: one report to every decoder,
// the input as a report stream, and again with CRCs recomputed): the report
// decoders, the stream decoder and the clock alignment behind it. Seeds:
// corpus/glove_protocol/ (regenerate with PROPRIO_REGEN_CORPUS=1, see
// tests/unit/input/imu_glove_board/test_glove_emulator.cpp). Frames take the size their report ID
// gives; unknown IDs take 64 bytes, so that every byte is consumed.
#include "proprio/imu_glove_board/imu_glove_protocol.hpp"
#include "proprio/imu_glove_board/imu_glove_stream.hpp"
#include "protocol_fuzz_template.hpp"

namespace {

using namespace proprio;
using namespace proprio::devices;
using fuzz::require;

// The IMU glove's timed stream: samples of up to kImuGloveImusPerReport IMUs, each report's timestamp clocked.
struct ImuGloveStream {
  using Decoder = ImuGloveStreamDecoder;
  using Sample = ImuGloveSample;
  using Result = ImuGlovePushResult;
  struct State {};
  static constexpr std::size_t kMaxSamplesPerReport = kImuGloveImusPerReport;
  static bool carries_device_time(const Result& r) {
    return r.verdict == ImuGloveReportVerdict::accepted || r.verdict == ImuGloveReportVerdict::duplicate ||
           r.verdict == ImuGloveReportVerdict::late;
  }
  static std::uint32_t clock_observe_us(const Result& r) { return r.timestamp_us; }
  static std::uint32_t clock_map_us(const Result& r) { return r.timestamp_us; }
  static void check_result(const Result&, std::span<const Sample> samples, State&) {
    for (const Sample& s : samples) {
      require(s.imu.accel_mps2.allFinite() && s.imu.gyro_radps.allFinite());
      require(s.imu.sensor_id < kImuGloveMaxImus);
    }
  }
  static void check_stats(const Decoder& decoder) {
    const ImuGloveStreamStats& s = decoder.stats();
    require(s.accepted + s.duplicates + s.late + s.decode_errors + s.other_reports == s.reports);
    require(fuzz::sum(s.decode_errors_by_code) == s.decode_errors);
  }
};

struct ImuGloveProtocol {
  static constexpr std::size_t kMaxFrames = SIZE_MAX;
  static constexpr bool kFixCrcOfShortFrames = true;
  static std::size_t frame_size(std::uint8_t id) {
    const std::size_t size = report_size_for_id(id);
    return size == 0 ? kImuGloveDataReportSize : size;
  }

  static void check_reports(std::span<const std::uint8_t> bytes) {
    fuzz::check_form<ImuGloveDataReport>(
        bytes, [](auto b, auto& v) { return decode_data_report(b, v); },
        [](const auto& v) { return encode_data_report(v); }, fuzz::OnReject::may_write,
        [](const ImuGloveDataReport& data) {
          require(data.block_count() >= 1 && data.block_count() <= kImuGloveImusPerReport);
          for (std::size_t i = 0; i < data.block_count(); ++i) {
            const ImuSample smp = to_imu_sample(data.imus[i], static_cast<std::uint16_t>(data.first_imu + i),
                                                data.accel_range, data.gyro_range);
            require(smp.accel_mps2.allFinite() && smp.gyro_radps.allFinite());
            require(smp.accel_mps2.cwiseAbs().maxCoeff() <= accel_full_scale_mps2(data.accel_range) * 1.01);
          }
        });
    fuzz::check_form<ImuGloveDeviceInfo>(
        bytes, [](auto b, auto& v) { return decode_info_report(b, v); },
        [](const auto& v) { return encode_info_report(v); }, fuzz::OnReject::may_write, [](const auto&) {});
    fuzz::check_form<ImuGloveCommand>(
        bytes, [](auto b, auto& v) { return decode_command(b, v); }, [](const auto& v) { return encode_command(v); },
        fuzz::OnReject::may_write, [](const auto&) {});
  }

  static void check_streams(const fuzz::Frames& frames, bool) { fuzz::check_timed_stream<ImuGloveStream>(frames); }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return proprio::fuzz::fuzz_protocol<ImuGloveProtocol>(data, size);
}
