// Internal (not exported, C++ only): what the simulated master truly did for
// a given report, so tests and `cdm stream --truth` can measure the driver's
// error against the simulation.
#pragma once

#include <cstdint>

struct cdm_device;

namespace cdm {

struct SimTruth {
    uint32_t sequence = 0;
    double position[3] = {0, 0, 0};    // device frame, mm
    double orientation[4] = {1, 0, 0, 0};
    double grip = 0;                   // rad
    uint16_t buttons = 0;
    int jig_point = -1;                // jig plan position of a MARK dwell, else -1
};

// The truth of report `seq` if `dev` is a sim: device that produced it among
// its last kSimTruthHistory reports. False otherwise (not a sim, too old).
constexpr uint32_t kSimTruthHistory = 16384;
bool sim_truth(cdm_device *dev, uint32_t seq, SimTruth &out);
bool sim_truth(cdm_device *dev, uint32_t seq, double position[3]);

} // namespace cdm
