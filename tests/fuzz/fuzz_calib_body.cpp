#include "fuzz_calib_body.h"

#include <cmath>
#include <cstdlib>
#include <string>

#include "calib/dataset/dataset.h"
#include "cdm/cdm.h"
#include "model/model.h"
#include "io/calibration_json.h"
#include "io/device_json.h"

void fuzz_calib_one(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    std::string err;
    cdm::Dataset d;
    if (cdm::parse_dataset(text, "fuzz.csv", d, err)) {
        for (auto &p : d.pos) {
            if (p.n <= 0) std::abort();
            for (int c = 0; c < 4; ++c)
                if (!std::isfinite(p.mean[c])) std::abort();
        }
    } else if (err.empty()) {
        std::abort(); // a refusal always says why
    }
    cdm::DeviceGeometry g;
    if (!cdm::io::parse_device_json(text, "fuzz.json", g, err) && err.empty()) std::abort();
    cdm_calibration *cal = nullptr;
    if (cdm_calibration_parse(text.data(), text.size(), &cal) == CDM_OK) {
        const double L[4] = {200, 200, 200, 200};
        double p[3] = {0, 0, 0};
        if (cdm_calibration_position(cal, L, p) == CDM_OK)
            for (double v : p)
                if (!std::isfinite(v)) std::abort();
        cdm_calibration_free(cal);
    } else if (cdm_thread_error()[0] == 0) {
        std::abort();
    }
}
