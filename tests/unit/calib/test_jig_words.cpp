// The words the diagnosis gives the fixture heights' x offsets
// (diag::jig_analysis), on residuals written by hand: a 3 x 3 plate at each
// height, every position's x residual its height's offset, no noise in the
// residuals themselves, and a stated standard error per height (each
// position's x variance 0.03^2 mm^2 over 9 positions: 0.01 mm per height).
// The statistics are then exact numbers the test can state: the common
// part's chi-square (1 dof) and the spread about it (K - 1 dof).
// Also: a false-alarm probability over fewer than one searched period is
// never below the single test's p (calib/evaluation/stats.h).
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <setjmp.h>
#include <string>
#include <vector>

#include "calib/evaluation/jig.h"
#include "calib/evaluation/spatial.h"
#include "calib/evaluation/stats.h"

extern "C" {
#include <cmocka.h>
}

namespace {

using namespace cdm;
using V3 = Eigen::Vector3d;

// The fixture's sentence for per-height x offsets `xoff` at `heights` (mm).
std::string fixture_words(const std::vector<double> &heights, const std::vector<double> &xoff,
                          const diag::FixtureLR *lr = nullptr) {
    std::vector<PreparedPos> pos;
    for (double x : heights)
        for (int y = -1; y <= 1; ++y)
            for (int z = -1; z <= 1; ++z) {
                PreparedPos p;
                p.ref = V3(x, 5.0 * y, 5.0 * z);
                p.mean.setZero();
                p.var_mean.setZero();
                p.cov.setZero();
                p.n = 10;
                pos.push_back(p);
            }
    const diag::Grid G = diag::make_grid(pos, heights);
    diag::Eval E;
    const size_t P = pos.size();
    E.res.assign(P, V3::Zero());
    E.var_mean.assign(P, V3::Constant(0.03 * 0.03)); // 0.01 mm per height of 9
    E.ok.assign(P, 1);
    E.est.assign(P, V3::Zero());
    E.Jp.resize(P);
    E.within[0].n = 1;
    for (size_t j = 0; j < P; ++j) E.res[j](0) = xoff[size_t(G.height_index[j])];
    const auto A = diag::jig_analysis(E, G, pos, V3::Zero(), V3::Constant(0.05), lr);
    std::string all;
    for (auto &t : A.report["text"]) all += t.get<std::string>() + "\n";
    return all;
}

bool has(const std::string &s, const char *what) { return s.find(what) != std::string::npos; }

// Per-height +0.034, -0.010, +0.034, -0.010, +0.012 mm (standard error 0.01):
// common part +0.012 (chi-square 7.2, p = 0.007: not significant alone), the
// spread about it chi-square 19.4 on 4 dof (p = 6.7e-4): each height's own.
// The spread's test alone would choose "the jig sits +0.012 mm off in x at
// every fixture height", with two heights on the other side.
void mixed_signs_are_the_heights_own(void **) {
    const std::string w = fixture_words({30, 40, 50, 60, 70}, {0.034, -0.010, 0.034, -0.010, 0.012});
    if (has(w, "jig sits") || !has(w, "each fixture height has its own offset"))
        fail_msg("per-height offsets of both signs: %s", w.c_str());
    diag::FixtureLR lr; // the same through the likelihood-ratio path
    lr.tested = true;
    lr.chi2 = 26.6;
    const std::string w2 = fixture_words({30, 40, 50, 60, 70}, {0.034, -0.010, 0.034, -0.010, 0.012}, &lr);
    if (has(w2, "jig sits") || !has(w2, "each fixture height has its own offset"))
        fail_msg("per-height offsets of both signs, likelihood ratio: %s", w2.c_str());
}

// A common shift of +0.05 mm (5 standard errors per height; common part
// chi-square 125) with a spread of +-0.005 mm: the jig sits off as a whole.
void a_common_shift_is_the_jig_sitting_off(void **) {
    const std::string w = fixture_words({30, 40, 50, 60, 70}, {0.055, 0.045, 0.05, 0.055, 0.045});
    if (!has(w, "jig sits +0.050 mm off in x at every fixture height"))
        fail_msg("a common shift: %s", w.c_str());
}

// Two heights at +0.000 and +0.045 mm: the offsets together are significant
// (chi-square 20.3 on 2 dof, p = 4e-5, times 3 axes), the common part
// (+0.0225 mm, chi-square 10.1, p = 0.0015) and the spread (the same) are
// not alone: neither story is told, the offsets are named together. (It
// read "the jig sits +0.022 mm off in x at every fixture height" with one
// height at zero.)
void neither_alone_names_them_together(void **) {
    const std::string w = fixture_words({30, 40}, {0.0, 0.045});
    if (has(w, "jig sits") || has(w, "own offset") || !has(w, "the fixture heights are off in x"))
        fail_msg("two heights, neither part significant alone: %s", w.c_str());
}

// sf over M independent periods: 1 - (1 - sf)^M, never below sf itself
// (M < 1 on spans of 8-16 mm, where the formula gave a p eight times too
// small), and the union bound for tiny sf.
void false_alarm_is_never_below_the_single_test(void **) {
    for (double M : {0.0, 0.12, 0.78, 1.0})
        for (double sf : {1e-15, 1e-6, 0.01, 0.3}) {
            const double p = diag::false_alarm(sf, M);
            if (!(p >= sf && p <= 1)) fail_msg("false_alarm(%g, %g) = %g", sf, M, p);
        }
    const double p = diag::false_alarm(0.01, 20);
    if (std::fabs(p - (1 - std::pow(0.99, 20))) > 1e-12) fail_msg("false_alarm(0.01, 20) = %g", p);
}

} // namespace

int main() {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(mixed_signs_are_the_heights_own),
        cmocka_unit_test(a_common_shift_is_the_jig_sitting_off),
        cmocka_unit_test(neither_alone_names_them_together),
        cmocka_unit_test(false_alarm_is_never_below_the_single_test),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
