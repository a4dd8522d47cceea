// See log.h.
#include "io/log.h"

#include <atomic>
#include <condition_variable>
#include <mutex>

namespace cdm::log {

namespace {
// Guards the sink and the count of its calls in progress; never held while
// the sink runs (a sink may call libcdm, cdm_close included, which may wait
// for a reader thread that is logging at the same time).
std::mutex g_mu;
std::condition_variable g_idle;
Fn g_fn = nullptr;
void *g_user = nullptr;
int g_running = 0;                // sink calls in progress, all threads
thread_local int t_running = 0;   // those of this thread (a sink that logs, or sets the sink)
std::atomic<bool> g_set{false}; // a quick "nobody listens" without the lock
} // namespace

void set_sink(Fn fn, void *user) {
    std::unique_lock<std::mutex> lock(g_mu);
    g_fn = fn;
    g_user = user;
    g_set.store(fn != nullptr);
    // The old sink's calls on other threads end before the caller may free
    // what `user` pointed to. From inside a sink call it does not wait: two
    // sinks each setting the sink would wait for each other.
    if (t_running == 0) g_idle.wait(lock, [] { return g_running == 0; });
}

void message(int level, const std::string &text) noexcept {
    if (!g_set.load(std::memory_order_relaxed)) return;
    Fn fn;
    void *user;
    {
        std::lock_guard<std::mutex> lock(g_mu);
        fn = g_fn;
        user = g_user;
        if (!fn) return;
        ++g_running;
    }
    ++t_running;
    try {
        fn(user, level, text.c_str());
    } catch (...) {
        // A message that cannot be delivered is dropped; the caller's error
        // code still says what happened.
    }
    --t_running;
    std::lock_guard<std::mutex> lock(g_mu);
    --g_running;
    g_idle.notify_all();
}

} // namespace cdm::log
