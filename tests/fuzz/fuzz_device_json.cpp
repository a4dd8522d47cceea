// The device description: a refusal names the file; an accepted geometry
// is finite and inside the sane ranges io/device_json.h states.
#include <cmath>
#include <cstdlib>
#include <string>

#include "io/device_json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    cdm::DeviceGeometry g;
    std::string err;
    if (!cdm::io::parse_device_json(text, "fuzz.json", g, err)) {
        if (err.empty()) std::abort();
        return 0;
    }
    if (!(g.a_mm >= cdm::io::kFrameMinMm && g.a_mm <= cdm::io::kFrameMaxMm)) std::abort();
    if (!(g.b_mm >= cdm::io::kFrameMinMm && g.b_mm <= cdm::io::kFrameMaxMm)) std::abort();
    if (!(g.m_mm >= cdm::io::kHolderMinMm && std::isfinite(g.m_mm))) std::abort();
    return 0;
}
