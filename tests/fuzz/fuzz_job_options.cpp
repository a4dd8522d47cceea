// The options of cdm_diagnose and cdm_fit (api/jobs.cpp): a refusal sets
// the thread's error text naming the option; accepted numbers are sane.
#include <cmath>
#include <cstdlib>
#include <string>

#include "api/jobs.h"
#include "cdm/cdm.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    for (bool diagnosis : {true, false}) {
        cdm::api::JobArgs a;
        if (cdm::api::parse_job_options(text.c_str(), "fuzz", diagnosis, a) != CDM_OK) {
            if (cdm_thread_error()[0] == 0) std::abort();
            continue;
        }
        if (!std::isfinite(a.jig_tolerance_mm)) std::abort();
        if (!diagnosis && a.effects.empty()) std::abort();
    }
    return 0;
}
