// Per-thread detail text for failing calls (cdm_thread_error), and the one
// exception boundary every extern "C" entry point goes through.
//
// Contract: an entry point wrapped in guarded() clears the text on entry, so
// after it returns the text belongs to that call: empty on success, set on
// every failure. Entry points that never fail with text (cdm_version,
// cdm_strerror, the count/name getters) leave it alone.
#pragma once
#include <new>
#include <stdexcept>
#include <string>

#include "cdm/cdm.h"

namespace cdm {
// Sets this thread's detail text and returns `code`, so callers can write
// `return fail(CDM_ERR_PARSE, "file.csv:3:5: ...")`.
int fail(int code, const std::string &detail);
void clear_thread_error();
// Sets the text without allocating a std::string argument first, and never
// throws (a text that cannot be stored is replaced by a fixed one).
int fail_noexcept(int code, const char *fn, const char *what) noexcept;
// Sets the text to a constant (a string literal that lives for the
// program), touching nothing but one initial-exec TLS pointer: no
// allocation, ever, even on a thread's first call (version_error.cpp). The
// real-time calls' (cdm_get_pose, cdm_get_raw) way to say why they failed.
int fail_static(int code, const char *text) noexcept;
// The same for the real-time calls' entry: the text reads empty.
void clear_thread_error_rt() noexcept;

// Runs `body` (returning a cdm status code) so that no exception reaches a C
// caller: std::bad_alloc -> CDM_ERR_NO_MEM, any other -> CDM_ERR_INTERNAL
// with its what() text, both naming `fn`.
template <class F> int guarded(const char *fn, F &&body) noexcept {
    clear_thread_error();
    try {
        return body();
    } catch (const std::bad_alloc &) {
        return fail_noexcept(CDM_ERR_NO_MEM, fn, "out of memory");
    } catch (const std::exception &e) {
        return fail_noexcept(CDM_ERR_INTERNAL, fn, e.what());
    } catch (...) {
        return fail_noexcept(CDM_ERR_INTERNAL, fn, "unknown exception");
    }
}
} // namespace cdm
