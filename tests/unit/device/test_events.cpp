// Device events (cdm_open_options.on_event) and the log hook
// (cdm_set_log_fn), both since 1.1, through the public API on sim: faults.
#include <atomic>
#include <chrono>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cdm/cdm.h"
#include "test_util.h"

extern "C" {
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>

#include <cmocka.h>
}

namespace {

struct Seen {
    std::mutex mu;
    std::vector<std::pair<uint32_t, std::string>> events;
    std::vector<std::pair<int, std::string>> logs;
    bool has(uint32_t kind) {
        std::lock_guard<std::mutex> lock(mu);
        for (auto &e : events)
            if (e.first == kind) return true;
        return false;
    }
};

void on_event(void *user, const cdm_event *e) {
    auto *s = static_cast<Seen *>(user);
    assert_true(e->struct_size >= sizeof(cdm_event) && e->text != nullptr && e->host_time_ns > 0);
    std::lock_guard<std::mutex> lock(s->mu);
    s->events.emplace_back(e->kind, e->text);
}

void on_log(void *user, int level, const char *msg) {
    auto *s = static_cast<Seen *>(user);
    std::lock_guard<std::mutex> lock(s->mu);
    s->logs.emplace_back(level, msg);
}

cdm_device *open_with_events(const char *uri, Seen &s) {
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &s;
    o.on_event = on_event;
    cdm_device *dev = nullptr;
    if (cdm_open_ex(uri, &o, &dev) != CDM_OK) fail_msg("open %s: %s", uri, cdm_thread_error());
    return dev;
}

// A stall: STALE once within the stale timeout (50 ms) + the reader's poll
// (50 ms) + scheduling; here 1 s is the outer bound of the wait, not a
// timing claim.
void test_stall_raises_stale_once(void **) {
    Seen s;
    cdm_device *dev = open_with_events("sim:?stall_after=30", s);
    assert_true(cdm_test::wait_until([&] { return s.has(CDM_EVENT_STALE); }, 1000));
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    cdm_close(dev);
    int stale = 0;
    for (auto &e : s.events) stale += e.first == CDM_EVENT_STALE;
    assert_int_equal(stale, 1); // an edge, not a level
}

// Unplug at report 100 for 200 ms: DISCONNECTED, then RECONNECTED, in that order.
void test_unplug_and_replug(void **) {
    Seen s;
    cdm_device *dev = open_with_events("sim:?disconnect=100:200", s);
    assert_true(cdm_test::wait_until([&] { return s.has(CDM_EVENT_RECONNECTED); }, 3000));
    cdm_close(dev);
    size_t d = s.events.size(), r = s.events.size();
    for (size_t i = 0; i < s.events.size(); ++i) {
        if (s.events[i].first == CDM_EVENT_DISCONNECTED && d == s.events.size()) d = i;
        if (s.events[i].first == CDM_EVENT_RECONNECTED && r == s.events.size()) r = i;
    }
    assert_true(d < r);
}

// The log: a failing call's detail at DEBUG; a malformed report at WARNING
// (logged at the 1st, 10th, 100th... only); NULL removes the hook.
void test_log_hook(void **) {
    Seen s;
    cdm_set_log_fn(on_log, &s);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("nosuch:", &dev), CDM_ERR_NO_DEVICE);
    {
        std::lock_guard<std::mutex> lock(s.mu);
        assert_false(s.logs.empty());
        assert_int_equal(s.logs.back().first, CDM_LOG_DEBUG);
        assert_non_null(std::strstr(s.logs.back().second.c_str(), "nosuch"));
    }
    dev = open_with_events("sim:?malformed=short:20", s);
    assert_true(cdm_test::wait_until(
        [&] {
            std::lock_guard<std::mutex> lock(s.mu);
            for (auto &l : s.logs)
                if (l.first == CDM_LOG_WARNING && l.second.find("rejected") != std::string::npos) return true;
            return false;
        },
        2000));
    cdm_close(dev);
    cdm_set_log_fn(nullptr, nullptr);
    const size_t n = s.logs.size();
    assert_int_equal(cdm_open("nosuch:", &dev), CDM_ERR_NO_DEVICE);
    assert_int_equal(s.logs.size(), n);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_stall_raises_stale_once),
        cmocka_unit_test(test_unplug_and_replug),
        cmocka_unit_test(test_log_hook),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
