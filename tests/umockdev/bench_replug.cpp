// bench_replug [CYCLES]: how soon an open hid: handle streams again after
// the emulated master is plugged back, waking on udev's hot-plug event
// against the retry poll alone (cdm::set_hotplug_events(false): the
// reader's 250-ms reconnection tick, what the driver did before). Run
// through umockdev-wrapper; docs/performance.md reports the numbers as a
// ratio. Not a ctest: timings on a shared machine are not pass/fail.
//
// Each cycle: stream, unplug, stay unplugged 200 ms + U(0, 250) ms (the
// uniform part puts the replug at every phase of the poll's tick; a fixed
// gap would measure one phase only), plug, and time from just before
// plug() to (a) the RECONNECTED event and (b) the first report handed over
// after it. The two modes alternate cycle by cycle, so that the machine's
// load falls on both alike. BENCH_LOG=1 prints libcdm's messages (every
// failed reconnection attempt) with the times of the plugs.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cdm/cdm.h"
#include "device/device.h"
#include "device/hotplug.h"
#include "master_testbed.h"

namespace {

struct Probe {
    std::atomic<uint64_t> reconnected_ns{0}, first_ns{0};
};

void on_event(void *user, const cdm_event *e) {
    auto *p = static_cast<Probe *>(user);
    if (e->kind == CDM_EVENT_RECONNECTED) p->reconnected_ns.store(e->host_time_ns);
}

void on_sample(void *user, const cdm_sample *s) {
    auto *p = static_cast<Probe *>(user);
    if (p->reconnected_ns.load() != 0 && p->first_ns.load() == 0) p->first_ns.store(s->raw->host_time_ns);
}

struct Series {
    std::vector<double> reconnect_ms, stream_ms;
};

double pct(std::vector<double> v, double q) {
    std::sort(v.begin(), v.end());
    const size_t i = std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5));
    return v[i];
}
double mean(const std::vector<double> &v) {
    double s = 0;
    for (double x : v) s += x;
    return s / double(v.size());
}

void print_row(const char *name, const std::vector<double> &v) {
    std::printf("  %-34s n %2zu  median %7.1f  mean %7.1f  p90 %7.1f  max %7.1f ms\n", name, v.size(),
                pct(v, 0.5), mean(v), pct(v, 0.9), pct(v, 1.0));
}

void on_log(void *, int level, const char *m) {
    if (std::getenv("BENCH_LOG"))
        std::fprintf(stderr, "%.3f [%d] %s\n", double(cdm::monotonic_ns() % 100000000000ull) * 1e-6, level, m);
}

} // namespace

int main(int argc, char **argv) {
    if (!cdm_umock::in_mock_environment()) {
        std::fprintf(stderr, "run me through umockdev-wrapper\n");
        return 1;
    }
    const int cycles = argc > 1 ? std::atoi(argv[1]) : 20;
    if (cycles < 2) {
        std::fprintf(stderr, "usage: bench_replug [CYCLES >= 2 per mode]\n");
        return 2;
    }
    cdm_set_log_fn(on_log, nullptr);
    cdm_umock::MasterTestbed tb;
    Probe probe;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_event = on_event;
    o.on_sample = on_sample;
    o.user = &probe;
    cdm_device *dev = nullptr;
    if (cdm_open_ex("hid:/dev/hidraw0", &o, &dev) != CDM_OK) {
        std::fprintf(stderr, "cdm_open: %s\n", cdm_thread_error());
        return 1;
    }
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> phase(0.0, double(cdm::kReconnectIntervalMs));
    Series s[2]; // 0: event, 1: poll only
    std::vector<double> plug_call_ms;
    for (int i = 0; i < 2 * cycles; ++i) {
        const int mode = i % 2;
        cdm::set_hotplug_events(mode == 0);
        cdm_pose p{};
        p.struct_size = sizeof p;
        cdm_stats st{};
        st.struct_size = sizeof st;
        cdm_get_stats(dev, &st);
        if (cdm_wait_pose_after(dev, st.reports, 5000, &p) != CDM_OK) {
            std::fprintf(stderr, "cycle %d: not streaming before the unplug\n", i);
            return 1;
        }
        tb.unplug();
        // Wait for the reader to see the unplug, then the random gap.
        const auto seen = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (cdm_get_pose(dev, &p) != CDM_ERR_DISCONNECTED && std::chrono::steady_clock::now() < seen)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        std::this_thread::sleep_for(std::chrono::microseconds(long(1000 * (200.0 + phase(rng)))));
        probe.reconnected_ns = 0;
        probe.first_ns = 0;
        const uint64_t t0 = cdm::monotonic_ns();
        if (std::getenv("BENCH_LOG")) std::fprintf(stderr, "%.3f plug (%s)\n", double(t0 % 100000000000ull) * 1e-6, mode ? "poll" : "event");
        tb.plug();
        plug_call_ms.push_back(double(cdm::monotonic_ns() - t0) * 1e-6);
        const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (probe.first_ns == 0 && std::chrono::steady_clock::now() < end)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        if (probe.first_ns == 0) {
            std::fprintf(stderr, "cycle %d (%s): no report within 5 s of the replug\n", i, mode ? "poll" : "event");
            return 1;
        }
        s[mode].reconnect_ms.push_back(double(probe.reconnected_ns - t0) * 1e-6);
        s[mode].stream_ms.push_back(double(probe.first_ns - t0) * 1e-6);
    }
    cdm_stats st{};
    st.struct_size = sizeof st;
    cdm_get_stats(dev, &st);
    cdm_close(dev);

    std::printf("replug to streaming, %d cycles per mode, report rate 250 Hz, retry poll %d ms\n", cycles,
                cdm::kReconnectIntervalMs);
    std::printf("(from just before the testbed's plug(), which itself took median %.1f ms: sysfs tree and uevents)\n",
                pct(plug_call_ms, 0.5));
    std::printf("udev event (hotplug.cpp):\n");
    print_row("plug -> RECONNECTED", s[0].reconnect_ms);
    print_row("plug -> first report", s[0].stream_ms);
    std::printf("retry poll only (before):\n");
    print_row("plug -> RECONNECTED", s[1].reconnect_ms);
    print_row("plug -> first report", s[1].stream_ms);
    std::printf("ratio poll/event, plug -> first report: median %.1f, mean %.1f, max %.1f\n",
                pct(s[1].stream_ms, 0.5) / pct(s[0].stream_ms, 0.5), mean(s[1].stream_ms) / mean(s[0].stream_ms),
                pct(s[1].stream_ms, 1.0) / pct(s[0].stream_ms, 1.0));
    std::printf("handle: %llu reconnects, %llu reports, %llu dropped (the gaps), %llu malformed\n",
                (unsigned long long)st.reconnects, (unsigned long long)st.reports, (unsigned long long)st.dropped,
                (unsigned long long)st.malformed);
    return 0;
}
