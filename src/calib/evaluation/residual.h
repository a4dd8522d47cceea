// Residual analysis beyond the plate: periodograms (Lomb-Scargle) for
// periodic errors and polynomial trends against physical variables.
#pragma once

#include <cstddef>
#include <vector>

namespace cdm {
namespace diag {

// Lomb-Scargle periodogram of y(t) (mean removed), normalised by the variance,
// at the nf frequencies f0 + k df (k = 0..nf-1, cycles per unit of t).
std::vector<double> lomb(const std::vector<double> &t, const std::vector<double> &y, double f0, double df, size_t nf);
// y minus its least-squares quadratic in t.
void detrend_quadratic(const std::vector<double> &t, std::vector<double> &y);

// Least-squares polynomial fit of degree deg; returns the F-test p-value
// against a constant and the fitted curve's range.
struct Trend {
    double p = 1, range = 0, r2 = 0;
};
Trend poly_trend(const std::vector<double> &x, const std::vector<double> &y, const std::vector<double> &w, int deg);

} // namespace diag
} // namespace cdm
