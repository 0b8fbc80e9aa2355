#pragma once
// The simulated wearer calibrated the way a real one is: its figure-eight and
// its three (imperfectly held) poses go through proprio::ftm's calibration
// (calibrate_ftm), never through the simulator's truth. Every user of the
// simulated FTM (the bench, the layer's sim source, the peg-in-hole study,
// `proprio calibrate ftm --sim-subject`) calibrates through this one path.
#include <vector>

#include "proprio/ftm/ftm_calibration.hpp"
#include "proprio/ftm_sim/ftm_wearer_sim.hpp"

namespace proprio::ftm_sim {

struct WearerCalibration {
  ftm::FtmCalibrationOutcome outcome;
  // Every event delivered up to the start of the task, in time order: a
  // tracker fed these first starts the task with converged filters.
  std::vector<ftm::FtmEvent> events;
};

// The wearer's events up to its task, split by its phases.
ftm::FtmCalibrationRecording calibration_recording(const FtmWearerSimulator& sim,
                                                   const std::vector<ftm::FtmEvent>& events);

// Advances `sim` to the start of its task and calibrates from what it
// delivered. The base calibration is nominal for the wearer's hand and size.
Result<WearerCalibration> calibrate_from_wearer(FtmWearerSimulator& sim, const ftm::MahonyOptions& attitude = {});

}  // namespace proprio::ftm_sim
