// The hid: transport against the REAL libhidapi-hidraw and libudev, on an
// emulated kernel device (master_testbed.h): enumeration (filtered and not),
// open, streaming checked against the simulator's truth, the info report,
// the calibration store, unplug and replug, and nodes that only claim to be
// a master. Runs under umockdev-wrapper (ctest does that).
#include <hidapi.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <cwchar>
#include <string>
#include <thread>

#include "cdm/cdm.h"
#include "device/protocol.h"
#include "master_testbed.h"
#include "model/model.h"

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
using cdm_umock::NodeMode;
using cdm_umock::TestbedOptions;

template <class P>
bool wait_until(P pred, int timeout_ms) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < end) {
        if (pred()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return pred();
}

cdm_pose new_pose() {
    cdm_pose p{};
    p.struct_size = sizeof p;
    return p;
}

int count_hid(unsigned short vid, unsigned short pid, std::wstring *serial = nullptr, std::wstring *product = nullptr) {
    hid_device_info *l = hid_enumerate(vid, pid);
    int n = 0;
    for (hid_device_info *d = l; d; d = d->next) {
        if (d->vendor_id != cdm::proto::kVendorId || d->product_id != cdm::proto::kProductId) continue;
        ++n;
        if (serial && d->serial_number) *serial = d->serial_number;
        if (product && d->product_string) *product = d->product_string;
    }
    hid_free_enumeration(l);
    return n;
}

// hidapi itself, unfiltered and filtered: both must see the master, with
// the USB device's strings.
void test_hidapi_enumerates(void **) {
    MasterTestbed tb;
    assert_int_equal(hid_init(), 0);
    std::wstring serial, product;
    assert_int_equal(count_hid(0, 0, &serial, &product), 1);
    assert_true(serial == L"UMOCK0001");
    assert_true(product == L"cdm haptic master");
    assert_int_equal(count_hid(cdm::proto::kVendorId, cdm::proto::kProductId), 1);
    assert_int_equal(count_hid(cdm::proto::kVendorId, 0), 1);
    assert_int_equal(count_hid(0x1234, 0x5678), 0);
}

void test_cdm_enumerate(void **) {
    MasterTestbed tb;
    cdm_device_list *list = nullptr;
    assert_int_equal(cdm_enumerate(&list), CDM_OK);
    bool found = false;
    for (size_t i = 0; i < cdm_device_list_count(list); ++i) {
        cdm_device_info info{};
        info.struct_size = sizeof info;
        assert_int_equal(cdm_device_list_get(list, i, &info), CDM_OK);
        if (std::strcmp(info.transport, "hid") != 0) continue;
        assert_string_equal(info.uri, "hid:/dev/hidraw0");
        assert_string_equal(info.serial, "UMOCK0001");
        assert_int_equal(info.vendor_id, 0x1209);
        assert_int_equal(info.product_id, 0xCD01);
        assert_string_equal(info.firmware, "1.0.0"); // from the info report: the node was opened
        found = true;
    }
    cdm_device_list_free(list);
    assert_true(found);
}

// Worst-case position error from the 16-bit ADC alone (noise is off in the
// testbed): each cable is off by at most half a count, 0.005 mm, and the
// position moves by sum_i |dp_k/dl_i| * 0.005 (numerical Jacobian of the
// nominal model's solver, central differences, h = 1e-3 mm). The solver's
// own convergence (1e-9 mm) is far below.
void quantisation_bound(const cdm::Model &m, const double p[3], double bound[3]) {
    double l0[4];
    m.readings(p, l0);
    const double h = 1e-3, half_count = 0.005;
    for (int k = 0; k < 3; ++k) bound[k] = 1e-6;
    for (int i = 0; i < 4; ++i) {
        double lp[4], lm[4], pp[3], pm[3];
        std::memcpy(lp, l0, sizeof l0);
        std::memcpy(lm, l0, sizeof l0);
        lp[i] += h;
        lm[i] -= h;
        assert_int_equal(m.position(lp, pp), 0);
        assert_int_equal(m.position(lm, pm), 0);
        for (int k = 0; k < 3; ++k) bound[k] += std::fabs((pp[k] - pm[k]) / (2 * h)) * half_count;
    }
}

void test_stream_matches_truth(void **) {
    MasterTestbed tb;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("hid:/dev/hidraw0", &dev), CDM_OK);
    const cdm::Model model{cdm::DeviceGeometry{}};
    int checked = 0;
    uint32_t last = 0;
    const bool got = wait_until(
        [&] {
            cdm_pose p = new_pose();
            if (cdm_get_pose(dev, &p) != CDM_OK || p.sequence == last) return false;
            last = p.sequence;
            cdm::SimTruth t;
            if (!tb.truth(p.sequence, t)) return false;
            double b[3];
            quantisation_bound(model, t.position, b);
            for (int k = 0; k < 3; ++k) assert_true(std::fabs(p.position[k] - t.position[k]) <= b[k]);
            assert_int_equal(p.buttons, t.buttons);
            return ++checked >= 100;
        },
        5000);
    cdm_stats st{};
    st.struct_size = sizeof st;
    assert_int_equal(cdm_get_stats(dev, &st), CDM_OK);
    print_message("checked %d poses; %llu reports, %llu dropped, %llu malformed\n", checked,
                  (unsigned long long)st.reports, (unsigned long long)st.dropped, (unsigned long long)st.malformed);
    cdm_close(dev);
    assert_true(got);
    assert_int_equal(st.malformed, 0);
}

void test_info_and_calibration_store(void **) {
    MasterTestbed tb;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("hid:/dev/hidraw0", &dev), CDM_OK);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    assert_int_equal(cdm_get_info(dev, &info), CDM_OK);
    assert_string_equal(info.serial, "UMOCK0001");
    assert_string_equal(info.transport, "hid");
    assert_true(std::fabs(info.report_rate_hz - 250.0) < 1e-3);
    // Through HIDIOCSFEATURE/HIDIOCGFEATURE 0x03/0x04, more than one chunk.
    std::string doc = "{\"note\": \"umockdev round trip\", \"pad\": \"";
    doc += std::string(300, 'x') + "\"}";
    assert_int_equal(cdm_device_calibration_write(dev, doc.data(), doc.size()), CDM_OK);
    std::string back(1024, '\0');
    size_t len = 0;
    assert_int_equal(cdm_device_calibration_read(dev, &back[0], back.size(), &len), CDM_OK);
    back.resize(len);
    assert_true(back == doc);
    cdm_close(dev);
    assert_true(tb.ioctls_seen(0x06) > 0 && tb.ioctls_seen(0x07) > 0);
}

// The kernel's unplug and replug: the open handle's reads fail, the reader
// finds the master again by serial (filtered enumeration) and reconnects;
// the reports sent while the handle was away count as dropped.
void test_unplug_replug(void **) {
    MasterTestbed tb;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("hid:/dev/hidraw0", &dev), CDM_OK);
    cdm_pose p = new_pose();
    assert_true(wait_until([&] { return cdm_get_pose(dev, &p) == CDM_OK && p.sequence > 10; }, 3000));
    tb.unplug();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    cdm_stats st{};
    st.struct_size = sizeof st;
    tb.plug();
    const auto t0 = std::chrono::steady_clock::now();
    const bool back = wait_until(
        [&] {
            return cdm_get_stats(dev, &st) == CDM_OK && st.reconnects >= 1 && cdm_get_pose(dev, &p) == CDM_OK &&
                   p.dropped > 0;
        },
        5000);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    print_message("replug to streaming: %.0f ms; reconnects %llu, dropped %u\n", ms,
                  (unsigned long long)st.reconnects, p.dropped);
    cdm_close(dev);
    assert_true(back);
}

// A node that claims to be a master and is not must give a clear error,
// never a crash. CDM_UMOCK_NODE_CHECK_FIXED says the device workstream's
// check before hid_open_path is in this tree (issue 13 item 3).
void open_bad_node(NodeMode mode) {
    TestbedOptions o;
    o.mode = mode;
    MasterTestbed tb(o);
    cdm_device *dev = nullptr;
    const int rc = cdm_open("hid:/dev/hidraw0", &dev);
    if (rc == CDM_OK) {
        // Garbage may open (the node answers); its reports must all be
        // rejected, never published as poses.
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        cdm_stats st{};
        st.struct_size = sizeof st;
        assert_int_equal(cdm_get_stats(dev, &st), CDM_OK);
        cdm_pose p = new_pose();
        const int prc = cdm_get_pose(dev, &p);
        cdm_close(dev);
        assert_int_equal(st.reports, 0);
        assert_true(prc != CDM_OK);
        return;
    }
    assert_true(rc == CDM_ERR_NO_DEVICE || rc == CDM_ERR_IO || rc == CDM_ERR_PROTOCOL);
    const char *why = cdm_thread_error();
    print_message("open refused: %s\n", why ? why : "(no text)");
    assert_non_null(why);
    assert_non_null(std::strstr(why, "/dev/hidraw0"));
}

void test_node_without_hid_ioctls(void **) { open_bad_node(NodeMode::NoIoctl); }
void test_node_with_garbage(void **) { open_bad_node(NodeMode::Garbage); }

void test_node_vanishes_before_open(void **) {
    MasterTestbed tb;
    tb.unplug();
    cdm_device *dev = nullptr;
    const int rc = cdm_open("hid:/dev/hidraw0", &dev);
    assert_int_equal(rc, CDM_ERR_NO_DEVICE);
    assert_non_null(std::strstr(cdm_thread_error(), "/dev/hidraw0"));
}

} // namespace

int main() {
    if (!cdm_umock::in_mock_environment()) {
        std::fprintf(stderr, "run me through umockdev-wrapper\n");
        return 1;
    }
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hidapi_enumerates),
        cmocka_unit_test(test_cdm_enumerate),
        cmocka_unit_test(test_stream_matches_truth),
        cmocka_unit_test(test_info_and_calibration_store),
        cmocka_unit_test(test_unplug_replug),
        cmocka_unit_test(test_node_vanishes_before_open),
        cmocka_unit_test(test_node_without_hid_ioctls),
        cmocka_unit_test(test_node_with_garbage),
    };
    if (const char *f = std::getenv("CMOCKA_TEST_FILTER")) cmocka_set_test_filter(f); // one test, by glob
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
