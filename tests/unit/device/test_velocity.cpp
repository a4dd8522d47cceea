// cdm_pose.velocity: the filter exactly (white box), then through the public
// API on the simulator's circle against its analytic velocity.
#include <cmath>
#include <cstdio>

#include "cdm/cdm.h"
#include "device/velocity.h"
#include "test_util.h"

extern "C" {
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>

#include <cmocka.h>
}

namespace {

// A ramp at constant velocity: the low-pass of a constant converges
// geometrically (factor 1 - a = tau/(tau+dt) = 0.76 per report at 1 kHz);
// after 200 reports the remainder is 0.76^200 ~ 1e-24 of the start:
// exact to rounding.
void test_ramp_converges_exactly(void **) {
    cdm::VelocityFilter f;
    const double v_true[3] = {12.5, -3.0, 0.25};
    double v[3];
    for (int i = 0; i <= 200; ++i) {
        const double t = i * 1e-3;
        const double p[3] = {10 + v_true[0] * t, v_true[1] * t, 5 + v_true[2] * t};
        f.update(p, t, true, v);
        if (i == 0)
            for (double c : v) assert_true(c == 0.0); // one position: no velocity yet
    }
    for (int k = 0; k < 3; ++k) assert_true(std::fabs(v[k] - v_true[k]) < 1e-9);
}

// Held positions, clock gaps and a clock that goes backward restart it.
void test_gaps_and_held_positions_reset(void **) {
    cdm::VelocityFilter f;
    double v[3];
    double p[3] = {0, 0, 0};
    for (int i = 0; i < 50; ++i) {
        p[0] = i * 0.01;
        f.update(p, i * 1e-3, true, v);
    }
    assert_true(v[0] > 5);
    f.update(p, 0.05, false, v); // out of workspace: held, so no motion is known
    assert_true(v[0] == 0 && v[1] == 0 && v[2] == 0);
    p[0] += 100;
    f.update(p, 0.051, true, v); // first fresh position after it: no difference yet
    assert_true(v[0] == 0);
    p[0] += 1;
    f.update(p, 0.2, true, v); // 149 ms later: a gap, not a motion of 1 mm / 149 ms
    assert_true(v[0] == 0);
    p[0] += 1;
    f.update(p, 0.1, true, v); // device clock went backward (a reset, a wrap)
    assert_true(v[0] == 0);
}

// The sim's circle: radius 40 mm at 0.25 Hz in the y-z plane, x fixed, so
// v = 40 w (0, -sin wt, cos wt), |v| = 62.8 mm/s. Without noise the
// error is the filter's lag (3.7 ms: 0.23 mm/s here, times the 1.0
// acceleration ratio) plus the ADC quantisation's difference noise (0.01 mm
// counts: about 4 mm/s rms per difference, 1.6 mm/s after the filter);
// 8 mm/s is 5 of those. Compared against the simulator's own time.
void test_circle_through_the_api(void **) {
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:?motion=circle&noise=0&imu_noise=0&hall_noise=0&rate=1000", &dev), CDM_OK);
    const double w = 2 * M_PI * 0.25, lag_s = 0.5e-3 + 1.0 / (2 * M_PI * cdm::VelocityFilter::kCutoffHz);
    int checked = 0;
    uint64_t after = 0;
    double worst = 0;
    while (checked < 300) {
        cdm_pose p{};
        p.struct_size = sizeof p;
        const int rc = cdm_wait_pose_after(dev, after, 1000, &p);
        assert_true(rc == CDM_OK || rc == CDM_ERR_STALE);
        after = p.host_sequence;
        if (p.host_sequence < 100) continue; // the filter has settled (0.76^100)
        const double t = double(p.device_time_us) * 1e-6 - lag_s;
        const double v[3] = {0, -40 * w * std::sin(w * t), 40 * w * std::cos(w * t)};
        for (int k = 0; k < 3; ++k) worst = std::fmax(worst, std::fabs(p.velocity[k] - v[k]));
        ++checked;
    }
    std::printf("circle: worst velocity error %.3f mm/s over %d poses (speed 62.8 mm/s)\n", worst, checked);
    assert_true(worst < 8.0);
    cdm_close(dev);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ramp_converges_exactly),
        cmocka_unit_test(test_gaps_and_held_positions_reset),
        cmocka_unit_test(test_circle_through_the_api),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
