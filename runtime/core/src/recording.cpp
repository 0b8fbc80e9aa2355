#include "proprio/core/recording.hpp"

#include "proprio/core/file_io.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <type_traits>
#include <utility>

namespace proprio {

namespace {

// 0x89 catches 7-bit transfers, CR LF and LF catch line-ending conversion, 0x1A
// stops DOS `type` (the PNG trick).
constexpr std::array<std::uint8_t, 8> kMagic = {0x89, 'P', 'R', 'P', '\r', '\n', 0x1A, '\n'};
constexpr std::uint32_t kFileHeaderBytes = 20;  // magic, major, minor, header length, CRC
constexpr std::uint32_t kMaxFileHeaderBytes = 4096;
constexpr std::size_t kRecordHeaderBytes = 16;
constexpr std::size_t kRecordCrcBytes = 4;
constexpr StreamId kFileLevelStream = 0xFFFF;  // End and other records that belong to no stream
constexpr std::size_t kMaxNameBytes = 255;
constexpr std::size_t kMarkerBytes = 13;

enum class RecordType : std::uint8_t { stream_def = 1, data = 2, end = 3 };

// ---------------------------------------------------------------- CRC-32
// Slicing-by-8: eight table lookups per 8 bytes, several times faster than the
// byte-wise loop and bit-identical to it.
constexpr auto kCrcTables = [] {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    t[0][i] = c;
  }
  for (std::size_t s = 1; s < 8; ++s) {
    for (std::size_t i = 0; i < 256; ++i) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFFu];
  }
  return t;
}();

// ---------------------------------------------------------------- little-endian bytes
// Byte by byte, so files are the same on any host; compilers fold these into single loads and stores.
template <int N>
std::uint64_t load_le(const std::uint8_t* p) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < N; ++i) v |= static_cast<std::uint64_t>(p[i]) << (8 * i);
  return v;
}
template <int N>
void store_le(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < N; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// Appends to out through a small staging buffer, so each field costs a store
// rather than a vector growth. The bytes are in out once the Encoder is gone.
class Encoder {
 public:
  explicit Encoder(std::vector<std::uint8_t>& out) noexcept : out_(out) {}
  Encoder(const Encoder&) = delete;
  Encoder& operator=(const Encoder&) = delete;
  ~Encoder() { flush(); }
  void u8(std::uint8_t v) { le<1>(v); }
  void u16(std::uint16_t v) { le<2>(v); }
  void u32(std::uint32_t v) { le<4>(v); }
  void u64(std::uint64_t v) { le<8>(v); }
  void f32(float v) { le<4>(std::bit_cast<std::uint32_t>(v)); }
  void f64(double v) { le<8>(std::bit_cast<std::uint64_t>(v)); }
  void vec3(const Vec3& v) { f64(v.x()), f64(v.y()), f64(v.z()); }
  // XrPosef order: orientation x, y, z, w, then position.
  void pose(const Pose& T) { f64(T.q.x()), f64(T.q.y()), f64(T.q.z()), f64(T.q.w()), vec3(T.p); }
  void bytes(const void* data, std::size_t n) {
    flush();
    const auto* b = static_cast<const std::uint8_t*>(data);
    out_.insert(out_.end(), b, b + n);
  }

 private:
  template <int N>
  void le(std::uint64_t v) {
    if (used_ + N > stage_.size()) flush();
    store_le<N>(stage_.data() + used_, v);
    used_ += N;
  }
  void flush() {
    out_.insert(out_.end(), stage_.begin(), stage_.begin() + static_cast<std::ptrdiff_t>(used_));
    used_ = 0;
  }
  std::vector<std::uint8_t>& out_;
  std::array<std::uint8_t, 512> stage_;
  std::size_t used_ = 0;
};

// Reads past the end yield zeros and set failed(); callers check once at the end.
class Decoder {
 public:
  explicit Decoder(std::span<const std::uint8_t> data) noexcept : d_(data) {}
  std::size_t remaining() const noexcept { return d_.size() - pos_; }
  bool failed() const noexcept { return failed_; }
  std::uint8_t u8() { return static_cast<std::uint8_t>(le<1>()); }
  std::uint16_t u16() { return static_cast<std::uint16_t>(le<2>()); }
  std::uint32_t u32() { return static_cast<std::uint32_t>(le<4>()); }
  std::uint64_t u64() { return le<8>(); }
  float f32() { return std::bit_cast<float>(static_cast<std::uint32_t>(le<4>())); }
  double f64() { return std::bit_cast<double>(le<8>()); }
  Vec3 vec3() {
    const double x = f64(), y = f64(), z = f64();
    return {x, y, z};
  }
  Pose pose() {
    const double qx = f64(), qy = f64(), qz = f64(), qw = f64();
    Pose T;
    T.q = Quat(qw, qx, qy, qz);
    T.p = vec3();
    return T;
  }
  std::span<const std::uint8_t> take(std::size_t n) {
    if (n > remaining()) return fail(), std::span<const std::uint8_t>{};
    const auto s = d_.subspan(pos_, n);
    pos_ += n;
    return s;
  }
  std::string string(std::size_t n) {
    const auto s = take(n);
    return {reinterpret_cast<const char*>(s.data()), s.size()};
  }

 private:
  void fail() noexcept {
    failed_ = true;
    pos_ = d_.size();
  }
  template <int N>
  std::uint64_t le() {
    if (std::size_t{N} > remaining()) return fail(), 0;
    const std::uint64_t v = load_le<N>(d_.data() + pos_);
    pos_ += N;
    return v;
  }
  std::span<const std::uint8_t> d_;
  std::size_t pos_ = 0;
  bool failed_ = false;
};

// ---------------------------------------------------------------- helpers
}  // namespace
// Named, not anonymous: the readers' and writers' Impls hold one, and in a
// unity build GCC warns about members of anonymous-namespace types.
namespace recording_detail {
struct FileCloser {
  void operator()(std::FILE* f) const noexcept { std::fclose(f); }
};
}  // namespace recording_detail
namespace {
using FilePtr = std::unique_ptr<std::FILE, recording_detail::FileCloser>;

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}
std::string hex32(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08x", v);
  return buf;
}

template <typename T, std::size_t I = 0>
constexpr StreamKind kind_of() {
  if constexpr (std::is_same_v<T, std::variant_alternative_t<I, RecordPayload>>) {
    return static_cast<StreamKind>(I + 1);
  } else {
    return kind_of<T, I + 1>();
  }
}
static_assert(kind_of<ImuSample>() == StreamKind::imu && kind_of<RawBytes>() == StreamKind::raw);

// Runs f, turning an escaping exception into an Error. Sizes are checked
// against the bytes present before anything is allocated, so this only fires
// when the process is genuinely out of memory.
template <typename F>
auto no_throw(F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const std::exception& e) {
    return make_error(Errc::io_error, std::string("recording: out of memory (") + e.what() + ")");
  }
}

// ---------------------------------------------------------------- validation
// Shared by writer (refuses) and reader (rejects the record). "" = fine.
std::string quat_problem(const Quat& q) {
  if (!q.coeffs().allFinite()) return "has a non-finite component (NaN or Inf)";
  const double n = q.norm();
  if (std::abs(n - 1.0) > kRecordingQuatNormTolerance) {
    return "has norm " + num(n) + ", not 1 within " + num(kRecordingQuatNormTolerance) + " (normalize it)";
  }
  return {};
}
// what() names the pose; it is only built when something is wrong.
template <typename Name>
std::string pose_problem(const Pose& T, Name what) {
  if (auto p = quat_problem(T.q); !p.empty()) return what() + " orientation " + p;
  if (!T.p.allFinite()) return what() + " position has a non-finite value (NaN or Inf)";
  return {};
}
std::string hand_problem(Handedness h) {
  if (h == Handedness::left || h == Handedness::right) return {};
  return "hand value " + std::to_string(static_cast<int>(h)) + " is neither 0 (left) nor 1 (right)";
}
template <typename Range>
std::string finite_problem(const Range& values, const char* what) {
  std::size_t i = 0;
  for (const double v : values) {
    if (!std::isfinite(v)) return std::string(what) + " #" + std::to_string(i) + " is " + num(v) + ", not finite";
    ++i;
  }
  return {};
}

std::string problem(const ImuSample& s) {
  if (!s.accel_mps2.allFinite()) return "accelerometer value is not finite (NaN or Inf)";
  if (!s.gyro_radps.allFinite()) return "gyroscope value is not finite (NaN or Inf)";
  if (s.mag_T && !s.mag_T->allFinite()) return "magnetometer value is not finite (NaN or Inf)";
  return {};
}
std::string problem(const MarkerObservations& m) {
  for (std::size_t i = 0; i < m.markers.size(); ++i) {
    const Marker& k = m.markers[i];
    if (!std::isfinite(k.u_px) || !std::isfinite(k.v_px) || !std::isfinite(k.area_px2)) {
      return "marker #" + std::to_string(i) + " has a non-finite coordinate or area";
    }
  }
  return {};
}
std::string problem(const CapacitanceFrame& f) { return finite_problem(f.values_F, "capacitance value"); }
std::string problem(const HandPose& p) {
  if (auto h = hand_problem(p.hand); !h.empty()) return h;
  if (!p.active) return {};
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    const auto joint = [i] { return "joint '" + std::string(to_string(joint_at(i))) + "'"; };
    if (auto e = pose_problem(p.T_world_joint[i], joint); !e.empty()) return e;
    if (!std::isfinite(p.radius_m[i])) return joint() + " radius is " + num(p.radius_m[i]) + ", not finite";
    if (p.has_velocity &&
        (!p.linear_velocity_in_world[i].allFinite() || !p.angular_velocity_in_world[i].allFinite())) {
      return joint() + " velocity has a non-finite value (NaN or Inf)";
    }
  }
  return {};
}
std::string problem(const JointAngles& a) {
  if (auto h = hand_problem(a.hand); !h.empty()) return h;
  return finite_problem(a.angles_rad, "joint angle");
}
std::string problem(const RigidPose& r) {
  return pose_problem(r.T_world_body, [] { return std::string("body"); });
}
std::string problem(const Event&) { return {}; }
std::string problem(const RawBytes&) { return {}; }

// ---------------------------------------------------------------- payload encoding
void encode(Encoder& e, const ImuSample& s) {
  e.u16(s.sensor_id);
  e.u8(s.mag_T ? 1 : 0);
  e.u8(0);
  e.vec3(s.accel_mps2);
  e.vec3(s.gyro_radps);
  if (s.mag_T) e.vec3(*s.mag_T);
}
void encode(Encoder& e, const MarkerObservations& m) {
  e.u8(m.camera_id);
  e.u8(0), e.u8(0), e.u8(0);
  e.u32(static_cast<std::uint32_t>(m.markers.size()));
  for (const Marker& k : m.markers) e.u8(k.hue), e.f32(k.u_px), e.f32(k.v_px), e.f32(k.area_px2);
}
void encode_doubles(Encoder& e, const std::vector<double>& v) {
  e.u32(static_cast<std::uint32_t>(v.size()));
  for (const double x : v) e.f64(x);
}
void encode(Encoder& e, const CapacitanceFrame& f) { encode_doubles(e, f.values_F); }
void encode(Encoder& e, const HandPose& p) {
  e.u8(static_cast<std::uint8_t>(p.hand));
  if (!p.active) {
    e.u8(0), e.u16(0);
    return;
  }
  e.u8(static_cast<std::uint8_t>(1u | (p.has_velocity ? 2u : 0u)));
  e.u16(static_cast<std::uint16_t>(kHandJointCount));
  e.bytes(p.flags.data(), p.flags.size());
  for (std::size_t i = 0; i < kHandJointCount; ++i) e.pose(p.T_world_joint[i]), e.f64(p.radius_m[i]);
  if (!p.has_velocity) return;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    e.vec3(p.linear_velocity_in_world[i]), e.vec3(p.angular_velocity_in_world[i]);
  }
}
void encode(Encoder& e, const JointAngles& a) {
  e.u8(static_cast<std::uint8_t>(a.hand));
  e.u8(0), e.u8(0), e.u8(0);
  encode_doubles(e, a.angles_rad);
}
void encode(Encoder& e, const RigidPose& r) { e.pose(r.T_world_body); }
void encode(Encoder& e, const Event& ev) { e.bytes(ev.text.data(), ev.text.size()); }
void encode(Encoder& e, const RawBytes& r) { e.bytes(r.bytes.data(), r.bytes.size()); }

// ---------------------------------------------------------------- payload decoding
// Each returns "" on success or what is wrong with the bytes.
std::string decode_doubles(Decoder& d, std::vector<double>& out, const char* what) {
  const std::uint32_t n = d.u32();
  if (n > d.remaining() / 8) {
    return std::string(what) + " count " + std::to_string(n) + " needs " + std::to_string(8ull * n) +
           " bytes, but only " + std::to_string(d.remaining()) + " remain in the record";
  }
  out.resize(n);
  for (double& x : out) x = d.f64();
  return {};
}
std::string decode(Decoder& d, ImuSample& s) {
  s.sensor_id = d.u16();
  const std::uint8_t flags = d.u8();
  d.u8();
  s.accel_mps2 = d.vec3();
  s.gyro_radps = d.vec3();
  if (flags & 1u) s.mag_T = d.vec3();
  return {};
}
std::string decode(Decoder& d, MarkerObservations& m) {
  m.camera_id = d.u8();
  d.take(3);
  const std::uint32_t n = d.u32();
  if (n > d.remaining() / kMarkerBytes) {
    return "marker count " + std::to_string(n) + " needs " + std::to_string(kMarkerBytes * n) +
           " bytes, but only " + std::to_string(d.remaining()) + " remain in the record";
  }
  m.markers.resize(n);
  for (Marker& k : m.markers) {
    k.hue = d.u8();
    k.u_px = d.f32();
    k.v_px = d.f32();
    k.area_px2 = d.f32();
  }
  return {};
}
std::string decode(Decoder& d, CapacitanceFrame& f) { return decode_doubles(d, f.values_F, "capacitance value"); }
std::string decode(Decoder& d, HandPose& p) {
  p.hand = static_cast<Handedness>(d.u8());
  const std::uint8_t flags = d.u8();
  const std::uint16_t joints = d.u16();
  p.active = (flags & 1u) != 0;
  if (!p.active) return {};
  if (joints != kHandJointCount) {
    return "active HandPose has " + std::to_string(joints) + " joints; this format stores " +
           std::to_string(kHandJointCount);
  }
  p.has_velocity = (flags & 2u) != 0;
  const auto flag_bytes = d.take(kHandJointCount);
  std::copy(flag_bytes.begin(), flag_bytes.end(), p.flags.begin());
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    p.T_world_joint[i] = d.pose();
    p.radius_m[i] = d.f64();
  }
  if (!p.has_velocity) return {};
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    p.linear_velocity_in_world[i] = d.vec3();
    p.angular_velocity_in_world[i] = d.vec3();
  }
  return {};
}
std::string decode(Decoder& d, JointAngles& a) {
  a.hand = static_cast<Handedness>(d.u8());
  d.take(3);
  return decode_doubles(d, a.angles_rad, "joint angle");
}
std::string decode(Decoder& d, RigidPose& r) {
  r.T_world_body = d.pose();
  return {};
}
std::string decode(Decoder& d, Event& ev) {
  ev.text = d.string(d.remaining());
  return {};
}
std::string decode(Decoder& d, RawBytes& r) {
  const auto s = d.take(d.remaining());
  r.bytes.assign(s.begin(), s.end());
  return {};
}

// Decodes and validates a data payload of a known kind into out.
template <std::size_t I = 0>
std::string decode_payload(StreamKind kind, std::span<const std::uint8_t> bytes, bool allow_trailing,
                           TimeNs time_ns, RecordPayload& out) {
  if constexpr (I < std::variant_size_v<RecordPayload>) {
    if (static_cast<std::size_t>(kind) != I + 1) {
      return decode_payload<I + 1>(kind, bytes, allow_trailing, time_ns, out);
    }
    auto& value = out.emplace<I>();
    if constexpr (std::is_same_v<std::decay_t<decltype(value)>, HandPose>) value.time_ns = time_ns;
    Decoder d(bytes);
    if (auto e = decode(d, value); !e.empty()) return e;
    if (d.failed()) return "payload is too short (" + std::to_string(bytes.size()) + " bytes) for its content";
    if (d.remaining() > 0 && !allow_trailing) {
      return std::to_string(d.remaining()) + " unexpected bytes after the payload";
    }
    return problem(value);
  } else {
    return "stream kind " + std::to_string(static_cast<int>(kind)) + " is unknown";
  }
}

// Names go into file names, CLI flags and logs: keep them to printable ASCII.
std::string name_problem(std::string_view name) {
  if (name.empty() || name.size() > kMaxNameBytes) {
    return "stream name must be 1 to " + std::to_string(kMaxNameBytes) + " bytes long, got " +
           std::to_string(name.size());
  }
  for (std::size_t i = 0; i < name.size(); ++i) {
    const auto c = static_cast<unsigned char>(name[i]);
    if (c <= 0x20 || c >= 0x7F) {
      return "stream name '" + std::string(name) + "' has byte " + std::to_string(c) + " at position " +
             std::to_string(i) + "; use printable ASCII without spaces, e.g. 'hand/right/ground_truth'";
    }
  }
  return {};
}

std::array<std::uint8_t, kFileHeaderBytes> file_header() {
  std::array<std::uint8_t, kFileHeaderBytes> h{};
  std::copy(kMagic.begin(), kMagic.end(), h.begin());
  store_le<2>(h.data() + 8, kRecordingFormatMajor);
  store_le<2>(h.data() + 10, kRecordingFormatMinor);
  store_le<4>(h.data() + 12, kFileHeaderBytes);
  store_le<4>(h.data() + 16, crc32_ieee(std::span(h).first(16)));
  return h;
}

}  // namespace

std::uint32_t crc32_ieee(std::span<const std::uint8_t> data, std::uint32_t crc) noexcept {
  const auto& t = kCrcTables;
  crc = ~crc;
  const std::uint8_t* p = data.data();
  std::size_t n = data.size();
  for (; n >= 8; p += 8, n -= 8) {
    const auto lo = crc ^ static_cast<std::uint32_t>(load_le<4>(p));
    const auto hi = static_cast<std::uint32_t>(load_le<4>(p + 4));
    crc = t[7][lo & 0xFFu] ^ t[6][(lo >> 8) & 0xFFu] ^ t[5][(lo >> 16) & 0xFFu] ^ t[4][lo >> 24] ^
          t[3][hi & 0xFFu] ^ t[2][(hi >> 8) & 0xFFu] ^ t[1][(hi >> 16) & 0xFFu] ^ t[0][hi >> 24];
  }
  for (; n > 0; ++p, --n) crc = t[0][(crc ^ *p) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

std::string_view to_string(StreamKind kind) noexcept {
  switch (kind) {
    case StreamKind::imu: return "imu";
    case StreamKind::markers: return "markers";
    case StreamKind::capacitance: return "capacitance";
    case StreamKind::hand_pose: return "hand_pose";
    case StreamKind::joint_angles: return "joint_angles";
    case StreamKind::rigid_pose: return "rigid_pose";
    case StreamKind::event: return "event";
    case StreamKind::raw: return "raw";
  }
  return "unknown";
}

bool is_known(StreamKind kind) noexcept { return to_string(kind) != "unknown"; }

const char* to_string(RecordingEnd end) noexcept {
  switch (end) {
    case RecordingEnd::reading: return "reading";
    case RecordingEnd::clean: return "clean";
    case RecordingEnd::missing_end: return "missing_end";
    case RecordingEnd::truncated: return "truncated";
    case RecordingEnd::corrupt: return "corrupt";
  }
  return "?";
}

// ==================================================================== writer

struct RecordingWriter::Impl {
  std::filesystem::path path;
  RecordingWriterOptions options;
  FilePtr file;
  std::vector<StreamInfo> streams;
  std::vector<std::uint8_t> scratch;  // [record header][payload][crc], reused
  std::uint64_t records = 0;
  std::optional<Error> failure;  // sticky: after a failed write the file's tail is unknown

  std::string where() const { return "recording '" + path.string() + "'"; }

  Status check_writable() const {
    if (failure) return *failure;
    if (!file) return make_error(Errc::invalid_argument, where() + " is closed; create a new writer to record more");
    return {};
  }

  // scratch: a kRecordHeaderBytes gap, then the payload.
  void begin() { scratch.assign(kRecordHeaderBytes, 0); }

  Status emit(RecordType type, StreamId stream, TimeNs time_ns) {
    const std::size_t payload = scratch.size() - kRecordHeaderBytes;
    if (payload > kRecordingMaxPayloadBytes) {
      return make_error(Errc::invalid_argument, where() + ": a record payload of " + std::to_string(payload) +
                                                    " bytes exceeds the " +
                                                    std::to_string(kRecordingMaxPayloadBytes) +
                                                    "-byte limit; split the data into several records");
    }
    std::uint8_t* h = scratch.data();
    store_le<4>(h, payload);
    h[4] = static_cast<std::uint8_t>(type);
    h[5] = 0;
    store_le<2>(h + 6, stream);
    store_le<8>(h + 8, static_cast<std::uint64_t>(time_ns));
    const std::uint32_t crc = crc32_ieee(scratch);
    scratch.resize(scratch.size() + kRecordCrcBytes);
    store_le<4>(scratch.data() + scratch.size() - kRecordCrcBytes, crc);
    if (std::fwrite(scratch.data(), 1, scratch.size(), file.get()) != scratch.size()) {
      failure = make_error(Errc::io_error, "writing " + where() + " failed (" + std::strerror(errno) +
                                               "); the file reads up to the last record that reached the "
                                               "disk; free disk space or check the device, then start a new "
                                               "recording");
      return *failure;
    }
    ++records;
    return {};
  }

  template <typename T>
  Status write(StreamId id, const T& value, TimeNs time_ns) {
    if (auto s = check_writable(); !s) return s;
    constexpr StreamKind kind = kind_of<T>();
    if (id >= streams.size()) {
      return make_error(Errc::invalid_argument, where() + ": no stream with id " + std::to_string(id) + " (it has " +
                                                    std::to_string(streams.size()) +
                                                    " streams); use the id add_stream() returned");
    }
    StreamInfo& info = streams[id];
    if (info.kind != kind) {
      return make_error(Errc::invalid_argument, where() + ": stream '" + info.name + "' holds " +
                                                    std::string(to_string(info.kind)) + " records; cannot write " +
                                                    std::string(to_string(kind)) + " to it");
    }
    if (auto p = problem(value); !p.empty()) {
      return make_error(Errc::invalid_argument, where() + ": refusing to write " + std::string(to_string(kind)) +
                                                    " at t=" + std::to_string(time_ns) + " ns to stream '" +
                                                    info.name + "': " + p);
    }
    begin();
    {
      Encoder e(scratch);
      encode(e, value);
    }
    if (auto s = emit(RecordType::data, id, time_ns); !s) return s;
    ++info.records;
    return {};
  }
};

RecordingWriter::RecordingWriter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RecordingWriter::RecordingWriter(RecordingWriter&&) noexcept = default;
RecordingWriter& RecordingWriter::operator=(RecordingWriter&& other) noexcept {
  if (this != &other) {
    if (impl_) (void)close();
    impl_ = std::move(other.impl_);
  }
  return *this;
}
RecordingWriter::~RecordingWriter() {
  if (impl_) (void)close();
}

Result<RecordingWriter> RecordingWriter::create(const std::filesystem::path& path, RecordingWriterOptions options) {
  return no_throw([&]() -> Result<RecordingWriter> {
    // Never over a file this process reads (its input recording, through any
    // path or link), a FIFO or a device.
    if (auto s = check_output_path(path, "recording"); !s) return s.error();
    errno = 0;
    // "x" (C11) opens with O_EXCL, so two recorders cannot race onto one file.
    FilePtr file(std::fopen(path.c_str(), options.overwrite ? "wb" : "wbx"));
    if (!file) {
      const int err = errno;
      if (err == EEXIST) {
        return make_error(Errc::invalid_argument, "recording '" + printable(path.string(), 300) +
                                                      "' already exists; choose another file name, delete it, or "
                                                      "pass --force to replace it");
      }
      return make_error(err == ENOENT ? Errc::not_found : Errc::io_error,
                        "cannot create recording '" + path.string() + "': " + std::strerror(err) +
                            (err == ENOENT ? "; create its folder first" : ""));
    }
    std::setvbuf(file.get(), nullptr, _IOFBF, 1 << 16);
    // An empty session still leaves a readable file: push the header out now.
    const auto header = file_header();
    if (std::fwrite(header.data(), 1, header.size(), file.get()) != header.size() || std::fflush(file.get()) != 0) {
      return make_error(Errc::io_error,
                        "cannot write the header of recording '" + path.string() + "': " + std::strerror(errno));
    }
    auto impl = std::make_unique<Impl>();
    impl->path = path;
    impl->options = options;
    impl->file = std::move(file);
    return RecordingWriter(std::move(impl));
  });
}

Result<StreamId> RecordingWriter::add_stream(StreamKind kind, std::string_view name, std::string_view meta) {
  Impl& im = *impl_;
  return no_throw([&]() -> Result<StreamId> {
    if (auto s = im.check_writable(); !s) return s.error();
    if (!is_known(kind)) {
      return make_error(Errc::invalid_argument,
                        im.where() + ": stream kind " + std::to_string(static_cast<int>(kind)) + " is unknown");
    }
    if (auto p = name_problem(name); !p.empty()) return make_error(Errc::invalid_argument, im.where() + ": " + p);
    for (const StreamInfo& s : im.streams) {
      if (s.name == name) {
        return make_error(Errc::invalid_argument, im.where() + ": a stream named '" + s.name +
                                                      "' already exists (id " + std::to_string(s.id) +
                                                      "); stream names must be unique");
      }
    }
    if (im.streams.size() >= kFileLevelStream) {
      return make_error(Errc::unsupported, im.where() + ": a recording holds at most " +
                                               std::to_string(kFileLevelStream) + " streams");
    }
    const auto id = static_cast<StreamId>(im.streams.size());
    im.begin();
    {
      Encoder e(im.scratch);
      e.u8(static_cast<std::uint8_t>(kind));
      e.u8(0);
      e.u16(static_cast<std::uint16_t>(name.size()));
      e.bytes(name.data(), name.size());
      e.u32(static_cast<std::uint32_t>(std::min<std::size_t>(meta.size(), UINT32_MAX)));
      e.bytes(meta.data(), meta.size());
    }
    if (auto s = im.emit(RecordType::stream_def, id, 0); !s) return s.error();
    im.streams.push_back(StreamInfo{id, kind, std::string(name), std::string(meta), 0});
    return id;
  });
}

Status RecordingWriter::write(StreamId s, const ImuSample& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}
Status RecordingWriter::write(StreamId s, const MarkerObservations& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}
Status RecordingWriter::write(StreamId s, const CapacitanceFrame& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}
Status RecordingWriter::write(StreamId s, const HandPose& v) {
  return no_throw([&] { return impl_->write(s, v, v.time_ns); });
}
Status RecordingWriter::write(StreamId s, const JointAngles& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}
Status RecordingWriter::write(StreamId s, const RigidPose& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}
Status RecordingWriter::write(StreamId s, const Event& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}
Status RecordingWriter::write(StreamId s, const RawBytes& v, TimeNs t) {
  return no_throw([&] { return impl_->write(s, v, t); });
}

Status RecordingWriter::flush() {
  Impl& im = *impl_;
  if (auto s = im.check_writable(); !s) return s;
  if (std::fflush(im.file.get()) != 0 || (im.options.fsync_on_flush && ::fsync(::fileno(im.file.get())) != 0)) {
    im.failure = make_error(Errc::io_error, "flushing " + im.where() + " failed: " + std::strerror(errno));
    return *im.failure;
  }
  return {};
}

Status RecordingWriter::close() {
  Impl& im = *impl_;
  if (!im.file) return im.failure ? Status(*im.failure) : Status();
  Status status = im.failure ? Status(*im.failure) : Status();
  if (status) {
    status = no_throw([&] {
      im.begin();
      Encoder(im.scratch).u64(im.records);
      return im.emit(RecordType::end, kFileLevelStream, 0);
    });
  }
  if (status && im.options.fsync_on_flush) status = flush();
  if (std::fclose(im.file.release()) != 0 && status) {
    status = make_error(Errc::io_error, "closing " + im.where() + " failed: " + std::strerror(errno));
  }
  return status;
}

bool RecordingWriter::is_open() const noexcept { return impl_ && impl_->file != nullptr; }
const std::filesystem::path& RecordingWriter::path() const noexcept { return impl_->path; }
const std::vector<StreamInfo>& RecordingWriter::streams() const noexcept { return impl_->streams; }
std::uint64_t RecordingWriter::records_written() const noexcept { return impl_->records; }

// ==================================================================== reader

struct RecordingReader::Impl {
  std::string name;
  FilePtr file;                       // reads sequentially from here...
  std::vector<std::uint8_t> memory;   // ...or from here when file is null
  std::uint64_t size = 0;             // bytes available when opened
  std::uint64_t pos = 0;              // offset of the next record
  std::uint16_t major = 0;
  std::uint16_t minor = 0;
  std::vector<StreamInfo> streams;
  std::vector<std::int32_t> index_of_id;  // stream id -> index into streams, -1 if undefined
  RecordingSummary summary;
  std::vector<std::uint8_t> buf;
  std::vector<std::uint8_t> scan;  // resynchronisation window
  std::vector<std::uint8_t> crc_chunk;  // candidate records are CRC-checked through this, chunk by chunk
  bool done = false;
  std::uint64_t file_pos = 0;      // where the FILE* stands; reads are sequential except after damage or seek()
  std::uint64_t last_record = 0;   // offset of the record next() returned last
  std::string corruption;          // what the first damaged region was, for the summary's detail
  bool rereading = false;          // seek() was called: stream definitions may come again

  bool read(std::uint64_t offset, std::uint8_t* dst, std::size_t n) {
    if (file) {
      if (offset != file_pos && ::fseeko(file.get(), static_cast<off_t>(offset), SEEK_SET) != 0) return false;
      const std::size_t got = std::fread(dst, 1, n, file.get());
      file_pos = offset + got;
      return got == n;
    }
    if (offset > memory.size() || n > memory.size() - offset) return false;
    std::memcpy(dst, memory.data() + offset, n);
    return true;
  }

  // A record header the writer could have written (length, type, stream):
  // cheap filters before a CRC is computed.
  static bool header_shape_ok(const std::uint8_t* h) {
    const auto len = static_cast<std::uint32_t>(load_le<4>(h));
    if (len > kRecordingMaxPayloadBytes || h[5] != 0) return false;
    const auto stream = static_cast<StreamId>(load_le<2>(h + 6));
    switch (static_cast<RecordType>(h[4])) {
      case RecordType::stream_def: return load_le<8>(h + 8) == 0 && stream != kFileLevelStream;
      case RecordType::data: return stream != kFileLevelStream;
      case RecordType::end: return len == 8 && stream == kFileLevelStream && load_le<8>(h + 8) == 0;
    }
    return false;
  }
  // The same, with room for its record before the end of the file.
  static bool plausible_header(const std::uint8_t* h, std::uint64_t room) {
    const auto len = static_cast<std::uint32_t>(load_le<4>(h));
    return header_shape_ok(h) && kRecordHeaderBytes + len + kRecordCrcBytes <= room;
  }

  std::uint64_t resync_budget() const {
    return kRecordingResyncBudgetFileSizes * size + kRecordingResyncBudgetExtraBytes;
  }

  // Whether a plausible header h at offset starts an intact record. The
  // record must end the file or be followed by another plausible header
  // (possibly cut off) before its CRC is checked; the CRC is computed in
  // chunks through one reused buffer and charged to the resync budget, which
  // once spent makes every later candidate fail (summary.resync_gave_up).
  bool intact_record_at(std::uint64_t offset, const std::uint8_t* h) {
    const auto len = static_cast<std::uint32_t>(load_le<4>(h));
    const std::uint64_t end = offset + kRecordHeaderBytes + len + kRecordCrcBytes;
    if (end < size) {
      std::array<std::uint8_t, kRecordHeaderBytes> after{};
      const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(after.size(), size - end));
      if (!read(end, after.data(), n)) return false;
      if (n == after.size() && !header_shape_ok(after.data())) return false;
    }
    const std::uint64_t cost = kRecordHeaderBytes + len;
    if (summary.resync_gave_up || summary.resync_checked_bytes + cost > resync_budget()) {
      summary.resync_gave_up = true;
      return false;
    }
    summary.resync_checked_bytes += cost;
    constexpr std::size_t kChunk = 1 << 16;
    crc_chunk.resize(kChunk);
    std::uint32_t crc = crc32_ieee(std::span(h, kRecordHeaderBytes));
    for (std::uint64_t at = offset + kRecordHeaderBytes, left = len; left > 0;) {
      const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(kChunk, left));
      if (!read(at, crc_chunk.data(), n)) return false;
      crc = crc32_ieee(std::span(crc_chunk).first(n), crc);
      at += n;
      left -= n;
    }
    std::array<std::uint8_t, kRecordCrcBytes> stored{};
    if (!read(end - kRecordCrcBytes, stored.data(), stored.size())) return false;
    return crc == static_cast<std::uint32_t>(load_le<4>(stored.data()));
  }

  // The offset of the next intact record after a damaged one at `from`, if
  // any (none also once the resync budget is spent).
  std::optional<std::uint64_t> find_next_record(std::uint64_t from) {
    constexpr std::size_t kWindow = 1 << 16;
    for (std::uint64_t base = from + 1; base + kRecordHeaderBytes + kRecordCrcBytes <= size; base += kWindow) {
      if (summary.resync_gave_up) return std::nullopt;
      const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(kWindow + kRecordHeaderBytes - 1, size - base));
      scan.resize(n);
      if (!read(base, scan.data(), n)) return std::nullopt;
      for (std::size_t i = 0; i < kWindow && i + kRecordHeaderBytes <= n; ++i) {
        if (plausible_header(scan.data() + i, size - base - i) && intact_record_at(base + i, scan.data() + i)) {
          return base + i;
        }
        if (summary.resync_gave_up) return std::nullopt;
      }
    }
    return std::nullopt;
  }

  // What finish() says when no intact record follows the damage.
  std::string no_intact_record() const {
    const std::string read_so_far = std::to_string(summary.records) + " records were read";
    if (!summary.resync_gave_up) return "no intact record after the damage; " + read_so_far;
    return "gave up searching for an intact record after the damage (" +
           std::to_string(summary.resync_checked_bytes) + " bytes CRC-checked in candidate records, the limit for a " +
           std::to_string(size) + "-byte file); " + read_so_far;
  }

  // Counts the damaged region [start, resume) and goes on at resume.
  void note_damage(std::uint64_t start, std::uint64_t resume, const std::string& what) {
    if (summary.corrupt_regions++ == 0) {
      summary.first_corrupt_offset = start;
      corruption = what;
    }
    summary.skipped_bytes += resume - start;
    pos = resume;
  }
  // The same up to the next intact record; false if there is none.
  bool skip_damage(std::uint64_t start, const std::string& what) {
    const auto next = find_next_record(start);
    note_damage(start, next.value_or(size), what);
    return next.has_value();
  }

  std::string at(std::uint64_t offset) const { return "'" + name + "' at byte " + std::to_string(offset); }

  Status parse_header() {
    const std::string what = "'" + name + "'";
    if (size == 0) {
      return make_error(Errc::parse_error, what + " is empty, not a Proprio recording (a writer that crashed "
                                                  "before its first write leaves such a file)");
    }
    buf.resize(kFileHeaderBytes);
    const std::size_t head = static_cast<std::size_t>(std::min<std::uint64_t>(size, 16));
    if (!read(0, buf.data(), head)) return make_error(Errc::io_error, "cannot read " + what);
    const std::size_t m = std::min(head, kMagic.size());
    if (!std::equal(kMagic.begin(), kMagic.begin() + static_cast<std::ptrdiff_t>(m), buf.begin())) {
      if (m >= 4 && std::equal(kMagic.begin() + 1, kMagic.begin() + 4, buf.begin() + 1)) {
        return make_error(Errc::parse_error, what + " is a damaged Proprio recording: its first bytes were "
                                                    "changed, as a text-mode transfer does (line endings or "
                                                    "8-bit bytes); copy the file in binary mode");
      }
      char got[64];
      std::snprintf(got, sizeof got, "%02x %02x %02x %02x", buf[0], m > 1 ? buf[1] : 0, m > 2 ? buf[2] : 0,
                    m > 3 ? buf[3] : 0);
      return make_error(Errc::parse_error, what + " is not a Proprio recording (bad magic: starts with " + got +
                                               ", expected 89 50 52 50 = \"\\x89PRP\")");
    }
    if (head < 16) {
      return make_error(Errc::parse_error, what + " is cut short inside its file header (" + std::to_string(size) +
                                               " bytes); the writer crashed while creating it");
    }
    major = static_cast<std::uint16_t>(load_le<2>(buf.data() + 8));
    minor = static_cast<std::uint16_t>(load_le<2>(buf.data() + 10));
    const auto header_len = static_cast<std::uint32_t>(load_le<4>(buf.data() + 12));
    const std::string version = std::to_string(major) + "." + std::to_string(minor);
    const std::string ours = std::to_string(kRecordingFormatMajor) + ".x";
    if (major > kRecordingFormatMajor) {
      return make_error(Errc::unsupported, what + " uses recording format version " + version +
                                               ", newer than this build supports (" + ours +
                                               "); update Proprio to read it");
    }
    if (major < kRecordingFormatMajor) {
      return make_error(Errc::unsupported, what + " uses recording format version " + version +
                                               ", which this build (" + ours + ") cannot read");
    }
    if (header_len < kFileHeaderBytes || header_len > kMaxFileHeaderBytes) {
      return make_error(Errc::parse_error, what + " has a damaged file header (header length " +
                                               std::to_string(header_len) + " is outside " +
                                               std::to_string(kFileHeaderBytes) + ".." +
                                               std::to_string(kMaxFileHeaderBytes) + ")");
    }
    if (header_len > size) {
      return make_error(Errc::parse_error, what + " is cut short inside its file header (" + std::to_string(size) +
                                               " of " + std::to_string(header_len) + " bytes)");
    }
    buf.resize(header_len);
    if (!read(16, buf.data() + 16, header_len - 16)) return make_error(Errc::io_error, "cannot read " + what);
    const std::uint32_t stored = static_cast<std::uint32_t>(load_le<4>(buf.data() + header_len - 4));
    const std::uint32_t computed = crc32_ieee(std::span(buf).first(header_len - 4));
    if (stored != computed) {
      return make_error(Errc::parse_error, what + " has a damaged file header (CRC " + hex32(computed) +
                                               ", stored " + hex32(stored) + ")");
    }
    pos = header_len;
    summary.valid_bytes = header_len;
    return {};
  }

  void finish(RecordingEnd end, std::string detail) {
    done = true;
    summary.ignored_bytes = size - summary.valid_bytes;
    const std::uint64_t after_end = summary.ignored_bytes - summary.skipped_bytes;
    if (end == RecordingEnd::clean && after_end > 0) {
      detail += "; " + std::to_string(after_end) + " bytes after the End record were ignored";
    }
    if (summary.corrupt_regions > 0) {
      std::string lost = std::to_string(summary.skipped_bytes) + " damaged bytes skipped in " +
                         std::to_string(summary.corrupt_regions) + " region" +
                         (summary.corrupt_regions > 1 ? "s" : "") + " (the first: " + corruption + ")";
      if (summary.lost_records > 0) lost += ", " + std::to_string(summary.lost_records) + " records lost";
      detail = lost + "; then: " + detail;
      end = RecordingEnd::corrupt;
    }
    summary.end = end;
    summary.detail = std::move(detail);
  }

  Error record_error(std::uint64_t offset, StreamId stream, TimeNs t, const std::string& problem) {
    ++summary.invalid_records;
    std::string s = "stream " + std::to_string(stream);
    if (const StreamInfo* info = find(stream)) s += " '" + printable(info->name, 80) + "'";
    return make_error(Errc::parse_error, "recording " + at(offset) + " (" + s + ", t=" + std::to_string(t) +
                                             " ns): " + problem + "; record skipped");
  }

  const StreamInfo* find(StreamId id) const {
    if (id >= index_of_id.size() || index_of_id[id] < 0) return nullptr;
    return &streams[static_cast<std::size_t>(index_of_id[id])];
  }
  StreamInfo* find(StreamId id) { return const_cast<StreamInfo*>(std::as_const(*this).find(id)); }

  // "" on success.
  std::string define_stream(StreamId id, std::span<const std::uint8_t> payload, bool allow_trailing) {
    Decoder d(payload);
    StreamInfo info;
    info.id = id;
    info.kind = static_cast<StreamKind>(d.u8());
    d.u8();
    info.name = d.string(d.u16());
    info.meta = d.string(d.u32());
    if (d.failed()) return "stream definition is too short for its name and meta";
    if (d.remaining() > 0 && !allow_trailing) return "stream definition has unexpected trailing bytes";
    if (id == kFileLevelStream) return "stream id 65535 is reserved";
    if (info.name.empty()) return "stream has an empty name";
    if (const StreamInfo* known = find(id)) {
      // After seek(), definitions read before come round again.
      if (rereading && known->name == info.name && known->kind == info.kind) return {};
      return "stream id " + std::to_string(id) + " is defined twice";
    }
    if (index_of_id.size() <= id) index_of_id.resize(std::size_t{id} + 1, -1);
    index_of_id[id] = static_cast<std::int32_t>(streams.size());
    streams.push_back(std::move(info));
    return {};
  }

  Result<std::optional<Record>> next() {
    // Newer minor versions may append fields to payloads; only then are extra bytes expected.
    const bool allow_trailing = minor > kRecordingFormatMinor;
    while (!done) {
      const std::uint64_t start = pos;
      const std::uint64_t remaining = size - start;
      const auto record_no = [&] { return "record #" + std::to_string(summary.records + 1); };
      if (remaining == 0) {
        finish(RecordingEnd::missing_end, "no End record after " + std::to_string(summary.records) +
                                              " records: the writer did not close the file (crash, or "
                                              "still recording); all complete records were read");
        break;
      }
      std::array<std::uint8_t, kRecordHeaderBytes> h{};
      const auto truncated = [&](std::uint64_t needed) {
        finish(RecordingEnd::truncated, "file ends inside " + record_no() + " " + at(start) + " (" +
                                            std::to_string(needed) + " bytes needed, " +
                                            std::to_string(remaining) + " present): the writer was cut off; " +
                                            std::to_string(summary.records) + " complete records were read");
      };
      if (remaining < h.size() || !read(start, h.data(), h.size())) {
        truncated(h.size());
        break;
      }
      const auto len = static_cast<std::uint32_t>(load_le<4>(h.data()));
      const auto type = static_cast<RecordType>(h[4]);
      const auto stream = static_cast<StreamId>(load_le<2>(h.data() + 6));
      const auto time_ns = static_cast<TimeNs>(load_le<8>(h.data() + 8));
      // Damage: go on at the next intact record (the CRC makes a false match
      // a 1-in-4-billion event), or stop if there is none.
      const auto damaged = [&](const std::string& what) {
        if (skip_damage(start, what)) return true;
        finish(RecordingEnd::corrupt, no_intact_record());
        return false;
      };
      if (len > kRecordingMaxPayloadBytes) {
        if (damaged(record_no() + " " + at(start) + " has payload length " + std::to_string(len) +
                    ", above the limit")) {
          continue;
        }
        break;
      }
      const std::uint64_t total = kRecordHeaderBytes + len + kRecordCrcBytes;
      buf.resize(len + kRecordCrcBytes);
      if (total > remaining || !read(start + h.size(), buf.data(), buf.size())) {
        // The writer cut off mid-record, unless an intact record follows: then
        // the length field was damaged.
        if (total > remaining) {
          const std::string what = record_no() + " " + at(start) + " has payload length " + std::to_string(len) +
                                   ", beyond the end of the file";
          if (const auto next = find_next_record(start)) {
            note_damage(start, *next, what + ", but intact records follow");
            continue;
          }
          // Not known to be a cut-off writer: the search for what follows gave up.
          if (summary.resync_gave_up) {
            note_damage(start, size, what);
            finish(RecordingEnd::corrupt, no_intact_record());
            break;
          }
        }
        truncated(total);
        break;
      }
      const std::uint32_t computed = crc32_ieee(std::span(buf).first(len), crc32_ieee(h));
      const auto stored = static_cast<std::uint32_t>(load_le<4>(buf.data() + len));
      if (computed != stored) {
        if (damaged(record_no() + " " + at(start) + " fails its CRC (" + hex32(computed) + ", stored " +
                    hex32(stored) + ")")) {
          continue;
        }
        break;
      }
      pos = start + total;
      last_record = start;
      summary.valid_bytes += total;
      const std::span<const std::uint8_t> payload(buf.data(), len);

      if (type == RecordType::end) {
        Decoder d(payload);
        const std::uint64_t count = d.u64();
        if (!d.failed() && summary.corrupt_regions > 0 && count > summary.records) {
          summary.lost_records = count - summary.records;
          finish(RecordingEnd::corrupt, "End record seen after " + std::to_string(summary.records) + " of " +
                                            std::to_string(count) + " records");
        } else if (d.failed() || count != summary.records) {
          finish(RecordingEnd::corrupt, "End record " + at(start) + " counts " + std::to_string(count) +
                                            " records, but " + std::to_string(summary.records) +
                                            " were read: records are missing or were spliced in");
        } else {
          finish(RecordingEnd::clean, "End record seen after " + std::to_string(count) + " records");
        }
        break;
      }
      ++summary.records;
      if (type == RecordType::stream_def) {
        if (auto p = define_stream(stream, payload, allow_trailing); !p.empty()) {
          return record_error(start, stream, time_ns, p);
        }
        continue;
      }
      if (type != RecordType::data) {
        ++summary.skipped_records;
        continue;
      }
      StreamInfo* info = find(stream);
      if (!info) return record_error(start, stream, time_ns, "data for a stream that was never defined");
      if (!is_known(info->kind)) {
        ++summary.skipped_records;
        continue;
      }
      std::optional<Record> rec(std::in_place);
      rec->stream = stream;
      rec->time_ns = time_ns;
      if (auto p = decode_payload(info->kind, payload, allow_trailing, time_ns, rec->payload); !p.empty()) {
        return record_error(start, stream, time_ns, std::string(to_string(info->kind)) + " payload: " + p);
      }
      ++info->records;
      return rec;
    }
    return std::optional<Record>{};
  }
};

RecordingReader::RecordingReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RecordingReader::RecordingReader(RecordingReader&&) noexcept = default;
RecordingReader& RecordingReader::operator=(RecordingReader&&) noexcept = default;
RecordingReader::~RecordingReader() = default;

Result<RecordingReader> RecordingReader::open(const std::filesystem::path& path) {
  return no_throw([&]() -> Result<RecordingReader> {
    // Regular files only (a FIFO would hang, /dev/zero never ends), and
    // remembered as an input so that no output of this process can replace it.
    auto input = open_input_file(path, "recording");
    if (!input) return input.error();
    const std::uint64_t size = input->size();
    FilePtr file(::fdopen(input->fd(), "rb"));
    if (!file) {
      return make_error(Errc::io_error, "cannot read recording '" + printable(path.string(), 300) + "': " +
                                            std::strerror(errno));
    }
    input->release();
    std::setvbuf(file.get(), nullptr, _IOFBF, 1 << 16);
    auto impl = std::make_unique<Impl>();
    impl->name = printable(path.string(), 300);
    impl->file = std::move(file);
    impl->size = size;
    if (auto s = impl->parse_header(); !s) return s.error();
    return RecordingReader(std::move(impl));
  });
}

Result<RecordingReader> RecordingReader::from_bytes(std::span<const std::uint8_t> bytes) {
  return no_throw([&]() -> Result<RecordingReader> {
    auto impl = std::make_unique<Impl>();
    impl->name = "<memory>";
    impl->memory.assign(bytes.begin(), bytes.end());
    impl->size = bytes.size();
    if (auto s = impl->parse_header(); !s) return s.error();
    return RecordingReader(std::move(impl));
  });
}

Result<std::optional<Record>> RecordingReader::next() {
  return no_throw([&] { return impl_->next(); });
}

std::uint16_t RecordingReader::format_major() const noexcept { return impl_->major; }
std::uint16_t RecordingReader::format_minor() const noexcept { return impl_->minor; }
const std::string& RecordingReader::source_name() const noexcept { return impl_->name; }
const std::vector<StreamInfo>& RecordingReader::streams() const noexcept { return impl_->streams; }
const StreamInfo* RecordingReader::stream(StreamId id) const noexcept { return impl_->find(id); }
const StreamInfo* RecordingReader::find_stream(std::string_view name) const noexcept {
  for (const StreamInfo& s : impl_->streams) {
    if (s.name == name) return &s;
  }
  return nullptr;
}
const RecordingSummary& RecordingReader::summary() const noexcept { return impl_->summary; }
std::uint64_t RecordingReader::last_record_offset() const noexcept { return impl_->last_record; }

Status RecordingReader::seek(std::uint64_t record_offset) {
  Impl& im = *impl_;
  if (record_offset < kFileHeaderBytes || record_offset >= im.size) {
    return make_error(Errc::out_of_range, "recording " + im.at(record_offset) + ": cannot seek there (the file has " +
                                              std::to_string(im.size) + " bytes)");
  }
  im.pos = record_offset;
  im.done = false;
  im.summary = RecordingSummary{};
  im.corruption.clear();
  im.rereading = true;
  return {};
}

// ==================================================================== timestamps

TimestampGuard::Step TimestampGuard::check(TimeNs t) noexcept {
  Step step;
  if (held_) {
    DurationNs back = 0;
    const bool far_back = __builtin_sub_overflow(held_ns_, t, &back) || back > max_jump_ns_;
    if (t > held_ns_) {
      held_ = false;
      step.release_held = true;
      last_ = held_ns_;
    } else if (!last_ && !far_back) {
      // The held sample is the stream's first and this one is a duplicate or
      // a small step back: this one is out of order, the first stands.
      return step;
    } else {
      held_ = false;
      step.reject_held = true;
    }
  }
  if (last_ && t <= *last_) return step;
  // The first sample waits for the second too: it may be the outlier.
  DurationNs jump = 0;
  if (!last_ || __builtin_sub_overflow(t, *last_, &jump) || jump > max_jump_ns_) {
    held_ = true;
    held_ns_ = t;
    step.hold = true;
    return step;
  }
  step.accept = true;
  last_ = t;
  return step;
}

bool TimestampGuard::finish() noexcept {
  if (!held_) return false;
  held_ = false;
  if (last_) return false;
  last_ = held_ns_;
  return true;
}

void TimestampGuard::reset(TimeNs last_accepted_ns) noexcept {
  last_ = last_accepted_ns;
  held_ = false;
}

}  // namespace proprio
