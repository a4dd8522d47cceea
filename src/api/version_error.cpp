#include "api/errors.h"

#include <string>
#include "cdm/cdm.h"
#include "io/log.h"

namespace {
thread_local std::string t_error;
// A constant text shown instead of t_error when set ("" for none): what the
// real-time calls (cdm_get_pose, cdm_get_raw) write, and all they touch. A
// plain pointer in the initial-exec TLS model: no constructor, no
// destructor to register, and no lazy allocation of the thread's TLS block
// on its first use even when libcdm was dlopen'ed (Python's ctypes), where
// t_error's first use in a thread may allocate (glibc's __tls_get_addr and
// __cxa_thread_atexit).
__attribute__((tls_model("initial-exec"))) thread_local const char *t_static = nullptr;
}

namespace cdm {
int fail(int code, const std::string &detail) {
    t_static = nullptr;
    t_error = detail;
    log::message(code == CDM_ERR_INTERNAL ? log::kError : log::kDebug, detail);
    return code;
}
void clear_thread_error() {
    t_static = nullptr;
    t_error.clear();
}
void clear_thread_error_rt() noexcept { t_static = ""; }
int fail_static(int code, const char *text) noexcept {
    t_static = text;
    return code;
}
int fail_noexcept(int code, const char *fn, const char *what) noexcept {
    t_static = nullptr;
    try {
        t_error = std::string(fn) + ": " + (code == CDM_ERR_INTERNAL ? "internal error: " : "") + what;
    } catch (...) {
        t_error.clear(); // no memory for the text: cdm_strerror(code) still says what
    }
    return code;
}
} // namespace cdm

extern "C" {

void cdm_set_log_fn(cdm_log_fn fn, void *user) { cdm::log::set_sink(fn, user); }

const char *cdm_version(void) {
#define CDM_STR2(x) #x
#define CDM_STR(x) CDM_STR2(x)
    return CDM_STR(CDM_VERSION_MAJOR) "." CDM_STR(CDM_VERSION_MINOR) "." CDM_STR(CDM_VERSION_PATCH);
}

int cdm_version_number(void) { return CDM_VERSION_NUMBER; }

const char *cdm_strerror(int code) {
    switch (code) {
    case CDM_OK: return "success";
    case CDM_ERR_INVALID_ARG: return "invalid argument";
    case CDM_ERR_NO_DEVICE: return "no such device";
    case CDM_ERR_IO: return "input/output error";
    case CDM_ERR_TIMEOUT: return "timed out";
    case CDM_ERR_DISCONNECTED: return "device disconnected";
    case CDM_ERR_STALE: return "pose is stale";
    case CDM_ERR_NO_DATA: return "no pose yet (no report received, or none could be solved)";
    case CDM_ERR_PROTOCOL: return "malformed or wrong-version report";
    case CDM_ERR_UNSUPPORTED: return "not supported by this device or transport";
    case CDM_ERR_NO_MEM: return "out of memory or buffer too small";
    case CDM_ERR_PARSE: return "malformed input file";
    case CDM_ERR_NUMERIC: return "no real solution or no convergence";
    case CDM_ERR_END_OF_STREAM: return "end of stream";
    case CDM_ERR_CRC: return "CRC mismatch";
    case CDM_ERR_INTERNAL: return "internal error in libcdm";
    case CDM_ERR_CLOSED: return "the device handle was closed (or shut down) during the call";
    default: return "unknown error";
    }
}

const char *cdm_thread_error(void) { return t_static ? t_static : t_error.c_str(); }

} // extern "C"
