// The jig dataset CSV parser: a refusal names what is wrong; accepted data
// has only positions with samples and finite means.
#include <cmath>
#include <cstdlib>
#include <string>

#include "calib/dataset.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    cdm::Dataset d;
    std::string err;
    if (!cdm::parse_dataset(text, "fuzz.csv", d, err)) {
        if (err.empty()) std::abort();
        return 0;
    }
    for (const auto &p : d.pos) {
        if (p.n <= 0) std::abort();
        for (double m : p.mean)
            if (!std::isfinite(m)) std::abort();
        for (double r : p.ref)
            if (!std::isfinite(r)) std::abort();
    }
    return 0;
}
