// libcdm's messages out to the application (cdm_set_log_fn): one process-
// wide sink, serialised. Lives in io because every module above may log.
// Never called on the haptic path (cdm_get_pose): only where something
// went wrong or changed (a failing call, a malformed report, a disconnection).
#pragma once

#include <string>

namespace cdm::log {

enum Level : int { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };
using Fn = void (*)(void *user, int level, const char *message);

// fn == nullptr removes the sink. Waits for a call in progress to end.
void set_sink(Fn fn, void *user);
// Hands `text` to the sink, if any; never throws. The sink is never called
// concurrently, and may itself call libcdm (even set_sink).
void message(int level, const std::string &text) noexcept;

} // namespace cdm::log
