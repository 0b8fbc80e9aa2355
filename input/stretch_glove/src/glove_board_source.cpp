#include "proprio/stretch_glove/glove_board_source.hpp"

#include <limits>

namespace proprio::stretch_glove {

Result<std::unique_ptr<GloveBoardSource>> GloveBoardSource::start(std::unique_ptr<hid::HidTransport> transport,
                                                                  const StretchGloveLayout& layout,
                                                                  MinMaxCalibration calibration, OnnxPoseModel model,
                                                                  GloveHandSourceOptions options,
                                                                  devices::StretchDeviceOptions device_options) {
  auto inner = GloveHandSource::create(layout, std::move(calibration), std::move(model), std::move(options));
  if (!inner) return inner.error();
  std::unique_ptr<GloveBoardSource> s(new GloveBoardSource());
  s->inner_ = std::move(*inner);
  device_options.stream.expected_top_strips = static_cast<std::uint8_t>(layout.top_strips);
  device_options.stream.expected_bottom_strips = static_cast<std::uint8_t>(layout.bottom_strips);
  // Flagged measurements are delivered too, as NaN: the read-out then leaves
  // their rows out of the solve instead of reusing a stale value.
  device_options.deliver_flagged = true;
  s->device_ = std::make_unique<devices::StretchDevice>(std::move(transport), device_options);
  GloveHandSource* sink = s->inner_.get();
  s->device_->set_sample_callback([sink](const devices::StretchSample& m) {
    const double pf = m.status == devices::StretchMeasurementStatus::ok ? m.capacitance_pf
                                                                       : std::numeric_limits<double>::quiet_NaN();
    sink->add_measurement(m.combination, pf, m.time_ns);
  });
  // A report's measurements arrive together: the frame that falls due inside
  // one is solved at its end, with all of them. Solving at the 16th update
  // instead kept the rest of the report (up to 8 measurements, 8 ms) out of
  // the pose although it was already here.
  s->device_->set_burst_callback([sink] { sink->end_burst(); });
  if (auto st = s->device_->start(); !st) return st.error();
  return s;
}

}  // namespace proprio::stretch_glove
