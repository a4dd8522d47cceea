// libcdm's messages out to the application (cdm_set_log_fn): one process-
// wide sink, called with no lock held. Lives in io because every module above may log.
// Never called on the haptic path (cdm_get_pose): only where something
// went wrong or changed (a failing call, a malformed report, a disconnection).
#pragma once

#include <string>

namespace cdm::log {

enum Level : int { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };
using Fn = void (*)(void *user, int level, const char *message);

// fn == nullptr removes the sink. Waits for the calls in progress on other
// threads to end.
void set_sink(Fn fn, void *user);
// Hands `text` to the sink, if any; never throws. No lock is held while the
// sink runs: it may be called concurrently from several threads, and may
// itself call libcdm (even set_sink, or cdm_close).
void message(int level, const std::string &text) noexcept;

} // namespace cdm::log
