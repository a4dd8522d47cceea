// See stats.h. Boost.Math raises on domain errors by default; the
// callers pass checked arguments, and the guards below turn the degenerate
// cases (no degrees of freedom, a non-positive statistic) into p = 1.
#include "calib/evaluation/stats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/normal.hpp>

namespace cdm {
namespace diag {

double normal_sf(double z) {
    if (!std::isfinite(z)) return z > 0 ? 0.0 : 1.0;
    return boost::math::cdf(boost::math::complement(boost::math::normal_distribution<double>(), z));
}

double false_alarm(double sf, double M) {
    // Fewer than one independent period (a span of 8-16 mm: a tiny jig)
    // is still the one that was tested: never below the single test's p.
    M = std::max(1.0, M);
    if (sf < 1e-12) return std::min(1.0, M * sf);
    return -std::expm1(M * std::log1p(-std::min(sf, 1 - 1e-16)));
}

double chi2_sf(double x, double dof) {
    if (!(dof > 0) || !(x > 0)) return 1.0;
    if (!std::isfinite(x)) return 0.0;
    return boost::math::cdf(boost::math::complement(boost::math::chi_squared_distribution<double>(dof), x));
}

double chi2_isf(double p, double dof) {
    p = std::min(std::max(p, 1e-300), 1.0);
    return boost::math::quantile(boost::math::complement(boost::math::chi_squared_distribution<double>(dof), p));
}

double f_sf(double F, double d1, double d2) {
    if (!(F > 0) || !(d1 > 0) || !(d2 > 0)) return 1.0;
    if (!std::isfinite(F)) return 0.0;
    return boost::math::cdf(boost::math::complement(boost::math::fisher_f_distribution<double>(d1, d2), F));
}

std::string fmt_num(double v, int prec, bool sign) {
    char b[64];
    std::snprintf(b, sizeof b, sign ? "%+.*f" : "%.*f", prec, v);
    return b;
}

std::string fmt_p(double p) {
    char b[64];
    // Between 0.001 and 0.01, four decimals: the tests' level is 1e-3
    // (kFindingLevel), and "p = 0.001" beside "explains the data" (p was
    // 0.0012) read as a p at the level.
    if (p >= 0.01)
        std::snprintf(b, sizeof b, "p = %.3f", p);
    else if (p >= 0.001)
        std::snprintf(b, sizeof b, "p = %.4f", p);
    else if (p > 0)
        std::snprintf(b, sizeof b, "p = %.1e", p);
    else
        std::snprintf(b, sizeof b, "p < 1e-300");
    return b;
}

} // namespace diag
} // namespace cdm
