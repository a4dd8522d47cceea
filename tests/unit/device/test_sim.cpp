// sim: end to end through the public API: accuracy against the simulator's
// truth, staleness, waiting, the jig script, the calibration store,
// calibrations, struct_size, and URI errors.

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "api/calibration_handle.h"
#include "jig/plan.h"
#include "cdm/cdm.h"
#include "device/sim/sim_truth.h"
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

namespace {

cdm_device *open_ok(const char *uri, const cdm_open_options *o = nullptr) {
    cdm_device *dev = nullptr;
    const int rc = cdm_open_ex(uri, o, &dev);
    if (rc != CDM_OK) fail_msg("cdm_open(%s): %s: %s", uri, cdm_strerror(rc), cdm_thread_error());
    return dev;
}

cdm_pose new_pose() {
    cdm_pose p{};
    p.struct_size = sizeof p;
    return p;
}

// Position accuracy. Each cable reading carries Gaussian noise sigma_n and
// then the ADC's rounding, uniform over one count q, i.e. variance
// sigma_n^2 + q^2/12 per cable, independent across cables. The position is
// a smooth function of the four readings (the seed's triangulation, the
// nominal model), so to first order its error on axis k has standard
// deviation sigma_k = sqrt(sum_i J_ki^2) * sqrt(sigma_n^2 + q^2/12), with J
// the Jacobian d position / d readings at the true position. J is computed
// here by central differences at every sample's true position (x is
// amplified by roughly L/x, ~4 at the workspace's centre, more near the
// plane, y and z by ~0.5: guessing would be wrong by that much).
// Each error divided by its sigma_k is then standard normal. Checks:
//  - every |z| < 5.5 (P(|z| > 5.5) = 3.8e-8; with ~1000 values the chance
//    of a false failure is 4e-5);
//  - the RMS of z per axis within 1 +- 0.2 (the RMS of N standard normals
//    has std 1/sqrt(2N) = 0.03 for N = 600: 0.2 is 6.6 of those), which
//    fails if the driver adds error, or if the simulator's noise is not
//    what it was told.
void jacobian_sigma(const cdm::DeviceGeometry &g, const double p[3], double sigma_cable, double sigma[3]) {
    // d p / d lengths of the nominal model at p: the model's own derivative.
    const cdm::Model m{g};
    double l0[4], q[3], dp_dl[12];
    cdm::nominal_lengths(g, p, l0);
    assert_int_equal(m.position(l0, 0.0, q, dp_dl), 0);
    for (int k = 0; k < 3; ++k) {
        double s2 = 0;
        for (int i = 0; i < 4; ++i) s2 += dp_dl[4 * k + i] * dp_dl[4 * k + i];
        sigma[k] = std::sqrt(s2) * sigma_cable;
    }
}

void test_accuracy_against_truth(void **) {
    const double noise = 0.05, q = 0.01; // URI noise, ADC count (docs/protocol.md)
    cdm_device *dev = open_ok("sim:?seed=7&noise=0.05&motion=random");
    const double sigma_cable = std::sqrt(noise * noise + q * q / 12);
    cdm::DeviceGeometry g; // the sim's default geometry
    std::map<uint32_t, cdm_pose> seen;
    // Through cdm_get_pose, polled as a haptic loop would: distinct
    // sequence numbers only.
    const bool got = cdm_test::wait_until(
        [&] {
            cdm_pose p = new_pose();
            if (cdm_get_pose(dev, &p) == CDM_OK) seen.emplace(p.sequence, p);
            return seen.size() >= 600;
        },
        20000);
    assert_true(got);
    double z2[3] = {0, 0, 0}, zmax = 0, angle_max = 0, grip_err_max = 0;
    int n = 0;
    for (const auto &kv : seen) {
        cdm::SimTruth t;
        if (!cdm::sim_truth(dev, kv.first, t)) continue;
        const cdm_pose &p = kv.second;
        double sigma[3];
        jacobian_sigma(g, t.position, sigma_cable, sigma);
        for (int k = 0; k < 3; ++k) {
            const double z = (p.position[k] - t.position[k]) / sigma[k];
            z2[k] += z * z;
            zmax = std::max(zmax, std::fabs(z));
        }
        double dot = 0;
        for (int k = 0; k < 4; ++k) dot += p.orientation[k] * t.orientation[k];
        angle_max = std::max(angle_max, 2 * std::acos(std::min(1.0, std::fabs(dot))));
        grip_err_max = std::max(grip_err_max, std::fabs(p.grip - t.grip));
        assert_int_equal(p.buttons, t.buttons);
        assert_int_equal(p.flags & ~CDM_POSE_STALE, 0);
        ++n;
    }
    cdm_close(dev);
    assert_true(n >= 500);
    for (int k = 0; k < 3; ++k) {
        const double rms = std::sqrt(z2[k] / n);
        print_message("axis %d: normalised RMS error %.3f over %d samples\n", k, rms, n);
        assert_true(rms > 0.8 && rms < 1.2);
    }
    assert_true(zmax < 5.5);
    // Orientation: the sim's IMU error is a rotation with std 0.001 rad per
    // axis (3 axes: |angle| is chi-distributed, P(> 6 sigma) ~ 1e-7), plus
    // Q14 rounding, at most 2 * 6.1e-5 rad of angle.
    assert_true(angle_max < 6 * 0.001 + 1.3e-4);
    // Grip: Hall noise 2 counts std, 1200 counts per 0.6 rad: 1e-3 rad std,
    // plus half a count of rounding (2.5e-4 rad).
    assert_true(grip_err_max < 6 * 1e-3 + 2.5e-4);
}

void test_stale_and_wait(void **) {
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.stale_timeout_us = 20000;
    cdm_device *dev = open_ok("sim:?stall_after=50&motion=still", &o);
    cdm_pose p = new_pose();
    // Before the first report: NO_DATA, zeroed.
    // (The sim starts immediately, so only check the code if we are early.)
    int rc = cdm_wait_pose(dev, 1000, &p);
    assert_true(rc == CDM_OK);
    const uint32_t first = p.sequence;
    rc = cdm_wait_pose(dev, 1000, &p);
    assert_int_equal(rc, CDM_OK);
    assert_true(p.sequence != first); // newer than at the call
    cdm_stats st{};
    st.struct_size = sizeof st;
    assert_true(cdm_test::wait_until([&] { return cdm_get_stats(dev, &st) == CDM_OK && st.reports == 50; }, 5000));
    // Reports stopped (a hung device, still connected). Within the 20 ms
    // deadline the pose is fresh...
    // ...and beyond it, stale: flagged, with the error code, still filled.
    std::this_thread::sleep_for(std::chrono::milliseconds(60));
    p = new_pose();
    rc = cdm_get_pose(dev, &p);
    assert_int_equal(rc, CDM_ERR_STALE);
    assert_true(p.flags & CDM_POSE_STALE);
    assert_int_equal(p.sequence, 49);
    assert_true(std::fabs(p.position[0] - 50.0) < 1.0); // motion=still holds x = 50 mm
    // wait_pose times out with the newest pose filled in.
    rc = cdm_wait_pose(dev, 30, &p);
    assert_int_equal(rc, CDM_ERR_TIMEOUT);
    assert_int_equal(p.sequence, 49);
    // A longer deadline makes the same pose fresh again.
    assert_int_equal(cdm_set_stale_timeout(dev, 10000000), CDM_OK);
    rc = cdm_get_pose(dev, &p);
    assert_int_equal(rc, CDM_OK);
    assert_false(p.flags & CDM_POSE_STALE);
    cdm_close(dev);
}

void test_struct_size(void **) {
    cdm_device *dev = open_ok("sim:?motion=still");
    cdm_pose p = new_pose();
    assert_int_equal(cdm_wait_pose(dev, 1000, &p), CDM_OK);
    // Too small for 1.0: refused.
    p.struct_size = 50;
    assert_int_equal(cdm_get_pose(dev, &p), CDM_ERR_INVALID_ARG);
    // A caller built against a newer, larger cdm_pose: the 1.0 fields are
    // written, the rest is left alone.
    struct Bigger {
        cdm_pose pose;
        uint64_t future[4];
    } big;
    std::memset(&big, 0xAB, sizeof big);
    big.pose.struct_size = sizeof big;
    assert_true(cdm_get_pose(dev, &big.pose) == CDM_OK || cdm_get_pose(dev, &big.pose) == CDM_ERR_STALE);
    assert_int_equal(big.pose.struct_size, sizeof big);
    for (uint64_t f : big.future) assert_true(f == 0xABABABABABABABABull);
    assert_true(big.pose.position[0] > 40 && big.pose.position[0] < 60);
    cdm_device_info info{};
    info.struct_size = 100;
    assert_int_equal(cdm_get_info(dev, &info), CDM_ERR_INVALID_ARG);
    info.struct_size = sizeof info;
    assert_int_equal(cdm_get_info(dev, &info), CDM_OK);
    assert_string_equal(info.transport, "sim");
    assert_int_equal(info.vendor_id, 0x1209);
    assert_int_equal(info.product_id, 0xCD01);
    assert_true(info.pot_scale_mm[0] > 0.0099 && info.pot_scale_mm[0] < 0.0101);
    cdm_stats st{};
    st.struct_size = 8;
    assert_int_equal(cdm_get_stats(dev, &st), CDM_ERR_INVALID_ARG);
    cdm_raw raw{};
    raw.struct_size = sizeof raw;
    assert_true(cdm_get_raw(dev, &raw) == CDM_OK);
    // lengths_mm are the ADC counts through the nominal scale.
    for (int i = 0; i < 4; ++i) assert_true(std::fabs(raw.lengths_mm[i] - raw.pot_adc[i] * double(0.01f)) < 1e-9);
    cdm_close(dev);
    cdm_close(nullptr); // NULL is fine
}

struct JigCtx {
    std::mutex mu;
    std::vector<cdm::SimTruth> truths;
    std::vector<cdm_pose> poses;
    std::atomic<cdm_device *> dev{nullptr};
    std::atomic<int> missing{0};
};

void jig_cb(void *user, const cdm_sample *s) {
    auto *c = static_cast<JigCtx *>(user);
    std::lock_guard<std::mutex> lock(c->mu);
    c->poses.push_back(*s->pose);
}

void test_jig_script(void **) {
    JigCtx ctx;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = jig_cb;
    o.user = &ctx;
    // realtime=0: the sim runs as fast as the reader thread takes reports.
    cdm_device *dev = open_ok(
        "sim:?motion=jig&realtime=0&noise=0&jig_n=3&jig_pitch=10&jig_heights=30,50&jig_samples=10&jig_transit=4"
        "&jig_tolerance=0.03&seed=3",
        &o);
    cdm_pose p = new_pose();
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM; }, 10000));
    assert_true(p.flags & CDM_POSE_END_OF_STREAM);
    assert_int_equal(cdm_wait_pose(dev, -1, &p), CDM_ERR_END_OF_STREAM); // never blocks after the end
    // 18 positions x (4 transit + 10 dwell) + 4 trailing.
    std::lock_guard<std::mutex> lock(ctx.mu);
    assert_int_equal(ctx.poses.size(), 18 * 14 + 4);
    cdm::JigPlanOptions po;
    po.n = 3;
    po.pitch_mm = 10;
    po.heights_mm = {30, 50};
    po.samples = 10;
    const auto plan = cdm::make_jig_plan(po);
    assert_int_equal(plan.size(), 18);
    // Dwells: MARK held for exactly jig_samples, at the plan position within
    // the jig's tolerance (0.03 mm std per axis: 5 sigma = 0.15 mm) plus the
    // ADC's quantisation propagated (noise=0: q/sqrt(12) = 0.003 mm per
    // cable, x amplified < 10 times: < 0.15 mm at 5 sigma).
    size_t i = 0;
    for (size_t k = 0; k < plan.size(); ++k) {
        for (int t = 0; t < 4; ++t, ++i) assert_false(ctx.poses[i].buttons & CDM_BUTTON_MARK);
        for (int s = 0; s < 10; ++s, ++i) {
            assert_true(ctx.poses[i].buttons & CDM_BUTTON_MARK);
            for (int a = 0; a < 3; ++a) assert_true(std::fabs(ctx.poses[i].position[a] - plan[k].ref[a]) < 0.3);
        }
    }
    // device time advances by 1/rate per report even unpaced.
    assert_true(ctx.poses.back().device_time_us == uint64_t(ctx.poses.size() - 1) * 1000);
    cdm_close(dev);
}

void test_calibration_store(void **) {
    cdm_device *dev = open_ok("sim:?motion=still");
    char buf[20000];
    size_t len = 99;
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_ERR_NO_DATA);
    assert_int_equal(len, 0);
    std::string blob;
    for (int i = 0; i < 1000; ++i) blob += char('a' + i % 26);
    assert_int_equal(cdm_device_calibration_write(dev, blob.data(), blob.size()), CDM_OK);
    assert_int_equal(cdm_device_calibration_read(dev, buf, 10, &len), CDM_ERR_NO_MEM);
    assert_int_equal(len, 1000);
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_OK);
    assert_int_equal(len, 1000);
    assert_memory_equal(buf, blob.data(), 1000);
    // The status bit of the input report follows the store.
    cdm_raw raw{};
    raw.struct_size = sizeof raw;
    assert_true(cdm_test::wait_until([&] { cdm_get_raw(dev, &raw); return (raw.status & 8) != 0; }, 2000));
    std::string big(16385, 'x');
    assert_int_equal(cdm_device_calibration_write(dev, big.data(), big.size()), CDM_ERR_INVALID_ARG);
    big.resize(16384);
    assert_int_equal(cdm_device_calibration_write(dev, big.data(), big.size()), CDM_OK);
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_OK);
    assert_int_equal(len, 16384);
    assert_int_equal(cdm_device_calibration_write(dev, "", 0), CDM_OK);
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_OK);
    assert_int_equal(len, 0);
    cdm_close(dev);
}

void test_set_calibration(void **) {
    cdm_device *dev = open_ok("sim:?motion=still&noise=0");
    cdm_pose p = new_pose();
    assert_int_equal(cdm_wait_pose(dev, 1000, &p), CDM_OK);
    assert_false(p.flags & CDM_POSE_COMPENSATED);
    const double x_nominal = p.position[0];
    // A calibration for another frame (10 mm narrower) is refused: it would
    // put the poses elsewhere and flag them COMPENSATED.
    cdm::DeviceGeometry g;
    g.a_mm = 140;
    cdm_calibration other{std::make_shared<const cdm::Model>(g), {}};
    assert_int_equal(cdm_set_calibration(dev, &other), CDM_ERR_INVALID_ARG);
    assert_non_null(std::strstr(cdm_thread_error(), "a_mm 140 (calibration) vs 150 (device"));
    // Pots reading 5 mm short (cable_offset -5 mm each): same readings,
    // another position, and the pose says a calibration was applied.
    auto with_offsets = [](double o) {
        cdm::Model m{cdm::DeviceGeometry{}};
        std::string err;
        assert_true(m.add_effect("cable_offset", {{"o1", o}, {"o2", o}, {"o3", o}, {"o4", o}}, err));
        return std::make_shared<const cdm::Model>(m);
    };
    cdm_calibration cal{with_offsets(-5.0), {}};
    assert_int_equal(cdm_set_calibration(dev, &cal), CDM_OK);
    cal.model.reset(); // the device keeps its own reference
    assert_true(cdm_test::wait_until(
        [&] { return cdm_get_pose(dev, &p) == CDM_OK && (p.flags & CDM_POSE_COMPENSATED); }, 2000));
    assert_true(std::fabs(p.position[0] - x_nominal) > 1.0);
    // Pots reading 20 mm long instead: at (50, 0, 0) the cables, 197 mm,
    // would be 177 mm, shorter than the 191 mm from anchor to holder corner
    // in the plane: no position. No NaN: the last good position is held and
    // flagged.
    const double held_x = p.position[0];
    cdm_calibration wide{with_offsets(20.0), {}};
    assert_int_equal(cdm_set_calibration(dev, &wide), CDM_OK);
    assert_true(cdm_test::wait_until(
        [&] { cdm_get_pose(dev, &p); return (p.flags & CDM_POSE_OUT_OF_WORKSPACE) != 0; }, 2000));
    assert_true(std::isfinite(p.position[0]) && std::fabs(p.position[0] - held_x) < 0.01);
    cdm_stats st{};
    st.struct_size = sizeof st;
    cdm_get_stats(dev, &st);
    assert_true(st.out_of_workspace > 0);
    assert_int_equal(cdm_set_calibration(dev, nullptr), CDM_OK);
    assert_true(cdm_test::wait_until(
        [&] { return cdm_get_pose(dev, &p) == CDM_OK && !(p.flags & CDM_POSE_COMPENSATED); }, 2000));
    assert_true(std::fabs(p.position[0] - x_nominal) < 0.01);
    cdm_close(dev);
}

void expect_open_error(const char *uri, int code, const char *needle) {
    cdm_device *dev = reinterpret_cast<cdm_device *>(0x1);
    const int rc = cdm_open(uri, &dev);
    if (rc != code) fail_msg("cdm_open(%s) = %d (%s), expected %d", uri ? uri : "NULL", rc, cdm_thread_error(), code);
    assert_null(dev);
    if (!std::strstr(cdm_thread_error(), needle))
        fail_msg("cdm_open(%s): detail \"%s\" does not name \"%s\"", uri ? uri : "NULL", cdm_thread_error(), needle);
}

void test_bad_uris(void **) {
    expect_open_error("bogus:thing", CDM_ERR_NO_DEVICE, "bogus");
    expect_open_error("no uri at all", CDM_ERR_NO_DEVICE, "no uri at all");
    expect_open_error("sim:?rate=abc", CDM_ERR_INVALID_ARG, "rate");
    expect_open_error("sim:?rate=0", CDM_ERR_INVALID_ARG, "rate");
    expect_open_error("sim:?noise=-1", CDM_ERR_INVALID_ARG, "noise");
    expect_open_error("sim:?nosuch=1", CDM_ERR_INVALID_ARG, "nosuch");
    expect_open_error("sim:?motion=dance", CDM_ERR_INVALID_ARG, "motion");
    expect_open_error("sim:?realtime=yes", CDM_ERR_INVALID_ARG, "realtime");
    expect_open_error("sim:?seed=1&seed=2", CDM_ERR_INVALID_ARG, "seed");
    expect_open_error("sim:?jig_n=5", CDM_ERR_INVALID_ARG, "motion=jig");
    expect_open_error("sim:?motion=jig&jig_heights=30,x", CDM_ERR_INVALID_ARG, "x");
    expect_open_error("sim:?effects=no_such_effect", CDM_ERR_INVALID_ARG, "no_such_effect");
    expect_open_error("sim:?device=/nonexistent/dev.json", CDM_ERR_INVALID_ARG, "/nonexistent/dev.json");
    expect_open_error("sim:?flag", CDM_ERR_INVALID_ARG, "flag");
    expect_open_error("sim:path", CDM_ERR_INVALID_ARG, "sim:path");
    expect_open_error("replay:/nonexistent/file.cdmrec", CDM_ERR_NO_DEVICE, "/nonexistent/file.cdmrec");
    expect_open_error("replay:", CDM_ERR_INVALID_ARG, "replay:");
    expect_open_error("hid:/dev/nonexistent-hidraw", CDM_ERR_NO_DEVICE, "/dev/nonexistent-hidraw");
    expect_open_error("serial:NOSUCHSERIAL", CDM_ERR_NO_DEVICE, "NOSUCHSERIAL");
    // NULL: $CDM_DEVICE first...
    setenv("CDM_DEVICE", "sim:?motion=still", 1);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open(nullptr, &dev), CDM_OK);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    cdm_get_info(dev, &info);
    assert_string_equal(info.uri, "sim:?motion=still");
    cdm_close(dev);
    // ...else the first real device, and there is none on this machine.
    unsetenv("CDM_DEVICE");
    expect_open_error(nullptr, CDM_ERR_NO_DEVICE, "CDM_DEVICE");
    assert_int_equal(cdm_open("sim:", nullptr), CDM_ERR_INVALID_ARG);
    cdm_pose p = new_pose();
    assert_int_equal(cdm_get_pose(nullptr, &p), CDM_ERR_INVALID_ARG);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_accuracy_against_truth), cmocka_unit_test(test_stale_and_wait),
        cmocka_unit_test(test_struct_size),            cmocka_unit_test(test_jig_script),
        cmocka_unit_test(test_calibration_store),      cmocka_unit_test(test_set_calibration),
        cmocka_unit_test(test_bad_uris),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
