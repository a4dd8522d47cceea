// diag::lomb, the periodogram behind the ripple's start period and the
// "periodic in cable length" finding, steps each point's phase from one
// frequency to the next by a rotation instead of calling sin and cos. Here
// it is held against Lomb's formula written out directly (two sin/cos per
// point and frequency, tau from its own sums) on irregular samples: the
// difference allowed is rounding, not method. The power is a ratio of sums
// of n = 3,000 terms of order 1; each rotated phase carries at most ~64
// steps of one rounding each (it is recomputed every 64 frequencies), so
// the powers agree to ~1e-12 relative; 1e-9 of the largest power leaves
// three orders of margin and still fails on any wrong term (a wrong tau,
// a swapped sum, a lost reseed, a phase off by one step: all >= 1e-3).
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <random>
#include <setjmp.h>
#include <vector>

#include "calib/evaluation/residual.h"

extern "C" {
#include <cmocka.h>
}

namespace {

std::vector<double> lomb_direct(const std::vector<double> &t, const std::vector<double> &y, double f0, double df,
                                size_t nf) {
    const size_t n = t.size();
    double mean = 0, var = 0;
    for (double v : y) mean += v;
    mean /= double(n);
    for (double v : y) var += (v - mean) * (v - mean);
    var /= double(n - 1);
    std::vector<double> P(nf, 0);
    for (size_t f = 0; f < nf; ++f) {
        const double w = 2 * M_PI * (f0 + df * double(f));
        double s2 = 0, c2 = 0;
        for (size_t k = 0; k < n; ++k) {
            s2 += std::sin(2 * w * t[k]);
            c2 += std::cos(2 * w * t[k]);
        }
        const double tau = std::atan2(s2, c2) / (2 * w);
        double yc = 0, ys = 0, cc = 0, ss = 0;
        for (size_t k = 0; k < n; ++k) {
            const double c = std::cos(w * (t[k] - tau)), s = std::sin(w * (t[k] - tau));
            yc += (y[k] - mean) * c;
            ys += (y[k] - mean) * s;
            cc += c * c;
            ss += s * s;
        }
        P[f] = 0.5 * (yc * yc / cc + ys * ys / ss) / var;
    }
    return P;
}

// Cable lengths as a jig gives them: 3,000 irregular values over 150-450 mm,
// a 94.2 mm ripple of 0.15 mm in noise of 0.05 mm.
void jig_like(std::vector<double> &t, std::vector<double> &y, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(150, 450);
    std::normal_distribution<double> noise(0, 0.05);
    t.clear();
    y.clear();
    for (int k = 0; k < 3000; ++k) {
        t.push_back(u(rng));
        y.push_back(0.15 * std::sin(2 * M_PI * t.back() / 94.2 + 0.7) + noise(rng));
    }
}

void matches_the_direct_formula(void **) {
    for (unsigned seed : {1u, 2u, 3u}) {
        std::vector<double> t, y;
        jig_like(t, y, seed);
        // The grid length_period uses: 1/span to 1/8 mm, 5x oversampled, and
        // a count that is not a multiple of the reseed interval.
        const double f0 = 1.0 / 300, f1 = 1.0 / 8;
        const size_t nf = 1000 + seed * 37;
        const double df = (f1 - f0) / double(nf - 1);
        const auto fast = cdm::diag::lomb(t, y, f0, df, nf);
        const auto ref = lomb_direct(t, y, f0, df, nf);
        assert_int_equal(fast.size(), nf);
        double pmax = 0;
        size_t kmax = 0;
        for (size_t f = 0; f < nf; ++f)
            if (ref[f] > pmax) pmax = ref[f], kmax = f;
        for (size_t f = 0; f < nf; ++f)
            if (!(std::fabs(fast[f] - ref[f]) <= 1e-9 * pmax))
                fail_msg("seed %u, frequency %zu: %.15g against %.15g (direct)", seed, f, fast[f], ref[f]);
        // And the peak is the ripple's: within one grid step of 1/94.2.
        assert_true(std::fabs(f0 + df * double(kmax) - 1 / 94.2) <= df);
    }
}

void degenerate_inputs(void **) {
    // Constant readings: no variance, zero power everywhere (not NaN).
    std::vector<double> t{1, 2, 3, 4, 5, 6, 7, 8}, y(8, 2.5);
    for (double p : cdm::diag::lomb(t, y, 0.01, 0.01, 10)) assert_true(p == 0);
    // Fewer than two points: zeros of the asked length.
    assert_int_equal(cdm::diag::lomb({1.0}, {1.0}, 0.1, 0.1, 5).size(), 5);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(matches_the_direct_formula),
        cmocka_unit_test(degenerate_inputs),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
