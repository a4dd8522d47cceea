// What `cdm calib diagnose` is asked to do (diagnose.h): the model, the
// stages that run, the threads, the readings' own error.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "calib/evaluation/noise.h"

namespace cdm {

struct DiagnoseOptions {
    std::vector<std::string> effects;  // the model to fit (none: nominal)
    double jig_tolerance_mm = -1;      // < 0: estimated from the data
    bool candidates = true;
    bool search = true;                // the model search (needs candidates)
    bool validation = true;
    bool per_position = true;
    // Positions the model and their neighbours both disown (a mis-seated
    // probe, a wrong hole) are set aside and the diagnosis run again without
    // them (data.outliers says which); false keeps every position.
    bool outliers = true;
    std::function<bool(const std::string &stage, double fraction)> progress;
    // Threads for the search's independent fits (0: the machine's cores, at
    // most 8). The result does not depend on it.
    int threads = 0;
    // Each reading's own white error (none: estimated from the user's
    // model's misclosure). diagnose() sets it for a second run when the
    // recommended model's misclosure disagrees (docs/calibration.md).
    std::optional<diag::ReadingNoise> reading_noise;
};

} // namespace cdm
