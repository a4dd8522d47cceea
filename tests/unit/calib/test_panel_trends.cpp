// diag::binned_trend, the test behind the report's residual panels
// (positions.trends): a one-way analysis of variance of y over bins of
// equal count of x. Under no trend its p-value is uniform, so at the 1 %
// level 400 independent noise series give about 4 false alarms: the
// binomial(400, 0.01) exceeds 12 with probability 3e-4, the bound below.
// A line rising by one noise sd over the range, 2,000 points, is found far
// below the verdict's 1e-3 (the bin means' variance ~1/12: F ~ 2000/12/9
// ~ 18 on 9 and 1990 dof, p ~ 1e-28); so is a bump of half an sd confined
// to one bin of ten (between-bin squares ~ 200 * 0.45^2 + 1800 * 0.05^2 ~ 45: F ~ 5, p ~ 5e-7),
// which a straight-line fit would miss.
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <random>
#include <setjmp.h>
#include <vector>

#include "calib/diagnosis/panels.h"

extern "C" {
#include <cmocka.h>
}

namespace {

using cdm::diag::binned_trend;

void noise_alarms_at_its_level(void **) {
    int alarms = 0;
    for (uint32_t seed = 1; seed <= 400; ++seed) {
        std::mt19937_64 rng(seed);
        std::normal_distribution<double> n(0, 1);
        std::uniform_real_distribution<double> u(0, 100);
        std::vector<double> x(2000), y(2000);
        for (size_t i = 0; i < x.size(); ++i) x[i] = u(rng), y[i] = n(rng);
        const auto t = binned_trend(x, y, 10);
        assert_int_equal(t.bins, 10);
        alarms += t.p < 0.01;
    }
    if (alarms > 12) fail_msg("%d of 400 noise series at p < 0.01", alarms);
}

void trends_and_bumps_are_found(void **) {
    std::mt19937_64 rng(7);
    std::normal_distribution<double> n(0, 1);
    std::uniform_real_distribution<double> u(0, 100);
    std::vector<double> x(2000), line(2000), bump(2000);
    for (size_t i = 0; i < x.size(); ++i) {
        x[i] = u(rng);
        line[i] = 0.01 * x[i] + n(rng);                           // 1 sd over the range
        bump[i] = (x[i] > 40 && x[i] < 50 ? 0.5 : 0.0) + n(rng); // one bin of ten
    }
    const auto a = binned_trend(x, line, 10), b = binned_trend(x, bump, 10);
    if (!(a.p < 1e-12)) fail_msg("a line of 1 sd: p = %g", a.p);
    if (!(b.p < 1e-4)) fail_msg("a bump of 0.5 sd in one bin: p = %g", b.p);
    assert_true(b.range_mm > 0.3);
}

void too_few_values_are_not_tested(void **) {
    std::vector<double> x{1, 2, 3, 4, 5}, y{1, 2, 3, 4, 5};
    assert_int_equal(binned_trend(x, y, 10).bins, 0);
    // Non-finite pairs are left out, not propagated.
    std::vector<double> xs(100), ys(100);
    for (size_t i = 0; i < 100; ++i) xs[i] = double(i), ys[i] = i % 7 ? double(i % 3) : NAN;
    const auto t = binned_trend(xs, ys, 10);
    assert_true(t.bins > 0 && std::isfinite(t.p));
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(noise_alarms_at_its_level),
        cmocka_unit_test(trends_and_bumps_are_found),
        cmocka_unit_test(too_few_values_are_not_tested),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
