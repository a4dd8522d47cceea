// The jig dataset CSV parser: a refusal names what is wrong; accepted data
// has only positions with samples and finite means; read again, it gives
// back every row but the glitches set aside, and without its first point
// every row but that point's.
#include <cmath>
#include <cstdlib>
#include <string>

#include "calib/dataset/dataset.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    cdm::Dataset d;
    std::string err;
    if (!cdm::parse_dataset(text, "fuzz.csv", d, err)) {
        if (err.empty()) std::abort();
        return 0;
    }
    size_t used = 0;
    for (const auto &p : d.pos) {
        if (p.n <= 0) std::abort();
        used += size_t(p.n);
        for (double m : p.mean)
            if (!std::isfinite(m)) std::abort();
        for (double r : p.ref)
            if (!std::isfinite(r)) std::abort();
    }
    if (used + d.glitches.size() != d.rows || d.glitches.size() != d.excluded_rows.size()) std::abort();
    size_t seen = 0;
    if (!cdm::for_each_sample(d, [&](size_t g, const double *) { seen += g < d.pos.size(); }, err) || seen != used)
        std::abort();
    if (d.pos.size() > 1) {
        cdm::Dataset kept;
        if (!cdm::without_points(d, {d.pos[0].point}, kept, err)) std::abort();
        size_t k = 0;
        for (const auto &p : kept.pos) k += size_t(p.n);
        if (kept.pos.size() + 1 != d.pos.size() || k != used - size_t(d.pos[0].n)) std::abort();
        seen = 0;
        if (!cdm::for_each_sample(kept, [&](size_t, const double *) { ++seen; }, err) || seen != k) std::abort();
    }
    return 0;
}
