// Per-thread detail text for failing calls that have no handle (cdm_open,
// cdm_calibration_load, ...). Every extern "C" entry point that fails sets it.
#pragma once
#include <string>

namespace cdm {
// Sets this thread's detail text and returns `code`, so callers can write
// `return fail(CDM_ERR_PARSE, "file.csv:3:5: ...")`.
int fail(int code, const std::string &detail);
void clear_thread_error();
} // namespace cdm
