#include "proprio/ftm_sim/wearer_calibration.hpp"

namespace proprio::ftm_sim {

ftm::FtmCalibrationRecording calibration_recording(const FtmWearerSimulator& sim,
                                                   const std::vector<ftm::FtmEvent>& events) {
  ftm::FtmCalibrationRecording rec;
  for (const FtmPhaseSpan& span : sim.phases()) {
    std::vector<ftm::FtmEvent>* part = nullptr;
    switch (span.phase) {
      case FtmPhase::figure_eight: part = &rec.figure_eight; break;
      case FtmPhase::pose_flat: part = &rec.poses[0]; break;
      case FtmPhase::pose_thumb_parallel: part = &rec.poses[1]; break;
      case FtmPhase::pose_bend_90: part = &rec.poses[2]; break;
      case FtmPhase::task: break;
    }
    if (part == nullptr) continue;
    for (const ftm::FtmEvent& e : events) {
      const TimeNs t = e.time_ns();
      if (t >= span.begin_ns && t < span.end_ns) part->push_back(e);
    }
  }
  return rec;
}

Result<WearerCalibration> calibrate_from_wearer(FtmWearerSimulator& sim, const ftm::MahonyOptions& attitude) {
  WearerCalibration out;
  sim.advance(sim.task_begin_ns() - 1, out.events);
  const HandShape& shape = sim.model().shape();
  const ftm::FtmCalibration base =
      ftm::nominal_ftm_calibration(sim.options().hand, shape.hand_length_m, shape.hand_width_m);
  auto outcome = ftm::calibrate_ftm(calibration_recording(sim, out.events), base, attitude);
  if (!outcome) return outcome.error();
  out.outcome = std::move(*outcome);
  return out;
}

}  // namespace proprio::ftm_sim
