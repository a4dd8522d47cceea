// Calibrations through the public API: a refusal sets the thread's error
// text; an accepted calibration never hands out a non-finite position.
#include <cmath>
#include <cstdlib>

#include "cdm/cdm.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    cdm_calibration *cal = nullptr;
    if (cdm_calibration_parse(reinterpret_cast<const char *>(data), size, &cal) != CDM_OK) {
        if (cdm_thread_error()[0] == 0) std::abort();
        return 0;
    }
    const double lengths[3][4] = {{200, 200, 200, 200}, {150, 250, 180, 220}, {1e-3, 1e4, 0, 5}};
    for (const auto &L : lengths) {
        double p[3] = {0, 0, 0};
        if (cdm_calibration_position(cal, L, p) == CDM_OK)
            for (double v : p)
                if (!std::isfinite(v)) std::abort();
        double back[4];
        if (cdm_calibration_lengths(cal, p, back) == CDM_OK)
            for (double v : back)
                if (!std::isfinite(v)) std::abort();
    }
    cdm_calibration_free(cal);
    return 0;
}
