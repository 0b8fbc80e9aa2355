#include "proprio/vist_eval/emulated_vist.hpp"

#include <fmt/format.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <optional>
#include <thread>

#include <opencv2/core.hpp>

#include "proprio/core/log.hpp"
#include "proprio/core/random.hpp"
#include "proprio/sim/hand_truth_writer.hpp"
#include "proprio/sim/imu_sim.hpp"
#include "proprio/sim/stereo_image_sim.hpp"
#include "proprio/sim/subjects.hpp"
#include "proprio/vist/stereo_camera.hpp"

namespace proprio::vist_eval {

Status EmulatedVistOptions::validate() const {
  if (auto s = sim::sim_subject(subject); !s) return s.error().with_context("emulated VIST");
  if (!std::isfinite(camera_scale) || camera_scale < 0.25 || camera_scale > 1.0) {
    return make_error(Errc::invalid_argument,
                      fmt::format("emulated VIST: camera_scale = {} must be in [0.25, 1]", camera_scale));
  }
  if (!(std::abs(imu_clock_error_ppm) <= 1000.0)) {
    return make_error(Errc::invalid_argument, "emulated VIST: imu_clock_error_ppm must be within +-1000");
  }
  if (serve.latency_min_ns < 0 || serve.latency_jitter_ns < 0 || serve.pump_interval_ns <= 0) {
    return make_error(Errc::invalid_argument, "emulated VIST: the board's latencies must be >= 0, its pump period > 0");
  }
  if (camera_reopen_attempts < 0 || camera_reopen_attempts > 1000 ||
      !(camera_reopen_interval_s >= 0.0 && camera_reopen_interval_s <= 60.0)) {
    return make_error(Errc::invalid_argument, "emulated VIST: camera reopen: 0-1000 attempts, 0-60 s apart");
  }
  return {};
}

std::string EmulatedVistOptions::describe() const {
  return fmt::format(
      "emulated VIST: subject {}, seed {}, {} hand, {} motion, camera at {:g} of the rig's "
      "resolution, board clock {:+g} ppm, USB latency {:.1f}-{:.1f} ms{}",
      subject, seed, to_string(hand), sim::to_string(protocol), camera_scale, imu_clock_error_ppm,
      1e-6 * static_cast<double>(serve.latency_min_ns),
      1e-6 * static_cast<double>(serve.latency_min_ns + serve.latency_jitter_ns),
      truth_path.empty() ? std::string() : "; truth -> " + truth_path);
}

std::string EmulatedVistStats::describe() const {
  std::string s = fmt::format(
      "emulated rig: {} frames rendered ({:.1f} ms mean, {:.1f} ms max), {} skipped, {} "
      "from the fallback head; board {} ticks, {} reports; {} truth rows{}",
      frames_rendered, render_ms_mean, render_ms_max, frames_skipped, frames_without_head, imu_ticks, imu_reports_sent,
      truth_rows, anchored ? "" : "; wearer not placed yet");
  if (!truth_error.empty()) s += " (truth file: " + truth_error + ")";
  return s;
}

ImuGloveDescription scale_camera(const ImuGloveDescription& glove, double scale) {
  ImuGloveDescription g = glove;
  if (scale == 1.0) return g;
  PinholeCamera& c = g.rig.camera;
  const double sx = std::round(c.width_px * scale) / c.width_px;
  const double sy = std::round(c.height_px * scale) / c.height_px;
  c.width_px = static_cast<int>(std::round(c.width_px * scale));
  c.height_px = static_cast<int>(std::round(c.height_px * scale));
  // Pixel centres at integers: a pixel's edge (x + 0.5) scales, its centre does not.
  c.fx_px *= sx;
  c.fy_px *= sy;
  c.cx_px = (c.cx_px + 0.5) * sx - 0.5;
  c.cy_px = (c.cy_px + 0.5) * sy - 0.5;
  return g;
}

namespace {

// The part of a head pose the wearer's body follows: position and heading
// (rotation about world +Y), upright.
Pose upright(const Pose& T_world_head) {
  Vec3 forward = T_world_head.q * Vec3(0.0, 0.0, -1.0);
  forward.y() = 0.0;
  if (forward.norm() < 1e-3) {  // looking straight up or down: the head's top points along the heading
    forward = T_world_head.q * Vec3(0.0, forward.y() >= 0.0 ? -1.0 : 1.0, 0.0);
    forward.y() = 0.0;
  }
  if (forward.norm() < 1e-9) return {Quat::Identity(), T_world_head.p};
  forward.normalize();
  const double yaw = std::atan2(-forward.x(), -forward.z());
  return {Quat(Eigen::AngleAxisd(yaw, Vec3::UnitY())), T_world_head.p};
}

HandPose transformed(const HandPose& in, const Pose& A) {
  HandPose out = in;
  for (std::size_t i = 0; i < kHandJointCount; ++i) {
    out.T_world_joint[i] = A * in.T_world_joint[i];
    out.linear_velocity_in_world[i] = A.q * in.linear_velocity_in_world[i];
    out.angular_velocity_in_world[i] = A.q * in.angular_velocity_in_world[i];
  }
  return out;
}

}  // namespace

// ---------------------------------------------------------------------------

struct EmulatedVistRig::Impl {
  Impl(const ImuGloveDescription& g, const EmulatedVistOptions& o, vist::HeadPoseProvider h, const Pose& fallback,
       HandShape shape, const sim::HandMotionOptions& mo)
      : glove(g),
        options(o),
        head(std::move(h)),
        fallback_T_world_head(fallback),
        T_rest_head_in_wearer(mo.T_world_head_rest),
        T_world_wearer(upright(fallback) * mo.T_world_head_rest.inverse()),
        motion_imu(HandModel(shape), mo),
        motion_camera(HandModel(shape), mo),
        motion_truth(HandModel(shape), mo) {}

  ImuGloveDescription glove;
  EmulatedVistOptions options;
  vist::HeadPoseProvider head;
  Pose fallback_T_world_head;
  Pose T_rest_head_in_wearer;  // the generator's resting head

  mutable std::mutex anchor_mutex;
  Pose T_world_wearer;
  bool anchored = false;

  // One generator per thread that samples it (it extends its keyframes
  // lazily): the board's, the camera's and truth_at()'s.
  sim::HandMotionGenerator motion_imu;     // board thread
  sim::HandMotionGenerator motion_camera;  // under render_mutex
  std::mutex truth_mutex;
  sim::HandMotionGenerator motion_truth;  // under truth_mutex
  std::optional<sim::ImuSimulator> imu;   // board thread (samples motion_imu)
  std::unique_ptr<sim::HandTruthWriter> truth_writer;
  std::atomic<std::uint64_t> truth_rows{0};

  std::mutex render_mutex;
  std::optional<sim::StereoImageSimulator> renderer;
  sim::StereoImageFrame frame;
  std::uint64_t frames_rendered = 0, frames_skipped = 0, frames_without_head = 0;  // under render_mutex
  double render_ms_sum = 0.0, render_ms_max = 0.0;

  std::atomic<TimeNs> t0{0};
  std::atomic<TimeNs> camera_unplugged_until{0};
  std::unique_ptr<devices::ImuGloveEmulatorServer> server;  // last: its thread uses everything above

  Pose wearer() const {
    std::lock_guard lock(anchor_mutex);
    return T_world_wearer;
  }

  // Camera thread: places the wearer at the first head pose the provider gives.
  void anchor_at(const Pose& T_world_head) {
    std::lock_guard lock(anchor_mutex);
    if (anchored) return;
    anchored = true;
    T_world_wearer = upright(T_world_head) * T_rest_head_in_wearer.inverse();
    const Vec3& p = T_world_wearer.p;
    logger().info(
        "emulated VIST: the wearer stands at the headset's first pose (wearer frame at ({:.2f}, {:.2f}, "
        "{:.2f}) m)",
        p.x(), p.y(), p.z());
  }

  // Board thread, one call per tick.
  void read_imus(TimeNs t_ns, std::span<ImuSample> out) {
    const auto readings = imu->next();
    for (std::size_t i = 0; i < out.size() && i < readings.size(); ++i) out[i] = readings[i].sample;
    if (truth_writer) {
      HandPose p = transformed(motion_imu.sample(t_ns).pose, wearer());
      p.time_ns = t0.load(std::memory_order_acquire) + t_ns;
      truth_writer->write(p);
      truth_rows.fetch_add(1, std::memory_order_relaxed);
    }
  }

  // Camera thread: the stereo pair captured at t_capture_ns, side by side, in a new buffer.
  void render(TimeNs t_capture_ns, cv::Mat& side_by_side) {
    Pose T_world_head = fallback_T_world_head;
    const bool known = head && head(t_capture_ns, T_world_head);
    if (known) anchor_at(T_world_head);
    const Pose T_wearer_world = wearer().inverse();
    const auto t_start = std::chrono::steady_clock::now();
    std::lock_guard lock(render_mutex);
    const TimeNs t = t_capture_ns - t0.load(std::memory_order_acquire);
    const HandPose hand = motion_camera.sample(std::max<TimeNs>(t, 0)).pose;
    renderer->render(hand, T_wearer_world * T_world_head, t, frame);
    side_by_side = cv::Mat();  // frames handed out keep their buffers
    cv::hconcat(frame.images[0], frame.images[1], side_by_side);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start).count();
    ++frames_rendered;
    frames_without_head += known ? 0 : 1;
    render_ms_sum += ms;
    render_ms_max = std::max(render_ms_max, ms);
  }

  bool camera_unplugged() const {
    return MonotonicClock::instance().now_ns() < camera_unplugged_until.load(std::memory_order_acquire);
  }
};

namespace {

// The camera: a stereo pair rendered at each grab.
class EmulatedStereoVideo final : public vist::VideoSource {
 public:
  explicit EmulatedStereoVideo(EmulatedVistRig::Impl& rig) : rig_(rig) {}

  std::string name() const override { return "emulated stereo camera"; }
  bool live() const override { return true; }
  Status open() override {
    if (rig_.camera_unplugged()) return make_error(Errc::not_found, "the emulated stereo camera is unplugged");
    closed_.store(false, std::memory_order_release);
    return {};
  }
  void close() override { closed_.store(true, std::memory_order_release); }

  bool grab() override {
    if (closed_.load(std::memory_order_acquire) || rig_.camera_unplugged()) return false;
    const Clock& clock = MonotonicClock::instance();
    const double period_ns = 1e9 / rig_.glove.rig.rate_hz;
    const TimeNs t0 = rig_.t0.load(std::memory_order_acquire);
    auto slot_time = [&](std::int64_t k) {
      return t0 + static_cast<TimeNs>(std::llround(period_ns * static_cast<double>(k)));
    };
    const auto now_slot = static_cast<std::int64_t>(std::floor(static_cast<double>(clock.now_ns() - t0) / period_ns));
    std::int64_t k = last_slot_ < 0 ? now_slot + 1 : last_slot_ + 1;
    if (k < now_slot) {  // still rendering when these were due: a real camera's frames would have been lost
      std::lock_guard lock(rig_.render_mutex);
      rig_.frames_skipped += static_cast<std::uint64_t>(now_slot - k);
      k = now_slot;
    }
    // Wait for the capture instant in short steps, so close() is noticed.
    for (TimeNs left = slot_time(k) - clock.now_ns(); left > 0; left = slot_time(k) - clock.now_ns()) {
      if (closed_.load(std::memory_order_acquire)) return false;
      std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<TimeNs>(left, 10 * kNsPerMillisecond)));
    }
    if (rig_.camera_unplugged()) return false;
    last_slot_ = k;
    capture_ns_ = slot_time(k);
    rig_.render(capture_ns_, image_);
    return true;
  }
  bool retrieve(cv::Mat& bgr) override {
    bgr = image_;
    return !bgr.empty();
  }
  // The capture instant on CLOCK_MONOTONIC, as a V4L2 camera reports it.
  double backend_time_ms() const override { return static_cast<double>(capture_ns_) * 1e-6; }
  double fps() const override { return rig_.glove.rig.rate_hz; }

 private:
  EmulatedVistRig::Impl& rig_;
  std::atomic<bool> closed_{true};
  std::int64_t last_slot_ = -1;
  TimeNs capture_ns_ = 0;
  cv::Mat image_;
};

}  // namespace

// ---------------------------------------------------------------------------

Result<std::shared_ptr<EmulatedVistRig>> EmulatedVistRig::create(const ImuGloveDescription& glove,
                                                                 const EmulatedVistOptions& options,
                                                                 vist::HeadPoseProvider head,
                                                                 const Pose& fallback_T_world_head) {
  if (auto s = options.validate(); !s) return s.error();
  auto subject = sim::sim_subject(options.subject);
  if (!subject) return subject.error();
  auto shape = subject->shape();
  if (!shape) return shape.error();
  // The same seed streams as the evaluation protocol (evaluation.cpp).
  const std::uint64_t seed = mix_seed(options.seed, static_cast<std::uint64_t>(options.subject));
  sim::HandMotionOptions mo;
  mo.protocol = options.protocol;
  mo.hand = options.hand;
  mo.seed = mix_seed(seed, 1);
  auto impl = std::make_unique<Impl>(glove, options, std::move(head), fallback_T_world_head, *shape, mo);

  auto imu = sim::ImuSimulator::create(impl->motion_imu, glove.place_imus(*shape, options.hand), sim::ImuNoiseOptions{},
                                       mix_seed(seed, 2));
  if (!imu) return imu.error();
  impl->imu.emplace(std::move(*imu));

  sim::StereoImageSimOptions io;
  io.visibility = sim::StereoImageSimOptions::default_visibility();
  io.visibility.drop_probability = 0.0;  // a lost frame is the camera's business (skips, unplugs)
  io.visibility.seed = mix_seed(seed, 3);
  io.seed = mix_seed(seed, 6);
  io.T_world_head_rest = mo.T_world_head_rest;
  auto renderer = sim::StereoImageSimulator::create(glove, *shape, io);
  if (!renderer) return renderer.error();
  impl->renderer.emplace(std::move(*renderer));

  if (!options.truth_path.empty()) {
    auto w = sim::HandTruthWriter::open(options.truth_path);
    if (!w) return w.error().with_context("emulated VIST");
    impl->truth_writer = std::move(*w);
  }

  devices::ImuGloveEmulatorOptions eo;
  eo.imu_count = static_cast<std::uint8_t>(impl->imu->imu_count());
  eo.rate_hz = static_cast<std::uint16_t>(std::lround(impl->imu->options().sample_rate_hz));
  eo.clock_error_ppm = options.imu_clock_error_ppm;
  eo.seed = mix_seed(seed, 7);
  auto emulator = devices::ImuGloveEmulator::create(eo);
  if (!emulator) return emulator.error().with_context("emulated VIST");
  auto link = std::make_shared<hid::FakeHidLink>();
  Impl* raw = impl.get();
  devices::ImuGloveServeOptions serve = options.serve;
  serve.seed = mix_seed(seed, 8);
  impl->server = std::make_unique<devices::ImuGloveEmulatorServer>(
      devices::ImuGloveTicker(std::move(*emulator), [raw](std::int64_t, TimeNs t_ns,
                                                          std::span<ImuSample> out) { raw->read_imus(t_ns, out); }),
      link, serve);
  std::shared_ptr<EmulatedVistRig> rig(new EmulatedVistRig(std::move(impl)));
  rig->link_ = std::move(link);
  return rig;
}

EmulatedVistRig::EmulatedVistRig(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

EmulatedVistRig::~EmulatedVistRig() {
  impl_->server->stop();
  if (impl_->truth_writer) impl_->truth_writer->flush();
}

void EmulatedVistRig::start() {
  // Time zero first: the camera's grid and the truth rows read it.
  impl_->t0.store(MonotonicClock::instance().now_ns(), std::memory_order_release);
  impl_->server->start();
  impl_->t0.store(impl_->server->time_zero_ns(), std::memory_order_release);
}

TimeNs EmulatedVistRig::time_zero_ns() const { return impl_->t0.load(std::memory_order_acquire); }

std::unique_ptr<devices::ImuGloveDevice> EmulatedVistRig::make_glove_device(devices::ImuGloveDeviceOptions options) {
  return std::make_unique<devices::ImuGloveDevice>(std::make_unique<hid::FakeHidTransport>(link_), options);
}

vist::StereoCameraOpener EmulatedVistRig::camera_opener() {
  Impl* rig = impl_.get();
  return [rig]() -> Result<std::unique_ptr<vist::StereoCamera>> {
    vist::StereoCameraOptions co;
    co.input = vist::StereoInput::device;
    co.left = "emulated";
    co.side_by_side = true;
    co.width_px = rig->glove.rig.camera.width_px;
    co.height_px = rig->glove.rig.camera.height_px;
    co.fps = rig->glove.rig.rate_hz;
    co.reader_thread = true;  // the camera captures whether or not anyone is reading
    co.reopen_attempts = rig->options.camera_reopen_attempts;
    co.reopen_interval_s = rig->options.camera_reopen_interval_s;
    return vist::StereoCamera::open(co, std::make_unique<EmulatedStereoVideo>(*rig), nullptr);
  };
}

void EmulatedVistRig::unplug_camera_for(DurationNs duration_ns) {
  impl_->camera_unplugged_until.store(MonotonicClock::instance().now_ns() + duration_ns, std::memory_order_release);
}

HandPose EmulatedVistRig::truth_at(TimeNs t_ns) {
  const Pose A = impl_->wearer();
  std::lock_guard lock(impl_->truth_mutex);
  HandPose p = transformed(impl_->motion_truth.sample(std::max<TimeNs>(0, t_ns - time_zero_ns())).pose, A);
  p.time_ns = t_ns;
  return p;
}

Pose EmulatedVistRig::T_world_wearer() const { return impl_->wearer(); }

EmulatedVistStats EmulatedVistRig::stats() const {
  EmulatedVistStats s;
  {
    std::lock_guard lock(impl_->render_mutex);
    s.frames_rendered = impl_->frames_rendered;
    s.frames_skipped = impl_->frames_skipped;
    s.frames_without_head = impl_->frames_without_head;
    s.render_ms_mean =
        impl_->frames_rendered ? impl_->render_ms_sum / static_cast<double>(impl_->frames_rendered) : 0.0;
    s.render_ms_max = impl_->render_ms_max;
  }
  const auto board = impl_->server->emulator_stats();
  s.imu_ticks = board.ticks;
  s.imu_reports_sent = board.reports_sent;
  s.truth_rows = impl_->truth_rows.load(std::memory_order_relaxed);
  {
    std::lock_guard lock(impl_->anchor_mutex);
    s.anchored = impl_->anchored;
  }
  if (impl_->truth_writer) s.truth_error = impl_->truth_writer->error();
  return s;
}

const ImuGloveDescription& EmulatedVistRig::glove() const noexcept { return impl_->glove; }
const EmulatedVistOptions& EmulatedVistRig::options() const noexcept { return impl_->options; }

// ---------------------------------------------------------------------------

Result<EmulatedVist> start_emulated_vist(const ImuGloveDescription& glove, const EmulatedVistOptions& options,
                                         vist::VistLiveSourceOptions source_options, vist::HeadPoseProvider head,
                                         devices::ImuGloveDeviceOptions glove_options) {
  if (auto s = options.validate(); !s) return s.error();
  const ImuGloveDescription scaled = scale_camera(glove, options.camera_scale);
  source_options.source.tracker.hand = options.hand;
  auto rig = EmulatedVistRig::create(scaled, options, head, source_options.live.T_world_head_fixed);
  if (!rig) return rig.error();
  (*rig)->start();
  auto device = (*rig)->make_glove_device(glove_options);
  auto opener = (*rig)->camera_opener();
  auto source = vist::VistLiveSource::start(scaled, std::move(device), std::move(opener), std::move(source_options),
                                            std::move(head), *rig);
  if (!source) return source.error();
  logger().info("{}", options.describe());
  return EmulatedVist{std::move(*source), std::move(*rig)};
}

}  // namespace proprio::vist_eval
