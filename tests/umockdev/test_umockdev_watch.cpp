// Hot-plug as an event, on the emulated kernel device
// (master_testbed.h), whose unplug and replug send the kernel's uevents:
// cdm_watch's arrivals and departures, the hid: transport's wait for an
// arrival (udev's monitor), and an open handle that reconnects after a
// replug with the gap counted exactly. Runs under umockdev-wrapper.
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cdm/cdm.h"
#include "device/hotplug.h"
#include "device/transport.h"
#include "master_testbed.h"

// cmocka last: its fail() macro must not meet the C++ headers.
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

namespace {

using cdm_umock::MasterTestbed;

// Generous upper bounds for something to happen at all (a shared 2-core
// machine); they are never what a test measures.
constexpr int kEventWaitMs = 5000;

struct Seen {
    uint32_t kind;
    std::string uri, serial, firmware;
    uint32_t struct_size;
};

struct Collector {
    std::mutex mu;
    std::condition_variable cv;
    std::vector<Seen> events;
    std::thread::id thread;

    static void cb(void *user, const cdm_watch_event *e) {
        auto *c = static_cast<Collector *>(user);
        std::lock_guard<std::mutex> lock(c->mu);
        c->thread = std::this_thread::get_id();
        c->events.push_back({e->kind, e->info->uri, e->info->serial, e->info->firmware, e->struct_size});
        if (std::getenv("WATCH_DEBUG"))
            std::fprintf(stderr, "event %u %s %s fw %s\n", e->kind, e->info->uri, e->info->serial, e->info->firmware);
        c->cv.notify_all();
    }
    // Waits until `n` events have come; returns whether they did.
    bool wait_count(size_t n) {
        std::unique_lock<std::mutex> lock(mu);
        return cv.wait_for(lock, std::chrono::milliseconds(kEventWaitMs), [&] { return events.size() >= n; });
    }
    size_t count() {
        std::lock_guard<std::mutex> lock(mu);
        return events.size();
    }
    Seen at(size_t i) {
        std::lock_guard<std::mutex> lock(mu);
        return events.at(i);
    }
};

void expect_master(const Seen &s, uint32_t kind) {
    assert_int_equal(s.kind, kind);
    assert_string_equal(s.uri.c_str(), "hid:/dev/hidraw0");
    assert_string_equal(s.serial.c_str(), "UMOCK0001");
    // Full info: the watcher read the info report from the arrived node.
    assert_string_equal(s.firmware.c_str(), "1.0.0");
    assert_int_equal(s.struct_size, sizeof(cdm_watch_event));
}

// With CDM_WATCH_ENUMERATE the master already there arrives first; the
// unplug is a departure, the replug an arrival, each exactly once (the
// replug sends four uevents: one arrival, not four).
void test_watch_arrival_departure(void **) {
    MasterTestbed tb;
    Collector c;
    cdm_watcher *w = nullptr;
    assert_int_equal(cdm_watch(CDM_WATCH_ENUMERATE, Collector::cb, &c, &w), CDM_OK);
    assert_true(c.wait_count(1));
    expect_master(c.at(0), CDM_WATCH_ARRIVED);
    assert_true(c.thread != std::this_thread::get_id()); // the watcher's own thread
    tb.unplug();
    assert_true(c.wait_count(2));
    expect_master(c.at(1), CDM_WATCH_LEFT);
    tb.plug();
    assert_true(c.wait_count(3));
    expect_master(c.at(2), CDM_WATCH_ARRIVED);
    // Anything extra would have come with the same batch of uevents; a
    // second unplug/replug cycle pushes a late duplicate, if any, in front
    // of its own events, where the kinds below would catch it.
    tb.unplug();
    tb.plug();
    assert_true(c.wait_count(5));
    cdm_watch_free(w);
    assert_int_equal(c.count(), 5);
    expect_master(c.at(3), CDM_WATCH_LEFT);
    expect_master(c.at(4), CDM_WATCH_ARRIVED);
}

// Without CDM_WATCH_ENUMERATE only changes are told; a watcher freed
// tells nothing more.
void test_watch_changes_only(void **) {
    MasterTestbed tb;
    tb.unplug();
    Collector c;
    cdm_watcher *w = nullptr;
    assert_int_equal(cdm_watch(0, Collector::cb, &c, &w), CDM_OK);
    tb.plug();
    assert_true(c.wait_count(1));
    expect_master(c.at(0), CDM_WATCH_ARRIVED);
    cdm_watch_free(w);
    tb.unplug();
    tb.plug();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    assert_int_equal(c.count(), 1);
}

void test_watch_bad_arguments(void **) {
    cdm_watcher *w = reinterpret_cast<cdm_watcher *>(1);
    assert_int_equal(cdm_watch(0, nullptr, nullptr, &w), CDM_ERR_INVALID_ARG);
    assert_null(w);
    assert_non_null(std::strstr(cdm_thread_error(), "fn is NULL"));
    assert_int_equal(cdm_watch(0, Collector::cb, nullptr, nullptr), CDM_ERR_INVALID_ARG);
    assert_int_equal(cdm_watch(0x80, Collector::cb, nullptr, &w), CDM_ERR_INVALID_ARG);
    assert_non_null(std::strstr(cdm_thread_error(), "unknown flags 0x80"));
    cdm_watch_free(nullptr);
}

// cdm_watch_free from the watcher's own callback would join its own
// thread: refused, and the watcher goes on.
struct SelfFree {
    cdm_watcher *w = nullptr;
    Collector c;
};
void self_free_cb(void *user, const cdm_watch_event *e) {
    auto *s = static_cast<SelfFree *>(user);
    cdm_watch_free(s->w); // must return at once
    Collector::cb(&s->c, e);
}
void test_watch_free_from_callback_refused(void **) {
    MasterTestbed tb;
    SelfFree s;
    assert_int_equal(cdm_watch(CDM_WATCH_ENUMERATE, self_free_cb, &s, &s.w), CDM_OK);
    assert_true(s.c.wait_count(1));
    tb.unplug();
    assert_true(s.c.wait_count(2)); // still watching
    cdm_watch_free(s.w);
}

// The hid: transport, disconnected, waits for udev's event: wait_arrival
// returns true on the replug's uevents (false would mean it slept its
// timeout out: no event reached it).
void test_transport_wakes_on_arrival(void **) {
    MasterTestbed tb;
    cdm::Uri u;
    std::string err;
    assert_int_equal(cdm::parse_uri("hid:/dev/hidraw0", u, err), CDM_OK);
    cdm::TransportPtr t;
    assert_int_equal(cdm::find_transport("hid")->open(u, t, err), CDM_OK);
    uint8_t buf[64];
    assert_true(t->read(buf, sizeof buf, 1000, err) > 0);
    tb.unplug();
    int n = 0;
    for (int i = 0; i < 100 && n >= 0; ++i) n = t->read(buf, sizeof buf, 100, err);
    assert_int_equal(n, cdm::kReadDisconnected);
    // Nothing arrives while unplugged: the wait runs out.
    assert_false(t->wait_arrival(200));
    bool woke = false;
    std::thread waiter([&] { woke = t->wait_arrival(kEventWaitMs); });
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    tb.plug();
    waiter.join();
    assert_true(woke);
    assert_int_equal(t->reopen(err), CDM_OK);
    assert_true(t->read(buf, sizeof buf, 1000, err) > 0);
}

// An open handle across an unplug and a replug: DISCONNECTED, then
// RECONNECTED, streaming again, and every report the master sent while the
// cable was out (the testbed's master keeps sampling, as a self-powered
// one does) counted as dropped: the counter equals the sequence gap.
struct Track {
    std::mutex mu;
    std::vector<int64_t> seqs; // sequence numbers, -1 where an event fell
    std::vector<uint32_t> events;
};
void track_sample(void *user, const cdm_sample *s) {
    auto *t = static_cast<Track *>(user);
    std::lock_guard<std::mutex> lock(t->mu);
    t->seqs.push_back(s->pose->sequence);
}
void track_event(void *user, const cdm_event *e) {
    // Only the connection's edges: a STALE/FRESH pair, should the loaded
    // machine delay the reader, is no part of what is checked here.
    if (e->kind != CDM_EVENT_DISCONNECTED && e->kind != CDM_EVENT_RECONNECTED) return;
    auto *t = static_cast<Track *>(user);
    std::lock_guard<std::mutex> lock(t->mu);
    t->events.push_back(e->kind);
    t->seqs.push_back(-1);
}

void test_replug_reconnects_gap_counted(void **) {
    MasterTestbed tb;
    Track tr;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = track_sample;
    o.on_event = track_event;
    o.user = &tr;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex("hid:/dev/hidraw0", &o, &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_int_equal(cdm_wait_pose(dev, kEventWaitMs, &p), CDM_OK);
    tb.unplug();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    tb.plug();
    cdm_stats st{};
    st.struct_size = sizeof st;
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(kEventWaitMs);
    while (std::chrono::steady_clock::now() < end) {
        assert_int_equal(cdm_get_stats(dev, &st), CDM_OK);
        if (st.reconnects >= 1) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    assert_int_equal(st.reconnects, 1);
    // Two poses after the reconnection: the first one carries the gap.
    const uint64_t after = st.reports;
    for (uint64_t k = 0; k < 2; ++k) {
        cdm_pose q{};
        q.struct_size = sizeof q;
        assert_int_equal(cdm_wait_pose_after(dev, after + k, kEventWaitMs, &q), CDM_OK);
    }
    assert_int_equal(cdm_get_stats(dev, &st), CDM_OK);
    cdm_close(dev); // joins the reader: tr is ours alone from here

    assert_int_equal(tr.events.size(), 2);
    assert_int_equal(tr.events[0], CDM_EVENT_DISCONNECTED);
    assert_int_equal(tr.events[1], CDM_EVENT_RECONNECTED);
    // While streaming every step is 1 (nothing dropped); across the
    // events, the step minus one is what the driver must have counted.
    int64_t before = -1, gap = -1;
    bool marked = false;
    for (int64_t s : tr.seqs) {
        if (s < 0) {
            marked = true;
            continue;
        }
        if (before >= 0) {
            if (marked) {
                assert_int_equal(gap, -1); // one unplug, one gap
                gap = s - before - 1;
            } else {
                assert_int_equal(s, before + 1);
            }
        }
        marked = false;
        before = s;
    }
    print_message("gap across the replug: %lld reports; dropped counter %llu\n", (long long)gap,
                  (unsigned long long)st.dropped);
    // 300 ms unplugged at 250 Hz: about 75 reports; at least one.
    assert_true(gap > 0);
    assert_int_equal(st.dropped, uint64_t(gap));
}

} // namespace

int main() {
    if (!cdm_umock::in_mock_environment()) {
        std::fprintf(stderr, "run me through umockdev-wrapper\n");
        return 1;
    }
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_watch_bad_arguments),
        cmocka_unit_test(test_watch_arrival_departure),
        cmocka_unit_test(test_watch_changes_only),
        cmocka_unit_test(test_watch_free_from_callback_refused),
        cmocka_unit_test(test_transport_wakes_on_arrival),
        cmocka_unit_test(test_replug_reconnects_gap_counted),
    };
    if (const char *f = std::getenv("CMOCKA_TEST_FILTER")) cmocka_set_test_filter(f); // one test, by glob
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
