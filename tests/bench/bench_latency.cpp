// Report-to-pose latency: from a report leaving the transport's read call
// (cdm_pose.host_time_ns, taken by the reader thread right after read
// returns) to the pose being seen by
//   - two threads polling cdm_get_pose at --poll-hz (default 10 kHz): the
//     figure includes the wait for the next poll, as a polling client sees it;
//   - one thread blocked in cdm_wait_pose_after: the reader's parse, model
//     and publication plus the kernel's wake-up of a sleeping thread.
// For sim:, replay: (a recording of sim: made here) and hid: through a mock of
// hidapi (this program is linked with -Wl,--wrap=hid_*; its hid_read_timeout
// returns reports a feeder thread queues at --rate). The baselines, measured
// first in the same run by the same threads: a notifier at --rate that
// stamps a counter, publishes it in two atomics (what two pollers at
// --poll-hz see: the wait for the next poll alone) and notifies a
// std::condition_variable (what a blocked waiter sees: a wake-up alone).
//
//   bench_latency [--seconds S (10)] [--rate HZ (1000)] [--poll-hz HZ (10000)]
//                 [--transport all|sim|replay|hid]
//
// Prints median, p99, p99.9 and max in microseconds, poses a consumer
// never saw, and the device's dropped count. Built, not run by ctest.
#include <hidapi.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <cwchar>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cdm/cdm.h"
#include "device/hid/hidraw_enum.h"
#include "device/protocol.h"
#include "device/sim/firmware.h"
#include "model/model.h"

namespace {

uint64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1000000000ull + uint64_t(ts.tv_nsec);
}

void sleep_until(uint64_t t_ns) {
    timespec ts;
    ts.tv_sec = time_t(t_ns / 1000000000ull);
    ts.tv_nsec = long(t_ns % 1000000000ull);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) != 0) {}
}

struct Options {
    double seconds = 10, rate = 1000, poll_hz = 10000;
    std::string transport = "all";
};

// Latencies in ns, preallocated so that measuring allocates nothing.
struct Series {
    std::vector<uint64_t> v;
    uint64_t missed = 0; // poses published that this consumer never saw
    explicit Series(size_t cap) { v.reserve(cap); }
    void add(uint64_t ns) {
        if (v.size() < v.capacity()) v.push_back(ns);
    }
};

struct Row {
    std::string what;
    std::vector<uint64_t> v;
    uint64_t missed;
};

double pct(const std::vector<uint64_t> &s, double q) {
    if (s.empty()) return NAN;
    const size_t k = size_t(std::ceil(q * double(s.size())));
    return double(s[std::min(s.size() - 1, k ? k - 1 : 0)]) * 1e-3;
}

void print_row(Row r, double base_median_us) {
    std::sort(r.v.begin(), r.v.end());
    const double med = pct(r.v, 0.5);
    std::printf("  %-34s %8zu %8.1f %8.1f %8.1f %8.1f %7llu", r.what.c_str(), r.v.size(), med, pct(r.v, 0.99),
                pct(r.v, 0.999), r.v.empty() ? NAN : double(r.v.back()) * 1e-3, (unsigned long long)r.missed);
    if (base_median_us > 0) std::printf(" %7.1f", med / base_median_us);
    std::printf("\n");
}

void print_header() {
    std::printf("  %-34s %8s %8s %8s %8s %8s %7s %7s\n", "consumer", "poses", "median", "p99", "p99.9", "max",
                "unseen", "ratio");
    std::printf("  %-34s %8s %8s %8s %8s %8s %7s %7s\n", "", "", "us", "us", "us", "us", "", "median");
}

// Two pollers at poll_hz; `sample` returns (sequence, time the item was
// made) of the newest item, sequence 0 for none.
template <class Sample>
void poller(const Options &o, std::atomic<bool> &stop, uint64_t warm, Series &s, Sample sample) {
    const uint64_t period = uint64_t(1e9 / o.poll_hz);
    uint64_t last = 0, next = now_ns();
    while (!stop.load(std::memory_order_relaxed)) {
        uint64_t seq = 0, made = 0;
        sample(seq, made);
        const uint64_t t = now_ns();
        if (seq != last) {
            if (seq > warm) {
                if (last > warm && seq > last + 1) s.missed += seq - last - 1;
                s.add(t - made);
            }
            last = seq;
        }
        next += period;
        if (next < t) next = t + period; // fell behind (descheduled): no burst to catch up
        sleep_until(next);
    }
}

// --- baseline: a condition variable notified at the report rate ----------

std::vector<Row> run_baseline(const Options &o, size_t cap) {
    std::mutex mu;
    std::condition_variable cv;
    uint64_t seq = 0, stamp = 0;
    std::atomic<uint64_t> pub_seq{0}, pub_stamp{0};
    std::atomic<bool> stop{false};
    Series waited(cap), polled[2] = {Series(cap), Series(cap)};
    std::thread w([&] {
        uint64_t after = 0;
        std::unique_lock<std::mutex> lock(mu);
        while (!stop.load()) {
            cv.wait_for(lock, std::chrono::milliseconds(100), [&] { return seq > after || stop.load(); });
            if (seq > after) {
                const uint64_t t = now_ns();
                if (after > 100 && seq > after + 1) waited.missed += seq - after - 1;
                if (seq > 100) waited.add(t - stamp);
                after = seq;
            }
        }
    });
    // The pollers read an atomic pair (the stamp is stored first, so a pair
    // read in the other order is never newer than its stamp): the baseline
    // of the polling rows, the wait for the next poll alone.
    std::thread p[2];
    for (int i = 0; i < 2; ++i)
        p[i] = std::thread([&, i] {
            poller(o, stop, 100, polled[i], [&](uint64_t &s, uint64_t &m) {
                s = pub_seq.load();
                m = pub_stamp.load();
            });
        });
    const uint64_t period = uint64_t(1e9 / o.rate), t0 = now_ns(), end = t0 + uint64_t(o.seconds * 1e9);
    for (uint64_t k = 1;; ++k) {
        const uint64_t due = t0 + k * period;
        if (due > end) break;
        sleep_until(due);
        {
            std::lock_guard<std::mutex> lock(mu);
            stamp = now_ns();
            ++seq;
        }
        pub_stamp.store(stamp);
        pub_seq.store(seq);
        cv.notify_all();
    }
    stop.store(true);
    cv.notify_all();
    w.join();
    for (auto &t : p) t.join();
    Row polls{"atomic load, 2 pollers (baseline)", polled[0].v, polled[0].missed + polled[1].missed};
    polls.v.insert(polls.v.end(), polled[1].v.begin(), polled[1].v.end());
    return {polls, {"cv wake-up (baseline)", waited.v, waited.missed}};
}

// --- the driver ------------------------------------------------------------

struct DeviceResult {
    std::vector<Row> rows;
    cdm_stats stats{};
};

DeviceResult measure(const Options &o, const char *uri, size_t cap) {
    DeviceResult r;
    cdm_device *dev = nullptr;
    if (cdm_open(uri, &dev) != CDM_OK) {
        std::fprintf(stderr, "cannot open %s: %s\n", uri, cdm_thread_error());
        std::exit(1);
    }
    const uint64_t warm = 100; // the first 100 poses: threads start, caches warm
    std::atomic<bool> stop{false};
    Series waited(cap), polled[2] = {Series(cap), Series(cap)};
    std::thread w([&] {
        cdm_pose p{};
        p.struct_size = sizeof p;
        uint64_t after = 0;
        while (!stop.load()) {
            const int rc = cdm_wait_pose_after(dev, after, 100, &p);
            const uint64_t t = now_ns();
            if (p.host_sequence > after) {
                if (after > warm && p.host_sequence > after + 1) waited.missed += p.host_sequence - after - 1;
                if (p.host_sequence > warm) waited.add(t - p.host_time_ns);
                after = p.host_sequence;
            }
            if (rc == CDM_ERR_END_OF_STREAM) break;
        }
    });
    std::thread p[2];
    for (int i = 0; i < 2; ++i)
        p[i] = std::thread([&, i] {
            cdm_pose pose{};
            pose.struct_size = sizeof pose;
            poller(o, stop, warm, polled[i], [&](uint64_t &s, uint64_t &m) {
                cdm_get_pose(dev, &pose);
                s = pose.host_sequence;
                m = pose.host_time_ns;
            });
        });
    std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
    stop.store(true);
    w.join();
    for (auto &t : p) t.join();
    r.stats.struct_size = sizeof r.stats;
    cdm_get_stats(dev, &r.stats);
    cdm_close(dev);
    Row polls{"cdm_get_pose, 2 pollers", polled[0].v, polled[0].missed + polled[1].missed};
    polls.v.insert(polls.v.end(), polled[1].v.begin(), polled[1].v.end());
    r.rows.push_back(polls);
    r.rows.push_back({"cdm_wait_pose_after", waited.v, waited.missed});
    return r;
}

// --- replay: a recording of sim:, made here -------------------------------

struct Recording {
    cdm_recorder *rec = nullptr;
    std::atomic<uint64_t> n{0};
    uint64_t want = 0, period_ns = 0;
};

void record_sample(void *user, const cdm_sample *s) {
    auto *r = static_cast<Recording *>(user);
    const uint64_t k = r->n.load();
    if (k >= r->want) return;
    // Host times at the nominal period: the replay then paces at the rate.
    if (cdm_recorder_write(r->rec, k * r->period_ns, s->report, s->report_len) == CDM_OK) r->n.store(k + 1);
}

std::string make_recording(const Options &o) {
    // The recorder never writes over a file: a fresh directory holds it.
    char dir[] = "/tmp/cdm_bench_latency_XXXXXX";
    if (!mkdtemp(dir)) {
        std::perror("mkdtemp");
        std::exit(1);
    }
    const std::string file = std::string(dir) + "/sim.cdmrec";
    const char *path = file.c_str();
    const std::string uri = "sim:?motion=random&realtime=0&rate=" + std::to_string(o.rate);
    cdm_open_options opts{};
    opts.struct_size = sizeof opts;
    Recording rec;
    rec.want = uint64_t(o.seconds * o.rate) + uint64_t(o.rate); // a second to spare: no end of stream
    rec.period_ns = uint64_t(1e9 / o.rate);
    // The recorder must exist before the first sample: open the sim once for
    // its device-info report, then again with the callback.
    cdm_device *dev = nullptr;
    uint8_t info[256];
    size_t len = 0;
    if (cdm_open(uri.c_str(), &dev) != CDM_OK || cdm_device_info_report(dev, info, sizeof info, &len) != CDM_OK ||
        cdm_recorder_open(path, info, len, &rec.rec) != CDM_OK) {
        std::fprintf(stderr, "cannot make the recording %s: %s\n", path, cdm_thread_error());
        std::exit(1);
    }
    cdm_close(dev);
    opts.on_sample = record_sample;
    opts.user = &rec;
    if (cdm_open_ex(uri.c_str(), &opts, &dev) != CDM_OK) {
        std::fprintf(stderr, "cannot open %s: %s\n", uri.c_str(), cdm_thread_error());
        std::exit(1);
    }
    while (rec.n.load() < rec.want) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    cdm_close(dev);
    if (cdm_recorder_close(rec.rec) != CDM_OK) {
        std::fprintf(stderr, "cannot write %s: %s\n", path, cdm_thread_error());
        std::exit(1);
    }
    return file;
}

// --- hid: a mock of hidapi fed at the report rate ---------------------------

using namespace cdm::proto;

struct HidMock {
    std::mutex mu;
    std::condition_variable cv;
    static constexpr size_t kQueue = 64; // the kernel's hidraw queue
    uint8_t q[kQueue][kInputReportSize];
    size_t head = 0, count = 0;
    uint64_t overflow = 0;
    cdm::sim::Firmware *fw = nullptr;
    std::atomic<bool> opened{false}; // the feeder starts once the driver has opened the device
};
HidMock *g_hid = nullptr;
int g_token;
hid_device *fake_handle() { return reinterpret_cast<hid_device *>(&g_token); }

DeviceInfoReport mock_info(double rate) {
    DeviceInfoReport r;
    r.fw_major = 2;
    r.fw_minor = 1;
    r.fw_patch = 7;
    r.adc_bits = 16;
    std::strcpy(r.serial, "MOCK0001");
    r.report_rate_hz = float(rate);
    r.pot_scale_mm = {0.01f, 0.01f, 0.01f, 0.01f};
    r.pot_offset_mm = {0, 0, 0, 0};
    r.a_mm = 150;
    r.b_mm = 150;
    r.m_mm = 30;
    r.hall_closed = 2600;
    r.hall_open = 1400;
    r.grip_open_rad = 0.6f;
    return r;
}

// Report k: a slow circle inside the workspace.
void report_at(uint32_t k, double rate, uint8_t *out) {
    const double t = k / rate, p[3] = {50.0, 30.0 * std::cos(t), 30.0 * std::sin(t)};
    double l[4];
    cdm::nominal_lengths(cdm::DeviceGeometry{}, p, l);
    InputReport r;
    r.sequence = k;
    r.device_time_us = uint64_t(t * 1e6);
    for (int i = 0; i < 4; ++i) r.pot_adc[i] = uint16_t(std::lround(l[i] / double(0.01f)));
    r.quat_q14 = {16384, 0, 0, 0};
    r.hall_adc = 2000;
    r.status = kStatusImuOk | kStatusPotsOk | kStatusHallOk;
    serialize_input(r, out);
}

} // namespace

extern "C" {
int __wrap_hid_init(void) { return 0; }
int __wrap_cdm_hidraw_list_masters(cdm_hidraw_master_fn, void *, char *, size_t) { return 0; }
int __wrap_cdm_hidraw_node_check(const char *, char *, size_t) { return 0; }
hid_device *__wrap_hid_open_path(const char *) {
    if (!g_hid) return nullptr;
    g_hid->opened.store(true);
    return fake_handle();
}
void __wrap_hid_close(hid_device *) {}
int __wrap_hid_get_serial_number_string(hid_device *, wchar_t *s, size_t n) {
    std::wcsncpy(s, L"MOCK0001", n);
    return 0;
}
const wchar_t *__wrap_hid_error(hid_device *) { return L"mock error"; }
int __wrap_hid_read_timeout(hid_device *, unsigned char *data, size_t length, int ms) {
    std::unique_lock<std::mutex> lock(g_hid->mu);
    if (!g_hid->cv.wait_for(lock, std::chrono::milliseconds(ms), [] { return g_hid->count > 0; })) return 0;
    const size_t n = std::min(length, kInputReportSize);
    std::memcpy(data, g_hid->q[g_hid->head], n);
    g_hid->head = (g_hid->head + 1) % HidMock::kQueue;
    --g_hid->count;
    return int(n);
}
int __wrap_hid_get_feature_report(hid_device *, unsigned char *data, size_t length) {
    std::lock_guard<std::mutex> lock(g_hid->mu);
    return g_hid->fw->get_feature(data, length);
}
int __wrap_hid_send_feature_report(hid_device *, const unsigned char *data, size_t length) {
    std::lock_guard<std::mutex> lock(g_hid->mu);
    return g_hid->fw->send_feature(data, length) < 0 ? -1 : int(length);
}
} // extern "C"

namespace {

DeviceResult measure_hid(const Options &o, size_t cap) {
    HidMock mock;
    cdm::sim::Firmware fw(mock_info(o.rate));
    mock.fw = &fw;
    g_hid = &mock;
    std::atomic<bool> stop{false};
    // The feeder queues report k at k / rate, as the kernel would.
    std::thread feeder([&] {
        while (!mock.opened.load() && !stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
        const uint64_t period = uint64_t(1e9 / o.rate), t0 = now_ns();
        uint8_t r[kInputReportSize];
        for (uint32_t k = 1; !stop.load(); ++k) {
            sleep_until(t0 + k * period);
            report_at(k, o.rate, r);
            {
                std::lock_guard<std::mutex> lock(mock.mu);
                if (mock.count == HidMock::kQueue) {
                    ++mock.overflow; // the oldest is lost, as in hidraw
                    mock.head = (mock.head + 1) % HidMock::kQueue;
                    --mock.count;
                }
                std::memcpy(mock.q[(mock.head + mock.count) % HidMock::kQueue], r, sizeof r);
                ++mock.count;
            }
            mock.cv.notify_all();
        }
    });
    DeviceResult res = measure(o, "hid:/dev/hidraw7", cap);
    stop.store(true);
    feeder.join();
    g_hid = nullptr;
    if (mock.overflow) std::printf("  (mock queue overflowed %llu times)\n", (unsigned long long)mock.overflow);
    return res;
}

bool parse(int argc, char **argv, Options &o) {
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (i + 1 >= argc) return false;
        const char *v = argv[++i];
        char *end = nullptr;
        if (a == "--transport") {
            o.transport = v;
            continue;
        }
        const double x = std::strtod(v, &end);
        if (!end || *end || !(x > 0)) return false;
        if (a == "--seconds") o.seconds = x;
        else if (a == "--rate") o.rate = x;
        else if (a == "--poll-hz") o.poll_hz = x;
        else return false;
    }
    return o.transport == "all" || o.transport == "sim" || o.transport == "replay" || o.transport == "hid";
}

// Rows: the pollers (ratio to the polling baseline), then the waiter
// (ratio to the condition variable's wake-up).
void print_device(const char *name, const DeviceResult &r, const double base_us[2]) {
    std::printf("%s %llu reports, %llu dropped, %llu malformed, %llu out of order\n", name,
                (unsigned long long)r.stats.reports, (unsigned long long)r.stats.dropped,
                (unsigned long long)r.stats.malformed, (unsigned long long)r.stats.out_of_order);
    print_header();
    for (size_t i = 0; i < r.rows.size(); ++i) print_row(r.rows[i], base_us[std::min<size_t>(i, 1)]);
}

} // namespace

int main(int argc, char **argv) {
    Options o;
    if (!parse(argc, argv, o)) {
        std::fprintf(stderr,
                     "usage: %s [--seconds S (10)] [--rate HZ (1000)] [--poll-hz HZ (10000)] "
                     "[--transport all|sim|replay|hid]\n",
                     argv[0]);
        return 2;
    }
    const size_t cap = size_t(o.seconds * o.rate * 1.5) + 1000;
    std::printf("%.0f s per transport at %.0f Hz; 2 pollers at %.0f Hz and 1 waiter; latency from the report "
                "leaving the transport's read to the consumer seeing the pose\n",
                o.seconds, o.rate, o.poll_hz);
    const std::vector<Row> base = run_baseline(o, cap);
    double base_us[2];
    for (int i = 0; i < 2; ++i) {
        std::vector<uint64_t> bv = base[size_t(i)].v;
        std::sort(bv.begin(), bv.end());
        base_us[i] = pct(bv, 0.5);
    }
    std::printf("baselines (a notifier at the rate, 2 pollers, 1 waiter):\n");
    print_header();
    for (int i = 0; i < 2; ++i) print_row(base[size_t(i)], base_us[i]);
    const bool all = o.transport == "all";
    if (all || o.transport == "sim") {
        const std::string uri = "sim:?motion=random&rate=" + std::to_string(o.rate);
        print_device("sim:", measure(o, uri.c_str(), cap), base_us);
    }
    if (all || o.transport == "replay") {
        const std::string path = make_recording(o);
        const std::string uri = "replay:" + path;
        const DeviceResult r = measure(o, uri.c_str(), cap);
        std::remove(path.c_str());
        rmdir(path.substr(0, path.rfind('/')).c_str());
        print_device("replay:", r, base_us);
    }
    if (all || o.transport == "hid") print_device("hid: (hidapi mocked)", measure_hid(o, cap), base_us);
    return 0;
}
