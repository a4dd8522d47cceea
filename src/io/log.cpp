// See log.h.
#include "io/log.h"

#include <atomic>
#include <mutex>

namespace cdm::log {

namespace {
// Recursive: a sink may call libcdm, which may log again on this thread.
std::recursive_mutex g_mu;
Fn g_fn = nullptr;
void *g_user = nullptr;
std::atomic<bool> g_set{false}; // a quick "nobody listens" without the lock
} // namespace

void set_sink(Fn fn, void *user) {
    std::lock_guard<std::recursive_mutex> lock(g_mu);
    g_fn = fn;
    g_user = user;
    g_set.store(fn != nullptr);
}

void message(int level, const std::string &text) noexcept {
    if (!g_set.load(std::memory_order_relaxed)) return;
    try {
        std::lock_guard<std::recursive_mutex> lock(g_mu);
        if (g_fn) g_fn(g_user, level, text.c_str());
    } catch (...) {
        // A message that cannot be delivered is dropped; the caller's error
        // code still says what happened.
    }
}

} // namespace cdm::log
