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

// A callback that waits on its own device (the header allows any cdm_*
// call but cdm_close there) would wait for a pose only its own thread can
// publish: until the timeout, or, without one, until cdm_close. It is
// refused at once, not left to block.
struct OwnWait {
    std::atomic<cdm_device *> dev{nullptr};
    std::atomic<int> calls{0}, rc{0};
    std::atomic<long> ms{-1};
    std::string text;
};

void wait_in_callback(void *user, const cdm_sample *) {
    auto *w = static_cast<OwnWait *>(user);
    cdm_device *dev = w->dev.load();
    if (!dev || w->calls.fetch_add(1) != 0) return;
    cdm_pose p{};
    p.struct_size = sizeof p;
    const auto t0 = std::chrono::steady_clock::now();
    w->rc = cdm_wait_pose_after(dev, 0xFFFFFFFFull, -1, &p); // no limit: only a refusal returns
    w->ms = long(std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0).count());
    w->text = cdm_thread_error();
}

void test_wait_from_own_callback_refused(void **) {
    OwnWait w;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &w;
    o.on_sample = wait_in_callback;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("sim:?rate=200", &o, &dev), CDM_OK);
    w.dev = dev;
    assert_true(cdm_test::wait_until([&] { return w.ms.load() >= 0; }, 3000));
    cdm_close(dev);
    assert_int_equal(w.rc.load(), CDM_ERR_INVALID_ARG);
    assert_true(w.ms.load() < 100); // at once, not after a wait
    assert_non_null(std::strstr(w.text.c_str(), "reader thread"));
}

// A failing cdm_get_pose / cdm_get_raw says why in cdm_thread_error, and a
// succeeding one leaves it empty: never an earlier call's text (e.g.
// "cdm_get_pose: ... cannot open the calibration" from a failed load).
void test_pose_calls_own_their_thread_error(void **) {
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?saturate=0:1000000", &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_NO_DATA && p.flags != 0; }, 2000));
    cdm_device *none = nullptr;
    assert_int_equal(cdm_open("nosuch:", &none), CDM_ERR_NO_DEVICE); // an unrelated failure's text
    assert_int_equal(cdm_get_pose(dev, &p), CDM_ERR_NO_DATA);
    assert_non_null(std::strstr(cdm_thread_error(), "cdm_get_pose: no position yet"));
    cdm_raw r{};
    r.struct_size = sizeof r;
    assert_int_equal(cdm_get_raw(dev, &r), CDM_ERR_NO_DATA);
    assert_non_null(std::strstr(cdm_thread_error(), "cdm_get_raw: no position yet"));
    p.struct_size = 4;
    assert_int_equal(cdm_get_pose(dev, &p), CDM_ERR_INVALID_ARG);
    assert_non_null(std::strstr(cdm_thread_error(), "struct_size"));
    cdm_close(dev);
    assert_int_equal(cdm_open("sim:", &dev), CDM_OK);
    p.struct_size = sizeof p;
    assert_int_equal(cdm_open("nosuch:", &none), CDM_ERR_NO_DEVICE);
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK; }, 2000));
    assert_string_equal(cdm_thread_error(), "");
    cdm_close(dev);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_stall_raises_stale_once),
        cmocka_unit_test(test_unplug_and_replug),
        cmocka_unit_test(test_log_hook),
        cmocka_unit_test(test_wait_from_own_callback_refused),
        cmocka_unit_test(test_pose_calls_own_their_thread_error),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
