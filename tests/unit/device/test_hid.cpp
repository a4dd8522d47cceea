// The hidapi transport against a mock of hid_* (linked with
// -Wl,--wrap=hid_...): open by path and by serial, reads, timeouts,
// malformed reports, sequence gaps, feature reports (through the emulated
// firmware, the same one the sim uses), out-of-workspace lengths, and an
// unplug / replug with the same serial on another hidraw node.
//
// The mock keeps its own mutex-guarded state rather than cmocka's
// will_return queues: hid_read_timeout runs on the driver's reader thread,
// and cmocka's queues are not thread-safe.
#include <hidapi.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <cwchar>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cdm/cdm.h"
#include "device/hid/hidraw_enum.h"
#include "device/protocol.h"
#include "device/sim/firmware.h"
#include "model/model.h"
#include "test_util.h"

// cmocka last: its fail() macro must not meet the C++ headers.
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

using namespace cdm::proto;

namespace {

struct Mock {
    std::mutex mu;
    std::condition_variable cv;
    bool plugged = true;
    std::string path = "/dev/hidraw7";
    std::wstring serial = L"MOCK0001";
    std::deque<std::vector<uint8_t>> reports;
    std::unique_ptr<cdm::sim::Firmware> fw;
    int opens = 0, closes = 0, open_handles = 0;
    bool feature_fail = false;
};
Mock *g_mock = nullptr;
// Handles a test opened. A failing assertion jumps out of the test; the
// teardown then closes what is left, so that no reader thread outlives the
// mock it reads from (and a failure fails, rather than hangs).
std::vector<cdm_device *> g_open;
int g_token; // the address is the fake hid_device*
hid_device *fake_handle() { return reinterpret_cast<hid_device *>(&g_token); }

DeviceInfoReport mock_info() {
    DeviceInfoReport r;
    r.fw_major = 2;
    r.fw_minor = 1;
    r.fw_patch = 7;
    r.adc_bits = 16;
    std::strcpy(r.serial, "MOCK0001");
    r.report_rate_hz = 1000;
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

} // namespace

extern "C" {

int __wrap_hid_init(void) { return 0; }

// The enumeration (device/hid/hidraw_enum.h, libudev in the library): the mock's
// one master while it is plugged in, with bcdDevice 2.1.
int __wrap_cdm_hidraw_list_masters(cdm_hidraw_master_fn fn, void *ctx, char *, size_t) {
    std::string path, serial;
    {
        std::lock_guard<std::mutex> lock(g_mock->mu);
        if (!g_mock->plugged) return 0;
        path = g_mock->path;
        serial.assign(g_mock->serial.begin(), g_mock->serial.end()); // ASCII
    }
    fn(ctx, path.c_str(), serial.c_str(), 0x0201);
    return 0;
}

// The mock's /dev/hidraw7 does not exist: the node check (tested on real
// paths in test_hid_paths.cpp) is bypassed and hid_open_path decides.
int __wrap_cdm_hidraw_node_check(const char *, char *, size_t) { return 0; }

// The node's own name, or another name for it (a symlink to the plain file
// the symlink test uses as the node), as the kernel would open it.
bool names_the_node(const std::string &node, const char *path) {
    if (node == path) return true;
    struct stat a {}, b {};
    return ::stat(path, &a) == 0 && ::stat(node.c_str(), &b) == 0 && a.st_dev == b.st_dev && a.st_ino == b.st_ino;
}

hid_device *__wrap_hid_open_path(const char *path) {
    std::lock_guard<std::mutex> lock(g_mock->mu);
    if (!g_mock->plugged || !names_the_node(g_mock->path, path)) return nullptr;
    ++g_mock->opens;
    ++g_mock->open_handles;
    return fake_handle();
}

void __wrap_hid_close(hid_device *d) {
    assert_ptr_equal(d, fake_handle());
    std::lock_guard<std::mutex> lock(g_mock->mu);
    ++g_mock->closes;
    --g_mock->open_handles;
}

int __wrap_hid_get_serial_number_string(hid_device *, wchar_t *s, size_t n) {
    std::lock_guard<std::mutex> lock(g_mock->mu);
    std::wcsncpy(s, g_mock->serial.c_str(), n);
    return 0;
}

const wchar_t *__wrap_hid_error(hid_device *) { return L"mock error"; }

int __wrap_hid_read_timeout(hid_device *d, unsigned char *data, size_t length, int ms) {
    assert_ptr_equal(d, fake_handle());
    std::unique_lock<std::mutex> lock(g_mock->mu);
    g_mock->cv.wait_for(lock, std::chrono::milliseconds(ms),
                        [] { return !g_mock->plugged || !g_mock->reports.empty(); });
    if (!g_mock->plugged) return -1; // hidraw after an unplug: ENODEV
    if (g_mock->reports.empty()) return 0;
    std::vector<uint8_t> r = g_mock->reports.front();
    g_mock->reports.pop_front();
    const size_t n = std::min(length, r.size());
    std::memcpy(data, r.data(), n);
    return int(n);
}

int __wrap_hid_get_feature_report(hid_device *, unsigned char *data, size_t length) {
    std::lock_guard<std::mutex> lock(g_mock->mu);
    if (!g_mock->plugged || g_mock->feature_fail) return -1;
    return g_mock->fw->get_feature(data, length);
}

int __wrap_hid_send_feature_report(hid_device *, const unsigned char *data, size_t length) {
    std::lock_guard<std::mutex> lock(g_mock->mu);
    if (!g_mock->plugged || g_mock->feature_fail) return -1;
    return g_mock->fw->send_feature(data, length) < 0 ? -1 : int(length);
}

} // extern "C"

namespace {

std::vector<uint8_t> report_at(uint32_t seq, const double p[3], uint16_t buttons = 0,
                               uint64_t device_time_us = ~uint64_t(0)) {
    cdm::DeviceGeometry g;
    double l[4];
    cdm::nominal_lengths(g, p, l);
    InputReport r;
    r.sequence = seq;
    r.device_time_us = device_time_us == ~uint64_t(0) ? uint64_t(seq) * 1000 : device_time_us;
    for (int i = 0; i < 4; ++i) r.pot_adc[i] = uint16_t(std::lround(l[i] / double(0.01f)));
    r.quat_q14 = {16384, 0, 0, 0};
    r.hall_adc = 2000; // halfway: grip 0.3 rad
    r.buttons = buttons;
    r.status = kStatusImuOk | kStatusPotsOk | kStatusHallOk;
    std::vector<uint8_t> b(kInputReportSize);
    serialize_input(r, b.data());
    return b;
}

void push(std::vector<uint8_t> r) {
    std::lock_guard<std::mutex> lock(g_mock->mu);
    g_mock->reports.push_back(std::move(r));
    g_mock->cv.notify_all();
}

void set_plugged(bool on, const char *path = nullptr) {
    std::lock_guard<std::mutex> lock(g_mock->mu);
    g_mock->plugged = on;
    if (path) g_mock->path = path;
    g_mock->cv.notify_all();
}

int setup(void **) {
    g_mock = new Mock;
    g_mock->fw = std::make_unique<cdm::sim::Firmware>(mock_info());
    return 0;
}

int teardown(void **) {
    const bool leaked = !g_open.empty();
    for (cdm_device *d : g_open) cdm_close(d);
    g_open.clear();
    assert_false(leaked);
    assert_int_equal(g_mock->open_handles, 0); // every hid handle closed
    delete g_mock;
    g_mock = nullptr;
    return 0;
}

cdm_device *open_ok(const char *uri) {
    cdm_device *dev = nullptr;
    const int rc = cdm_open(uri, &dev);
    if (rc != CDM_OK) fail_msg("cdm_open(%s): %s: %s", uri, cdm_strerror(rc), cdm_thread_error());
    g_open.push_back(dev);
    return dev;
}

void close_dev(cdm_device *dev) {
    g_open.erase(std::remove(g_open.begin(), g_open.end(), dev), g_open.end());
    cdm_close(dev);
}

cdm_stats stats(cdm_device *dev) {
    cdm_stats s{};
    s.struct_size = sizeof s;
    assert_int_equal(cdm_get_stats(dev, &s), CDM_OK);
    return s;
}

void test_open_read_timeout(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    cdm_device_info info{};
    info.struct_size = sizeof info;
    assert_int_equal(cdm_get_info(dev, &info), CDM_OK);
    assert_string_equal(info.transport, "hid");
    assert_string_equal(info.serial, "MOCK0001");
    assert_string_equal(info.firmware, "2.1.7");
    assert_string_equal(info.uri, "serial:MOCK0001");
    cdm_pose p{};
    p.struct_size = sizeof p;
    // Nothing read yet: NO_DATA, zeroed; waiting times out.
    assert_int_equal(cdm_get_pose(dev, &p), CDM_ERR_NO_DATA);
    assert_int_equal(p.sequence, 0);
    assert_int_equal(cdm_wait_pose(dev, 100, &p), CDM_ERR_NO_DATA);
    const double at[3] = {45.0, 12.0, -20.0};
    push(report_at(100, at, CDM_BUTTON_CLUTCH));
    // Wait for that report itself: cdm_wait_pose waits for one newer than
    // the newest at its call, which may already be this one (a race the
    // slower sanitizer builds lose).
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 100; }, 2000));
    assert_int_equal(p.sequence, 100);
    assert_int_equal(p.buttons, CDM_BUTTON_CLUTCH);
    // Only the ADC's rounding separates the pose from `at`: half a count,
    // 0.005 mm per cable, amplified < 10 times in x near this point.
    for (int k = 0; k < 3; ++k) assert_true(std::fabs(p.position[k] - at[k]) < 0.05);
    assert_true(std::fabs(p.orientation[0] - 1.0) < 1e-12);
    assert_true(std::fabs(p.grip - 0.3) < 1e-7); // grip_open_rad is the float32 0.6f
    assert_true(p.device_time_us == 100000);
    // A timeout of the transport is no error: the pose stays, newer never comes.
    assert_int_equal(cdm_wait_pose(dev, 100, &p), CDM_ERR_TIMEOUT);
    assert_int_equal(p.sequence, 100);
    // A sequence gap counts as dropped reports.
    push(report_at(105, at));
    // Wait for that report itself: cdm_wait_pose waits for one newer than
    // the newest at its call, which may already be this one (a race the
    // slower sanitizer builds lose).
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 105; }, 2000));
    assert_int_equal(p.dropped, 4);
    assert_int_equal(stats(dev).dropped, 4);
    // Wrap-around of the 32-bit counter is no gap.
    push(report_at(0xFFFFFFFFu, at));
    push(report_at(0, at));
    assert_true(cdm_test::wait_until([&] { cdm_get_pose(dev, &p); return p.sequence == 0; }, 2000));
    // 105 -> 0xFFFFFFFF is a (huge, backward-looking) jump: it is taken as
    // a counter reset, not as 4 billion lost reports.
    assert_true(stats(dev).dropped < 1000);
    close_dev(dev);
}

void test_malformed_counted(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {50, 0, 0};
    struct Case {
        std::vector<uint8_t> bytes;
        const char *text;
    };
    std::vector<Case> cases;
    auto r = report_at(1, at);
    cases.push_back({std::vector<uint8_t>(r.begin(), r.begin() + 20), "short report"});
    auto b = r;
    b[0] = 0x05;
    cases.push_back({b, "wrong report ID"});
    b = r;
    b[1] = 7;
    cases.push_back({b, "wrong protocol version"});
    b = r;
    std::memset(b.data() + 24, 0, 8);
    cases.push_back({b, "all-zero quaternion"});
    b = r;
    put_u16(b.data() + 26, 16384); // w = x = 1: norm sqrt(2)
    cases.push_back({b, "norm far from 1"});
    uint64_t n = 0;
    for (const Case &c : cases) {
        push(c.bytes);
        ++n;
        assert_true(cdm_test::wait_until([&] { return stats(dev).malformed == n; }, 2000));
        char text[256];
        assert_int_equal(cdm_device_error(dev, text, sizeof text), CDM_OK);
        if (!std::strstr(text, c.text)) fail_msg("device error \"%s\" does not say \"%s\"", text, c.text);
    }
    // The reader is still alive and well.
    push(report_at(2, at));
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 2; }, 2000));
    assert_int_equal(stats(dev).reports, 1);
    // Truncated error text is still terminated.
    char tiny[5];
    cdm_device_error(dev, tiny, sizeof tiny);
    assert_int_equal(std::strlen(tiny), 4);
    close_dev(dev);
}

void test_out_of_workspace(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {40, 5, 5};
    push(report_at(1, at));
    cdm_pose p{};
    p.struct_size = sizeof p;
    // Wait for that report itself: cdm_wait_pose waits for one newer than
    // the newest at its call, which may already be this one (a race the
    // slower sanitizer builds lose).
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 1; }, 2000));
    const double x = p.position[0];
    // Cables far too short for the frame: the spheres do not meet.
    auto r = report_at(2, at);
    for (int i = 0; i < 4; ++i) put_u16(r.data() + 16 + 2 * i, 100);
    push(r);
    assert_true(cdm_test::wait_until([&] { cdm_get_pose(dev, &p); return p.sequence == 2; }, 2000));
    assert_true(p.flags & CDM_POSE_OUT_OF_WORKSPACE);
    assert_true(std::isfinite(p.position[0]) && p.position[0] == x);
    assert_int_equal(stats(dev).out_of_workspace, 1);
    push(report_at(3, at));
    assert_true(cdm_test::wait_until([&] { cdm_get_pose(dev, &p); return p.sequence == 3; }, 2000));
    assert_false(p.flags & CDM_POSE_OUT_OF_WORKSPACE);
    close_dev(dev);
}

// Waits until the reader has taken `n` reports in all (published, rejected
// or discarded as out of order).
void settle(cdm_device *dev, uint64_t n) {
    assert_true(cdm_test::wait_until(
        [&] {
            const cdm_stats s = stats(dev);
            return s.reports + s.malformed + s.out_of_order >= n;
        },
        2000));
}

// Before the first solvable report there is no position to hold: not
// (0,0,0) passed off as one.
void test_oow_before_first_pose_has_no_position(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {40, 5, 5};
    auto r = report_at(1, at);
    for (int i = 0; i < 4; ++i) put_u16(r.data() + 16 + 2 * i, 100);
    push(r);
    settle(dev, 1);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_int_equal(cdm_get_pose(dev, &p), CDM_ERR_NO_DATA);
    assert_true(p.flags & CDM_POSE_OUT_OF_WORKSPACE);
    assert_true(p.flags & CDM_POSE_NO_POSITION);
    assert_int_equal(p.host_sequence, 1);
    const double qn = p.orientation[0] * p.orientation[0] + p.orientation[1] * p.orientation[1] +
                      p.orientation[2] * p.orientation[2] + p.orientation[3] * p.orientation[3];
    assert_true(std::fabs(qn - 1) < 1e-12); // a unit quaternion, from the report
    push(report_at(2, at));
    settle(dev, 2);
    assert_int_equal(cdm_get_pose(dev, &p), CDM_OK);
    assert_false(p.flags & (CDM_POSE_NO_POSITION | CDM_POSE_OUT_OF_WORKSPACE));
    // Out of the workspace again: now the last good position is held.
    r = report_at(3, at);
    for (int i = 0; i < 4; ++i) put_u16(r.data() + 16 + 2 * i, 100);
    push(r);
    settle(dev, 3);
    const int rc = cdm_get_pose(dev, &p);
    assert_true(rc == CDM_OK || rc == CDM_ERR_STALE);
    assert_true(p.flags & CDM_POSE_OUT_OF_WORKSPACE);
    assert_false(p.flags & CDM_POSE_NO_POSITION);
    close_dev(dev);
}

// Before any report, the pose's orientation is the identity, not zero.
void test_no_report_orientation_is_identity(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_int_equal(cdm_get_pose(dev, &p), CDM_ERR_NO_DATA);
    assert_true(p.orientation[0] == 1.0 && p.orientation[1] == 0 && p.orientation[2] == 0 && p.orientation[3] == 0);
    close_dev(dev);
}

// One flipped bit of the sequence number, or a counter reset, would add 4e9
// or 3e8 to dropped as a gap. The flip is two jumps (there and back), the
// reset a restart, and dropped stays honest.
void test_sequence_flipped_bit_not_counted_as_dropped(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {40, 5, 5};
    const uint32_t seqs[] = {1000, 1001, 1002 | (1u << 30), 1003, 1004};
    uint64_t n = 0;
    for (uint32_t q : seqs) {
        push(report_at(q, at));
        settle(dev, ++n);
    }
    cdm_stats s = stats(dev);
    assert_int_equal(s.dropped, 0);
    assert_int_equal(s.sequence_jumps, 2); // there and back
    assert_int_equal(s.restarts, 0);
    // The device restarts its counter (no unplug): a restart, not a jump;
    // its report 0 never arrived.
    push(report_at(1, at));
    settle(dev, ++n);
    push(report_at(2, at));
    settle(dev, ++n);
    s = stats(dev);
    assert_int_equal(s.restarts, 1);
    assert_int_equal(s.dropped, 1);
    assert_int_equal(s.sequence_jumps, 2);
    // A real gap of 3 reports is still counted as 3 dropped (within the bound
    // of 2 x rate x elapsed + 64).
    push(report_at(6, at));
    settle(dev, ++n);
    assert_int_equal(stats(dev).dropped, 4);
    assert_int_equal(stats(dev).sequence_jumps, 2);
    // A backward step to a number the device could not have counted to
    // from 0 since the last report (past the bound) is a jump, not a restart.
    push(report_at(3, at));
    settle(dev, ++n);
    assert_int_equal(stats(dev).out_of_order, 1); // within 64 behind: late
    push(report_at(1000000, at));
    settle(dev, ++n);
    push(report_at(500000, at));
    settle(dev, ++n);
    s = stats(dev);
    assert_int_equal(s.sequence_jumps, 4);
    assert_int_equal(s.restarts, 1);
    cdm_pose p{};
    p.struct_size = sizeof p;
    cdm_get_pose(dev, &p);
    assert_int_equal(p.dropped, 4);
    close_dev(dev);
}

// Counter and sample time as the device sent them, one report at a time;
// returns the counters once the reader has taken it.
struct Feed {
    cdm_device *dev;
    uint64_t n = 0;
    cdm_stats operator()(uint32_t seq, uint64_t device_us) {
        const double at[3] = {40, 5, 5};
        push(report_at(seq, at, 0, device_us));
        settle(dev, ++n);
        return stats(dev);
    }
};

// A restart is a step back to a number the device could have counted to
// from 0; what only looks like one is told apart (docs/protocol.md,
// "Sequence numbers"). Each case on a fresh handle, at 1 ms per report.
void test_sequence_restart_told_from_look_alikes(void **) {
    {   // Restart from a counter past 2^31 (24.8 days at 1 kHz): a restart, not a jump.
        cdm_device *dev = open_ok("hid:/dev/hidraw7");
        Feed f{dev};
        f(3000000000u, 5000000);
        f(3000000001u, 5001000);
        const cdm_stats s = f(0, 5002000);
        assert_int_equal(s.restarts, 1);
        assert_int_equal(s.sequence_jumps, 0);
        close_dev(dev);
    }
    {   // A flipped bit that lowers the counter (41 -> 9), then back: two jumps, nothing lost.
        cdm_device *dev = open_ok("hid:/dev/hidraw7");
        Feed f{dev};
        for (uint32_t k = 30; k <= 40; ++k) f(k, k * 1000);
        f(41 ^ 32, 41000);
        const cdm_stats s = f(42, 42000);
        assert_int_equal(s.restarts, 0);
        assert_int_equal(s.sequence_jumps, 2);
        assert_int_equal(s.dropped, 0);
        close_dev(dev);
    }
    {   // Two reports in a row with bit 16 flipped (65557 -> 21, 65558 -> 22), then back.
        cdm_device *dev = open_ok("hid:/dev/hidraw7");
        Feed f{dev};
        f(65555, 100000);
        f(65556, 101000);
        f(65557 ^ 65536, 102000);
        f(65558 ^ 65536, 103000);
        const cdm_stats s = f(65559, 104000);
        assert_int_equal(s.restarts, 0);
        assert_int_equal(s.sequence_jumps, 2);
        assert_int_equal(s.dropped, 0);
        close_dev(dev);
    }
    {   // A report of the old count arriving late, after the restart: discarded, not a second restart.
        cdm_device *dev = open_ok("hid:/dev/hidraw7");
        Feed f{dev};
        f(18, 18000);
        f(19, 19000);
        f(0, 21000); // report 21 restarted the count; report 20 is late
        const cdm_stats s = f(20, 20000);
        assert_int_equal(s.restarts, 1);
        assert_int_equal(s.out_of_order, 1);
        assert_int_equal(s.sequence_jumps, 0);
        close_dev(dev);
    }
    {   // A restart that also restarts the device clock, 200 reports in: not taken for late reports.
        cdm_device *dev = open_ok("hid:/dev/hidraw7");
        Feed f{dev};
        for (uint32_t k = 180; k <= 200; ++k) f(k, k * 1000);
        f(0, 300);
        const cdm_stats s = f(1, 1300);
        assert_int_equal(s.restarts, 1);
        assert_int_equal(s.out_of_order, 0);
        assert_int_equal(s.reports, 23);
        close_dev(dev);
    }
}

// A duplicated report and a late one are discarded (an older sample must
// not replace a newer one) and counted in out_of_order.
void test_sequence_duplicate_and_reordered_discarded(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {40, 5, 5};
    const uint32_t seqs[] = {1, 2, 2, 4, 3, 5};
    uint64_t n = 0;
    for (uint32_t q : seqs) {
        push(report_at(q, at));
        settle(dev, ++n);
    }
    const cdm_stats s = stats(dev);
    assert_int_equal(s.out_of_order, 2);
    assert_int_equal(s.reports, 4);
    assert_int_equal(s.dropped, 1); // 3 was missing when 4 came; it came late
    assert_int_equal(s.sequence_jumps, 0);
    cdm_pose p{};
    p.struct_size = sizeof p;
    cdm_get_pose(dev, &p);
    assert_int_equal(p.sequence, 5);
    assert_int_equal(p.host_sequence, 4);
    close_dev(dev);
}

// cdm_wait_pose_after returns at once when a newer pose already exists, so
// a consumer that was busy between two calls loses no wake-up.
void test_wait_pose_after_no_lost_wakeup(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {40, 5, 5};
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_int_equal(cdm_wait_pose_after(dev, 0, 0, &p), CDM_ERR_TIMEOUT);
    push(report_at(1, at));
    assert_int_equal(cdm_wait_pose_after(dev, 0, 2000, &p), CDM_OK);
    assert_int_equal(p.host_sequence, 1);
    // Published while nobody waited: the next call must not sleep.
    push(report_at(2, at));
    settle(dev, 2);
    const auto t0 = std::chrono::steady_clock::now();
    assert_int_equal(cdm_wait_pose_after(dev, 1, 5000, &p), CDM_OK);
    assert_true(std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(500));
    assert_int_equal(p.host_sequence, 2);
    assert_int_equal(cdm_wait_pose_after(dev, 2, 50, &p), CDM_ERR_TIMEOUT);
    assert_int_equal(p.host_sequence, 2);
    // A 1.0-sized struct cannot see host_sequence: refused.
    p.struct_size = 104;
    assert_int_equal(cdm_wait_pose_after(dev, 2, 0, &p), CDM_ERR_INVALID_ARG);
    close_dev(dev);
}

// A device info with a pot offset of 3e38 gave poses of x = 3e38 mm.
void test_device_info_insane_values_refused(void **) {
    struct Case {
        const char *field;
        void (*spoil)(DeviceInfoReport &);
    } cases[] = {
        {"pot_offset_mm[0]", [](DeviceInfoReport &r) { r.pot_offset_mm[0] = 3e38f; }},
        {"pot_scale_mm[1]", [](DeviceInfoReport &r) { r.pot_scale_mm[1] = 0; }},
        {"pot_scale_mm[2]", [](DeviceInfoReport &r) { r.pot_scale_mm[2] = -0.01f; }},
        {"pot_scale_mm[3]", [](DeviceInfoReport &r) { r.pot_scale_mm[3] = std::nanf(""); }},
        {"a_mm", [](DeviceInfoReport &r) { r.a_mm = 1e30f; }},
        {"m_mm", [](DeviceInfoReport &r) { r.m_mm = 0.001f; }},
        {"report_rate_hz", [](DeviceInfoReport &r) { r.report_rate_hz = 1e9f; }},
    };
    for (const Case &c : cases) {
        DeviceInfoReport info = mock_info();
        c.spoil(info);
        g_mock->fw = std::make_unique<cdm::sim::Firmware>(info);
        cdm_device *dev = nullptr;
        assert_int_equal(cdm_open("hid:/dev/hidraw7", &dev), CDM_ERR_PROTOCOL);
        assert_null(dev);
        if (!std::strstr(cdm_thread_error(), c.field))
            fail_msg("\"%s\" does not name %s", cdm_thread_error(), c.field);
        assert_non_null(std::strstr(cdm_thread_error(), "outside"));
    }
}

void test_feature_reports(void **) {
    cdm_device *dev = open_ok("serial:MOCK0001");
    const char blob[] = "{\"format\":\"cdm-calibration\",\"version\":1} and some more bytes to span two chunks "
                        "of fifty-eight bytes each, at least";
    assert_int_equal(cdm_device_calibration_write(dev, blob, sizeof blob), CDM_OK);
    char buf[512];
    size_t len = 0;
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_OK);
    assert_int_equal(len, sizeof blob);
    assert_memory_equal(buf, blob, sizeof blob);
    // A flipped bit in the device's store: the host's CRC check catches it.
    g_mock->fw->corrupt_store(70);
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_ERR_CRC);
    assert_non_null(std::strstr(cdm_thread_error(), "CRC"));
    // The transport failing (a STALL) is an I/O error naming the report.
    g_mock->feature_fail = true;
    assert_int_equal(cdm_device_calibration_write(dev, blob, sizeof blob), CDM_ERR_IO);
    assert_non_null(std::strstr(cdm_thread_error(), "0x03"));
    g_mock->feature_fail = false;
    close_dev(dev);
    // Opening needs the device-info report.
    g_mock->feature_fail = true;
    cdm_device *d2 = nullptr;
    assert_int_equal(cdm_open("hid:/dev/hidraw7", &d2), CDM_ERR_IO);
    assert_non_null(std::strstr(cdm_thread_error(), "0x02"));
    g_mock->feature_fail = false;
    // Unknown serial.
    assert_int_equal(cdm_open("hid:serial=OTHER", &d2), CDM_ERR_NO_DEVICE);
    assert_non_null(std::strstr(cdm_thread_error(), "OTHER"));
}

void test_enumerate(void **) {
    cdm_device_list *list = nullptr;
    assert_int_equal(cdm_enumerate(&list), CDM_OK);
    assert_int_equal(cdm_device_list_count(list), 1);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    assert_int_equal(cdm_device_list_get(list, 0, &info), CDM_OK);
    assert_string_equal(info.uri, "hid:/dev/hidraw7");
    assert_string_equal(info.serial, "MOCK0001");
    assert_string_equal(info.firmware, "2.1.7"); // from the device-info report, not bcdDevice
    assert_int_equal(cdm_device_list_get(list, 1, &info), CDM_ERR_INVALID_ARG);
    cdm_device_list_free(list);
    cdm_device_list_free(nullptr);
    // NULL URI, no $CDM_DEVICE: the first device found.
    unsetenv("CDM_DEVICE");
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open(nullptr, &dev), CDM_OK);
    cdm_close(dev);
    set_plugged(false);
    assert_int_equal(cdm_enumerate(&list), CDM_OK);
    assert_int_equal(cdm_device_list_count(list), 0);
    cdm_device_list_free(list);
}

// Another name for the master's node (a udev rule's SYMLINK+=): the handle
// opens that name and knows the master's serial, so it reconnects by serial
// like a handle opened by the node's own name, not only by the link's path.
// The mock's node is
// a plain file here (the node check is bypassed; file identity is what the
// library compares).
void test_open_through_a_link(void **) {
    char dir[] = "/tmp/cdm-hid-link-XXXXXX";
    assert_non_null(mkdtemp(dir));
    const std::string node = std::string(dir) + "/hidraw7", link = std::string(dir) + "/cdm-master";
    FILE *f = std::fopen(node.c_str(), "w");
    assert_non_null(f);
    std::fclose(f);
    assert_int_equal(symlink(node.c_str(), link.c_str()), 0);
    set_plugged(true, node.c_str());
    cdm_device *dev = open_ok(("hid:" + link).c_str());
    cdm_device_info info{};
    info.struct_size = sizeof info;
    assert_int_equal(cdm_get_info(dev, &info), CDM_OK);
    assert_string_equal(info.uri, "serial:MOCK0001");
    close_dev(dev);
    // A link to something that is not an enumerated master is opened by
    // its own path (and here refused: the mock's hid_open_path knows only
    // the node and its names).
    const std::string other = std::string(dir) + "/other", other_link = std::string(dir) + "/other-link";
    f = std::fopen(other.c_str(), "w");
    assert_non_null(f);
    std::fclose(f);
    assert_int_equal(symlink(other.c_str(), other_link.c_str()), 0);
    cdm_device *none = nullptr;
    assert_int_equal(cdm_open(("hid:" + other_link).c_str(), &none), CDM_ERR_NO_DEVICE);
    assert_null(none);
    for (const std::string &p : {link, node, other_link, other}) std::remove(p.c_str());
    rmdir(dir);
    // An empty serial is the same mistake in both spellings (hid:serial= was
    // taken for a path "serial=").
    for (const char *uri : {"serial:", "hid:serial="}) {
        assert_int_equal(cdm_open(uri, &none), CDM_ERR_INVALID_ARG);
        assert_non_null(std::strstr(cdm_thread_error(), "empty serial number"));
    }
}

void test_unplug_replug(void **) {
    cdm_device *dev = open_ok("hid:/dev/hidraw7");
    const double at[3] = {50, -10, 10};
    push(report_at(10, at));
    cdm_pose p{};
    p.struct_size = sizeof p;
    // Wait for that report itself: cdm_wait_pose waits for one newer than
    // the newest at its call, which may already be this one (a race the
    // slower sanitizer builds lose).
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 10; }, 2000));
    // Unplug: hid_read_timeout returns -1.
    set_plugged(false);
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_DISCONNECTED; }, 2000));
    assert_true(p.flags & CDM_POSE_DISCONNECTED);
    assert_int_equal(p.sequence, 10); // the last pose, held
    assert_true(std::fabs(p.position[1] + 10) < 0.05);
    cdm_raw raw{};
    raw.struct_size = sizeof raw;
    assert_int_equal(cdm_get_raw(dev, &raw), CDM_ERR_DISCONNECTED);
    char text[256];
    cdm_device_error(dev, text, sizeof text);
    assert_non_null(std::strstr(text, "serial:MOCK0001")); // names the device that went away
    // Feature requests while unplugged fail cleanly.
    size_t len;
    char buf[16];
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_ERR_DISCONNECTED);
    // Still gone after several retry intervals: no reconnect counted.
    std::this_thread::sleep_for(std::chrono::milliseconds(600));
    assert_int_equal(stats(dev).reconnects, 0);
    // Plugged back in, with the same serial, on another node.
    set_plugged(true, "/dev/hidraw9");
    assert_true(cdm_test::wait_until([&] { return stats(dev).reconnects == 1; }, 2000));
    // The device kept counting while unplugged... (a hub glitch, not a
    // power cycle): the gap shows in `dropped`.
    push(report_at(20, at));
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 20; }, 2000));
    assert_false(p.flags & CDM_POSE_DISCONNECTED);
    assert_int_equal(p.dropped, 9);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    cdm_get_info(dev, &info);
    assert_string_equal(info.uri, "serial:MOCK0001");
    // ...or restarted from 0 after a power cycle: the gap is estimated from
    // the host time and the nominal rate, so it is at least the 300 ms spent
    // unplugged at 1 kHz (minus the slack of the retry interval).
    set_plugged(false);
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_DISCONNECTED; }, 2000));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    set_plugged(true);
    assert_true(cdm_test::wait_until([&] { return stats(dev).reconnects == 2; }, 2000));
    push(report_at(0, at));
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence == 0; }, 2000));
    assert_true(p.dropped >= 9 + 250);
    close_dev(dev);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_open_read_timeout, setup, teardown),
        cmocka_unit_test_setup_teardown(test_malformed_counted, setup, teardown),
        cmocka_unit_test_setup_teardown(test_out_of_workspace, setup, teardown),
        cmocka_unit_test_setup_teardown(test_feature_reports, setup, teardown),
        cmocka_unit_test_setup_teardown(test_oow_before_first_pose_has_no_position, setup, teardown),
        cmocka_unit_test_setup_teardown(test_no_report_orientation_is_identity, setup, teardown),
        cmocka_unit_test_setup_teardown(test_sequence_flipped_bit_not_counted_as_dropped, setup, teardown),
        cmocka_unit_test_setup_teardown(test_sequence_restart_told_from_look_alikes, setup, teardown),
        cmocka_unit_test_setup_teardown(test_sequence_duplicate_and_reordered_discarded, setup, teardown),
        cmocka_unit_test_setup_teardown(test_wait_pose_after_no_lost_wakeup, setup, teardown),
        cmocka_unit_test_setup_teardown(test_device_info_insane_values_refused, setup, teardown),
        cmocka_unit_test_setup_teardown(test_enumerate, setup, teardown),
        cmocka_unit_test_setup_teardown(test_unplug_replug, setup, teardown),
        cmocka_unit_test_setup_teardown(test_open_through_a_link, setup, teardown),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
