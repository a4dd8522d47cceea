// Distribution tails and running moments for the diagnosis. The tails come
// from Boost.Math's complementary functions, so a tiny p-value is exact (down
// to the smallest double) and never printed as 0 from cancellation in 1 - cdf.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>

#include <nlohmann/json.hpp>

namespace cdm {
namespace diag {

double normal_sf(double z);             // P(Z > z), Z standard normal
double chi2_sf(double x, double dof);   // P(X > x), X ~ chi-square(dof)
double chi2_isf(double p, double dof);  // x with P(X > x) = p
double f_sf(double F, double d1, double d2); // P(X > F), X ~ F(d1, d2)
// The probability that the largest of M independent tests each passing
// with probability sf passes: 1 - (1 - sf)^M, the union bound M sf (exact
// in the tail) once sf is below 1e-12.
double false_alarm(double sf, double M);

// Numbers in the diagnosis' words: fixed decimals (sign: a leading + for
// positive values), and a p-value ("p = 0.042", "p = 3.2e-05", "p < 1e-300").
std::string fmt_num(double v, int prec, bool sign = false);
std::string fmt_p(double p);

// Weighted running moments of one error component.
struct Acc {
    double n = 0, s = 0, ss = 0, mx = 0;
    void add(double v, double w = 1) {
        n += w;
        s += w * v;
        ss += w * v * v;
        mx = std::max(mx, std::fabs(v));
    }
    // Moments of a group of values added at once (their count, sum and sum
    // of squares); the maximum is left to add_extreme().
    void add_moments(double cnt, double sum, double sumsq) {
        n += cnt;
        s += sum;
        ss += sumsq;
    }
    void add_extreme(double v) { mx = std::max(mx, std::fabs(v)); }
    nlohmann::json to_json() const {
        const double mean = n > 0 ? s / n : 0;
        const double var = n > 1 ? std::max(0.0, (ss - n * mean * mean) / (n - 1)) : 0;
        return {{"mean", mean}, {"std", std::sqrt(var)}, {"rms", n > 0 ? std::sqrt(ss / n) : 0}, {"max", mx}};
    }
};
inline nlohmann::json stats3(const Acc a[3]) {
    return {{"x", a[0].to_json()}, {"y", a[1].to_json()}, {"z", a[2].to_json()}};
}

} // namespace diag
} // namespace cdm
