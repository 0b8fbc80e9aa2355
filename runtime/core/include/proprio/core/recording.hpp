#pragma once
// Session recordings: one versioned, append-only file holding many timestamped
// streams (IMU, stereo markers, capacitance, hand poses, ground truth, head
// pose, events). A file cut short by a crash reads up to its last complete
// record. Byte layout, versioning and crash semantics: docs/recording-format.md.
//
// No exception leaves this API; every failure is a Result/Status with a message
// that says what, where (file, byte offset) and what to do.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "proprio/core/hand_pose.hpp"
#include "proprio/core/result.hpp"

namespace proprio {

inline constexpr std::uint16_t kRecordingFormatMajor = 1;
inline constexpr std::uint16_t kRecordingFormatMinor = 0;
// Larger length fields are corruption, so a damaged file cannot make a reader allocate gigabytes.
inline constexpr std::uint32_t kRecordingMaxPayloadBytes = 16u << 20;
// Resynchronising after damage CRC-checks candidate records. A crafted file of
// plausible headers could make that quadratic, so a reader CRC-checks at most
// this many times the file's size plus this many bytes per pass (from open()
// or a seek()), then gives up searching and reports the rest as corrupt.
inline constexpr std::uint64_t kRecordingResyncBudgetFileSizes = 4;
inline constexpr std::uint64_t kRecordingResyncBudgetExtraBytes = 16u << 20;
// |q| must be 1 within this for every stored orientation.
inline constexpr double kRecordingQuatNormTolerance = 1e-4;

// CRC-32 (IEEE 802.3, the one zlib.crc32 and PNG use). Chain calls by passing
// the previous result as crc.
std::uint32_t crc32_ieee(std::span<const std::uint8_t> data, std::uint32_t crc = 0) noexcept;

using StreamId = std::uint16_t;

// The payload type of a stream's data records. Values are stored in files:
// never renumber; a new kind needs a new minor format version.
enum class StreamKind : std::uint8_t {
  imu = 1,
  markers = 2,
  capacitance = 3,
  hand_pose = 4,
  joint_angles = 5,
  rigid_pose = 6,
  event = 7,
  raw = 8,
};
std::string_view to_string(StreamKind kind) noexcept;  // "imu", ..., "unknown"
bool is_known(StreamKind kind) noexcept;               // false for kinds of a newer minor version

// One IMU reading, in the sensor's own frame.
struct ImuSample {
  std::uint16_t sensor_id = 0;
  Vec3 accel_mps2 = Vec3::Zero();  // specific force: at rest it reads +9.81 m/s² along "up"
  Vec3 gyro_radps = Vec3::Zero();
  std::optional<Vec3> mag_T;  // magnetic flux density, tesla (Earth: ~5e-5 T)
};

// One blob found in one camera image.
struct Marker {
  std::uint8_t hue = 0;  // marker colour hue, 256 steps over 360° (OpenCV HSV_FULL)
  // Blob centroid in pixels: (0, 0) is the centre of the top-left pixel, u right, v down.
  float u_px = 0.0f;
  float v_px = 0.0f;
  float area_px2 = 0.0f;  // blob area, square pixels
};

struct MarkerObservations {
  std::uint8_t camera_id = 0;  // e.g. 0 = left, 1 = right of a stereo pair
  std::vector<Marker> markers;
};

// One scan of a capacitive glove: one value per channel, in farads (SI; 1 pF = 1e-12 F).
// The channel layout is described in the stream's meta.
struct CapacitanceFrame {
  std::vector<double> values_F;
};

// Joint angles of a kinematic hand model; the DOF order is given in the stream's meta.
struct JointAngles {
  Handedness hand = Handedness::right;
  std::vector<double> angles_rad;
};

// A tracked rigid body, e.g. the head.
struct RigidPose {
  Pose T_world_body;
};

// A free-text marker in the session ("trial 3 start", "calibration done").
struct Event {
  std::string text;
};

// Opaque bytes, e.g. device wire packets to replay through a codec.
struct RawBytes {
  std::vector<std::uint8_t> bytes;
};

// Index order equals StreamKind - 1.
using RecordPayload =
    std::variant<ImuSample, MarkerObservations, CapacitanceFrame, HandPose, JointAngles, RigidPose, Event, RawBytes>;

struct Record {
  StreamId stream = 0;
  TimeNs time_ns = 0;  // measurement time; for a HandPose it equals payload.time_ns
  RecordPayload payload;

  StreamKind kind() const noexcept { return static_cast<StreamKind>(payload.index() + 1); }
};

struct StreamInfo {
  StreamId id = 0;
  StreamKind kind = StreamKind::event;
  std::string name;  // "hand/right/ground_truth", "imu/0", ... (conventions in the format doc)
  std::string meta;  // UTF-8, conventionally JSON
  std::uint64_t records = 0;  // data records read (reader) or written (writer) so far
};

struct RecordingWriterOptions {
  bool overwrite = false;       // replace an existing file instead of refusing to
  bool fsync_on_flush = false;  // flush() also waits until the bytes are on disk (slow)
};

// Appends records to a new file. Bytes go out through a buffer; flush() pushes
// them to the OS. A crash at any moment leaves a file that reads up to its last
// complete record. Not thread-safe: one owner writes. A moved-from writer may
// only be destroyed or assigned to.
class RecordingWriter {
 public:
  // Writes and flushes the file header. Refuses an existing file unless
  // options.overwrite is set.
  static Result<RecordingWriter> create(const std::filesystem::path& path, RecordingWriterOptions options = {});

  RecordingWriter(RecordingWriter&&) noexcept;
  RecordingWriter& operator=(RecordingWriter&&) noexcept;
  ~RecordingWriter();  // close()s if still open (errors are lost: call close() to see them)

  // Declares a stream. Names are 1-255 printable ASCII characters, unique in the file.
  Result<StreamId> add_stream(StreamKind kind, std::string_view name, std::string_view meta = {});

  // Each write checks that the stream has the matching kind and that the value
  // is storable: every float finite, every quaternion of unit norm. A refused
  // value writes nothing and leaves the writer usable.
  Status write(StreamId stream, const ImuSample& sample, TimeNs time_ns);
  Status write(StreamId stream, const MarkerObservations& observations, TimeNs time_ns);
  Status write(StreamId stream, const CapacitanceFrame& frame, TimeNs time_ns);
  // The record time is pose.time_ns. An inactive pose stores only time, hand and
  // the inactive flag; its joints read back as defaults.
  Status write(StreamId stream, const HandPose& pose);
  Status write(StreamId stream, const JointAngles& angles, TimeNs time_ns);
  Status write(StreamId stream, const RigidPose& pose, TimeNs time_ns);
  Status write(StreamId stream, const Event& event, TimeNs time_ns);
  Status write(StreamId stream, const RawBytes& raw, TimeNs time_ns);

  Status flush();
  // Writes the End record and closes the file. Further calls do nothing.
  Status close();

  bool is_open() const noexcept;
  const std::filesystem::path& path() const noexcept;
  const std::vector<StreamInfo>& streams() const noexcept;
  std::uint64_t records_written() const noexcept;  // stream definitions and data, End excluded

 private:
  struct Impl;
  explicit RecordingWriter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

enum class RecordingEnd : std::uint8_t {
  reading,      // next() has not reached the end yet
  clean,        // End record seen: the writer closed the file
  missing_end,  // ends on a record boundary without End: the writer crashed or is still writing
  truncated,    // ends inside a record (crash mid-write); that partial record was ignored
  // Damaged bytes were found: a record failed its length or CRC check, or End's
  // count does not match. The reader skipped to the next intact record and went
  // on (corrupt_regions, skipped_bytes say how much was lost), or found none.
  corrupt,
};
const char* to_string(RecordingEnd end) noexcept;

struct RecordingSummary {
  RecordingEnd end = RecordingEnd::reading;
  std::string detail;            // why reading stopped and at which byte offset
  std::uint64_t records = 0;     // complete records of every type, End excluded
  std::uint64_t invalid_records = 0;  // intact, but next() rejected the content with an Error
  std::uint64_t skipped_records = 0;  // unknown record type or stream kind (newer minor version)
  std::uint64_t valid_bytes = 0;      // file header + complete records, End included
  std::uint64_t ignored_bytes = 0;    // every byte not in valid_bytes: damaged regions, partial tail, after End
  // Damaged regions skipped by resynchronising on the next intact record, and
  // their bytes (part of ignored_bytes). A region that runs to the end of the
  // file counts too.
  std::uint64_t corrupt_regions = 0;
  std::uint64_t skipped_bytes = 0;
  std::uint64_t first_corrupt_offset = 0;  // byte offset of the first damaged region (if any)
  // Records lost in damaged regions, from the End record's count; 0 when the
  // file has no End record (the count is then unknown).
  std::uint64_t lost_records = 0;
  // Bytes CRC-checked while searching for an intact record after damage
  // (bounded by kRecordingResyncBudget*), and whether that search gave up.
  std::uint64_t resync_checked_bytes = 0;
  bool resync_gave_up = false;

  // The writer closed the file and nothing was lost or damaged.
  bool clean() const noexcept { return end == RecordingEnd::clean && ignored_bytes == 0 && invalid_records == 0; }
};

// Reads a recording front to back. The whole-file view (streams(), summary())
// fills in as records are read; it is final once next() has returned nullopt.
class RecordingReader {
 public:
  // Errors: Errc::not_found / io_error (cannot open), parse_error (not a
  // recording, damaged header), unsupported (newer major format version).
  static Result<RecordingReader> open(const std::filesystem::path& path);
  // Same, over a copy of bytes in memory (tests, fuzzing, network).
  static Result<RecordingReader> from_bytes(std::span<const std::uint8_t> bytes);

  RecordingReader(RecordingReader&&) noexcept;
  RecordingReader& operator=(RecordingReader&&) noexcept;
  ~RecordingReader();

  // The next data record, or nullopt at the end of the readable data; summary()
  // then says whether the end was clean. An Error rejects one intact record
  // (non-finite value, unknown stream, bad count); call next() again to go on.
  // Stream definitions are absorbed into streams(); records of unknown types or
  // kinds (newer minor version) are skipped.
  Result<std::optional<Record>> next();

  std::uint16_t format_major() const noexcept;
  std::uint16_t format_minor() const noexcept;
  const std::string& source_name() const noexcept;  // the path, or "<memory>"
  const std::vector<StreamInfo>& streams() const noexcept;  // in order of definition
  const StreamInfo* stream(StreamId id) const noexcept;      // nullptr if not (yet) defined
  const StreamInfo* find_stream(std::string_view name) const noexcept;
  const RecordingSummary& summary() const noexcept;

  // Random access for readers that index a file in one pass and come back
  // later (ReplayHandSource): the byte offset of the record next() returned
  // last, and a jump back to such an offset. After seek(), next() goes on
  // from there and summary() counts again what it reads; the streams stay.
  std::uint64_t last_record_offset() const noexcept;
  Status seek(std::uint64_t record_offset);

 private:
  struct Impl;
  explicit RecordingReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Keeps one stream's time stamps in order and catches isolated jumps, e.g. a
// CLOCK_REALTIME stamp from a third-party writer in a CLOCK_MONOTONIC stream,
// or a flipped bit. A sample not later than the previous accepted one is
// rejected. A sample more than max_jump_ns after it is held back: the next
// sample decides. Later still, and the new timeline is real (a pause, a
// reconnect): the held sample is accepted. Earlier, and the held sample was an
// outlier: it is rejected and the stream goes on. One bad stamp thus costs one
// sample, never the rest of the stream. The caller keeps the held sample.
class TimestampGuard {
 public:
  static constexpr DurationNs kDefaultMaxJumpNs = 10 * kNsPerSecond;
  explicit TimestampGuard(DurationNs max_jump_ns = kDefaultMaxJumpNs) noexcept : max_jump_ns_(max_jump_ns) {}

  struct Step {
    bool release_held = false;  // accept the held sample now, before this one
    bool reject_held = false;   // the held sample was an outlier
    bool accept = false;        // accept this sample
    bool hold = false;          // keep this sample until the next one decides
    // Neither accept nor hold: this sample is rejected (not later than the last accepted one).
  };
  Step check(TimeNs t_ns) noexcept;
  // The stream ended: a sample still held is rejected, unless nothing was
  // accepted before it (a one-sample stream). Returns whether to accept it.
  bool finish() noexcept;
  // Restarts from a known accepted sample (after a seek).
  void reset(TimeNs last_accepted_ns) noexcept;
  bool holding() const noexcept { return held_; }
  std::optional<TimeNs> last_accepted_ns() const noexcept { return last_; }

 private:
  DurationNs max_jump_ns_;
  std::optional<TimeNs> last_;
  TimeNs held_ns_ = 0;
  bool held_ = false;
};

}  // namespace proprio
