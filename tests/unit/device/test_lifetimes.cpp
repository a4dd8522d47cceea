// Handle lifetimes against re-entrancy: cdm_close from the device's own
// callbacks and from the log sink, a close or cdm_shutdown while other
// threads wait, and what a callback may call (docs/reliability.md,
// "Callbacks"). Through the public API on sim:.
#include <dirent.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
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

// Threads of this process: a freed handle has no reader thread left.
int thread_count() {
    int n = 0;
    if (DIR *d = opendir("/proc/self/task")) {
        while (dirent *e = readdir(d)) n += e->d_name[0] != '.';
        closedir(d);
    }
    return n;
}

// Runs `f` on a thread and fails the test (without hanging the suite) when
// it has not returned within `ms`: a deadlock is a failure, not a timeout of
// the whole program.
template <class F>
void returns_within(F f, int ms, const char *what) {
    std::atomic<bool> done{false};
    std::thread t([&] {
        f();
        done.store(true);
    });
    if (!cdm_test::wait_until([&] { return done.load(); }, ms)) {
        std::fprintf(stderr, "%s: still blocked after %d ms (deadlock)\n", what, ms);
        std::_Exit(1);
    }
    t.join();
}

struct Closer {
    std::atomic<cdm_device *> dev{nullptr};
    std::atomic<int> closes{0};     // callbacks that called cdm_close
    std::atomic<int> after{0};      // callbacks that started after the close
    std::string text;               // cdm_thread_error after the deferred close
};

// The first callback closes the device (when `close` holds); any callback
// after that close is counted in `after`.
void close_once(Closer *c, bool close = true) {
    cdm_device *d = c->dev.load();
    if (!d) return;
    if (c->closes.load() > 0) {
        c->after.fetch_add(1);
        return;
    }
    if (!close) return;
    cdm_close(d);
    c->text = cdm_thread_error();
    c->closes.fetch_add(1);
}

void close_in_sample(void *user, const cdm_sample *) { close_once(static_cast<Closer *>(user)); }

void close_in_event(void *user, const cdm_event *e) {
    close_once(static_cast<Closer *>(user), e->kind == CDM_EVENT_STALE);
}

// Closes on the first rejected report (a malformed one, then several more
// that must reach no callback).
void close_in_rejected(void *user, const cdm_rejected *) { close_once(static_cast<Closer *>(user)); }

// The reader thread is gone (the handle freed) once the thread count is
// back to what it was before the open.
void expect_reader_gone(int before) {
    assert_true(cdm_test::wait_until([&] { return thread_count() == before; }, 3000));
}

// cdm_close from on_sample: deferred, no abort (a self-join threw
// std::system_error out of the destructor), no callback after it, and the
// reader thread frees the handle.
void test_close_from_on_sample_is_deferred(void **) {
    const int before = thread_count();
    Closer c;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &c;
    o.on_sample = close_in_sample;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("sim:?rate=1000", &o, &dev), CDM_OK);
    c.dev.store(dev);
    assert_true(cdm_test::wait_until([&] { return c.closes.load() == 1; }, 3000));
    expect_reader_gone(before);
    assert_int_equal(c.after.load(), 0);
    assert_non_null(std::strstr(c.text.c_str(), "cdm_close: deferred"));
}

// cdm_close from on_rejected (since 1.2): the same, and neither a
// rejected report nor a sample reaches a callback after it.
void test_close_from_on_rejected_is_deferred(void **) {
    const int before = thread_count();
    Closer c;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &c;
    o.on_rejected = close_in_rejected;
    o.on_sample = [](void *user, const cdm_sample *) {
        auto *cl = static_cast<Closer *>(user);
        if (cl->closes.load() > 0) cl->after.fetch_add(1);
    };
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("sim:?rate=1000&malformed=short:200,version:201,short:202&duplicate=210", &o, &dev),
                     CDM_OK);
    c.dev.store(dev);
    assert_true(cdm_test::wait_until([&] { return c.closes.load() == 1; }, 3000));
    expect_reader_gone(before);
    assert_int_equal(c.after.load(), 0);
    assert_non_null(std::strstr(c.text.c_str(), "cdm_close: deferred"));
}

// cdm_close from on_event (STALE of a stalled device): the same.
void test_close_from_on_event_is_deferred(void **) {
    const int before = thread_count();
    Closer c;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &c;
    o.on_event = close_in_event;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("sim:?rate=1000&stall_after=20", &o, &dev), CDM_OK);
    c.dev.store(dev);
    assert_true(cdm_test::wait_until([&] { return c.closes.load() == 1; }, 3000));
    expect_reader_gone(before);
    assert_int_equal(c.after.load(), 0);
    assert_non_null(std::strstr(c.text.c_str(), "cdm_close: deferred"));
}

struct SinkCloser {
    std::atomic<cdm_device *> dev{nullptr};
    std::atomic<int> closes{0};
    std::atomic<bool> reader_logged{false};
    std::atomic<bool> hold{false}; // the main thread's sink call waits for a reader message
};

// The log sink closes the device when the reader thread reports a rejected
// report: cdm_close on the reader thread, inside the sink.
void sink_close_on_reject(void *user, int, const char *msg) {
    auto *s = static_cast<SinkCloser *>(user);
    cdm_device *d = s->dev.load();
    if (d && std::strstr(msg, "rejected") && s->closes.fetch_add(1) == 0) cdm_close(d);
}

void test_close_from_log_sink_on_reader_thread(void **) {
    const int before = thread_count();
    SinkCloser s;
    cdm_set_log_fn(sink_close_on_reject, &s);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?rate=1000&malformed=short:50", &dev), CDM_OK);
    s.dev.store(dev);
    assert_true(cdm_test::wait_until([&] { return s.closes.load() >= 1; }, 3000));
    expect_reader_gone(before);
    cdm_set_log_fn(nullptr, nullptr);
}

// The deadlock: a sink running on the caller's thread (a failing
// call's debug message) calls cdm_close while the device's reader thread
// logs at the same time. With the log mutex held during the sink, the close
// waited for the reader, and the reader for the mutex.
void sink_close_while_reader_logs(void *user, int, const char *msg) {
    auto *s = static_cast<SinkCloser *>(user);
    if (std::strstr(msg, "reconnect failed")) {
        s->reader_logged.store(true);
        return;
    }
    if (!std::strstr(msg, "nosuch") || !s->hold.exchange(false)) return;
    // The disconnected reader logs a failed reconnection every 250 ms:
    // wait until it has logged while this sink call runs, then close.
    s->reader_logged.store(false);
    cdm_test::wait_until([&] { return s->reader_logged.load(); }, 2000);
    cdm_close(s->dev.exchange(nullptr));
    s->closes.fetch_add(1);
}

void test_close_from_log_sink_while_reader_logs(void **) {
    SinkCloser s;
    cdm_set_log_fn(sink_close_while_reader_logs, &s);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?rate=1000&disconnect=5:600000", &dev), CDM_OK);
    s.dev.store(dev);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_DISCONNECTED; }, 3000));
    s.hold.store(true);
    returns_within(
        [] {
            cdm_device *none = nullptr;
            cdm_open("nosuch:", &none); // fails: its debug message runs the sink on this thread
        },
        5000, "cdm_close from the log sink while the reader logs");
    assert_int_equal(s.closes.load(), 1);
    assert_true(s.reader_logged.load());
    cdm_set_log_fn(nullptr, nullptr);
}

// Threads blocked in cdm_wait_pose / cdm_wait_pose_after without a timeout
// on a stalled device: cdm_close wakes them with CDM_ERR_CLOSED and no pose
// (never the last pose of a freed handle), and returns once they have left.
void test_close_wakes_blocked_waiters_with_closed(void **) {
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?rate=1000&stall_after=10", &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_STALE; }, 3000));
    constexpr int kThreads = 4;
    std::atomic<int> entered{0};
    int rc[kThreads];
    cdm_pose out[kThreads];
    std::vector<std::thread> ts;
    for (int i = 0; i < kThreads; ++i) {
        ts.emplace_back([&, i] {
            out[i] = cdm_pose{};
            out[i].struct_size = sizeof(cdm_pose);
            entered.fetch_add(1);
            rc[i] = (i % 2) ? cdm_wait_pose(dev, -1, &out[i])
                            : cdm_wait_pose_after(dev, p.host_sequence, -1, &out[i]);
        });
    }
    assert_true(cdm_test::wait_until([&] { return entered.load() == kThreads; }, 3000));
    // Entering the call is not being asleep in it: the close must hold
    // either way, so no sleep here is needed for the assertion's truth.
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    returns_within([&] { cdm_close(dev); }, 5000, "cdm_close with blocked waiters");
    for (auto &t : ts) t.join();
    for (int i = 0; i < kThreads; ++i) {
        assert_int_equal(rc[i], CDM_ERR_CLOSED);
        assert_int_equal(out[i].host_sequence, 0);
        assert_true(out[i].position[0] == 0 && out[i].position[1] == 0 && out[i].position[2] == 0);
        assert_true(out[i].orientation[0] == 1.0);
    }
}

// cdm_shutdown: the waiters wake with CDM_ERR_CLOSED, later waits return it
// at once, and the handle stays valid (cdm_get_pose works) until cdm_close.
void test_shutdown_wakes_waiters_handle_stays_valid(void **) {
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?rate=1000&stall_after=10", &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_STALE; }, 3000));
    int rc = 0;
    std::thread t([&] {
        cdm_pose q{};
        q.struct_size = sizeof q;
        rc = cdm_wait_pose_after(dev, p.host_sequence, -1, &q);
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    assert_int_equal(cdm_shutdown(dev), CDM_OK);
    returns_within([&] { t.join(); }, 5000, "waiter after cdm_shutdown");
    assert_int_equal(rc, CDM_ERR_CLOSED);
    cdm_pose q{};
    q.struct_size = sizeof q;
    assert_int_equal(cdm_wait_pose(dev, 1000, &q), CDM_ERR_CLOSED);
    assert_non_null(std::strstr(cdm_thread_error(), "closed"));
    assert_int_equal(cdm_get_pose(dev, &q), CDM_ERR_STALE); // still the last pose
    assert_int_equal(q.host_sequence, p.host_sequence);
    assert_int_equal(cdm_shutdown(dev), CDM_OK); // idempotent
    assert_int_equal(cdm_shutdown(nullptr), CDM_ERR_INVALID_ARG);
    cdm_close(dev);
}

// What a sample callback may call on its own device: every non-blocking
// call succeeds there (the table's "may call" column).
struct Caller {
    std::atomic<cdm_device *> dev{nullptr};
    std::atomic<int> done{0};
    int rc_pose = 1, rc_raw = 1, rc_info = 1, rc_stats = 1, rc_err = 1, rc_cal = 1, rc_stale = 1;
};

void call_everything(void *user, const cdm_sample *) {
    auto *c = static_cast<Caller *>(user);
    cdm_device *d = c->dev.load();
    if (!d || c->done.load()) return;
    cdm_pose p{};
    p.struct_size = sizeof p;
    c->rc_pose = cdm_get_pose(d, &p);
    cdm_raw r{};
    r.struct_size = sizeof r;
    c->rc_raw = cdm_get_raw(d, &r);
    cdm_device_info i{};
    i.struct_size = sizeof i;
    c->rc_info = cdm_get_info(d, &i);
    cdm_stats s{};
    s.struct_size = sizeof s;
    c->rc_stats = cdm_get_stats(d, &s);
    char buf[64];
    c->rc_err = cdm_device_error(d, buf, sizeof buf);
    c->rc_cal = cdm_set_calibration(d, nullptr);
    c->rc_stale = cdm_set_stale_timeout(d, 0);
    c->done.store(1);
}

void test_callback_may_call_its_device(void **) {
    Caller c;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &c;
    o.on_sample = call_everything;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("sim:?rate=1000", &o, &dev), CDM_OK);
    c.dev.store(dev);
    assert_true(cdm_test::wait_until([&] { return c.done.load() == 1; }, 3000));
    cdm_close(dev);
    assert_int_equal(c.rc_pose, CDM_OK);
    assert_int_equal(c.rc_raw, CDM_OK);
    assert_int_equal(c.rc_info, CDM_OK);
    assert_int_equal(c.rc_stats, CDM_OK);
    assert_int_equal(c.rc_err, CDM_OK);
    assert_int_equal(c.rc_cal, CDM_OK);
    assert_int_equal(c.rc_stale, CDM_OK);
}

// cdm_shutdown from the device's own callback, then cdm_close from the
// owner's thread: both fine.
void shutdown_in_sample(void *user, const cdm_sample *) {
    auto *c = static_cast<Caller *>(user);
    cdm_device *d = c->dev.load();
    if (!d || c->done.load()) return;
    c->rc_pose = cdm_shutdown(d);
    c->done.store(1);
}

void test_shutdown_from_callback(void **) {
    Caller c;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.user = &c;
    o.on_sample = shutdown_in_sample;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("sim:?rate=1000", &o, &dev), CDM_OK);
    c.dev.store(dev);
    assert_true(cdm_test::wait_until([&] { return c.done.load() == 1; }, 3000));
    assert_int_equal(c.rc_pose, CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_int_equal(cdm_wait_pose(dev, 1000, &p), CDM_ERR_CLOSED);
    cdm_close(dev);
}

} // namespace

int main(void) {
    // ThreadSanitizer's runtime starts a background thread of its own at the
    // first pthread_create and keeps it: start one thread before any test
    // takes its thread count, so the count measures the library's threads.
    std::thread([] {}).join();
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_close_from_on_sample_is_deferred),
        cmocka_unit_test(test_close_from_on_rejected_is_deferred),
        cmocka_unit_test(test_close_from_on_event_is_deferred),
        cmocka_unit_test(test_close_from_log_sink_on_reader_thread),
        cmocka_unit_test(test_close_from_log_sink_while_reader_logs),
        cmocka_unit_test(test_close_wakes_blocked_waiters_with_closed),
        cmocka_unit_test(test_shutdown_wakes_waiters_handle_stays_valid),
        cmocka_unit_test(test_callback_may_call_its_device),
        cmocka_unit_test(test_shutdown_from_callback),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
