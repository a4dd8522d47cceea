// The options of cdm_diagnose, cdm_fit and cdm_check (api/jobs.cpp): a refusal sets
// the thread's error text naming the option; accepted numbers are sane.
#include <cmath>
#include <cstdlib>
#include <string>

#include "api/jobs.h"
#include "cdm/cdm.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    using cdm::api::JobKind;
    for (JobKind kind : {JobKind::Diagnosis, JobKind::Fit, JobKind::Check}) {
        cdm::api::JobArgs a;
        if (cdm::api::parse_job_options(text.c_str(), "fuzz", kind, a) != CDM_OK) {
            if (cdm_thread_error()[0] == 0) std::abort();
            continue;
        }
        if (!std::isfinite(a.jig_tolerance_mm) || !std::isfinite(a.max_error_mm)) std::abort();
        if (kind == JobKind::Fit && a.effects.empty()) std::abort();
        if (kind == JobKind::Check && (!a.effects.empty() || !a.calib_out.empty())) std::abort();
        if (kind != JobKind::Check && a.max_error_mm != -1) std::abort();
    }
    return 0;
}
