#pragma once
// The stretch glove on a live read-out board: the board's reader thread
// (devices::StretchDevice, USB HID) feeds a GloveHandSource. Unplugging the
// board stops new poses (consumers see them go stale); plugging it back in
// resumes them, after one measurement cycle refills the read-out.
#include <memory>

#include "proprio/hid/hid_transport.hpp"
#include "proprio/stretch_board/stretch_device.hpp"
#include "proprio/stretch_glove/glove_hand_source.hpp"

namespace proprio::stretch_glove {

class GloveBoardSource final : public HandSource {
 public:
  // Starts reading. The device refuses a board whose strip counts differ from the layout's.
  static Result<std::unique_ptr<GloveBoardSource>> start(std::unique_ptr<hid::HidTransport> transport,
                                                         const StretchGloveLayout& layout,
                                                         MinMaxCalibration calibration, OnnxPoseModel model,
                                                         GloveHandSourceOptions options = {},
                                                         devices::StretchDeviceOptions device_options = {});

  std::string_view name() const noexcept override { return "glove"; }
  bool available(Handedness hand) const noexcept override { return inner_->available(hand); }
  Result<HandPose> pose_at(Handedness hand, TimeNs t_ns) override { return inner_->pose_at(hand, t_ns); }
  PoseLookup lookup(Handedness hand, TimeNs t_ns, HandPose& out) noexcept override {
    return inner_->lookup(hand, t_ns, out);
  }
  GloveSourceStats stats() const { return inner_->stats(); }
  devices::StretchDeviceStats device_stats() { return device_->stats(); }

 private:
  GloveBoardSource() = default;
  std::unique_ptr<GloveHandSource> inner_;
  std::unique_ptr<devices::StretchDevice> device_;  // declared last: stops first
};

}  // namespace proprio::stretch_glove
