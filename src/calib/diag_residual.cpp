// See diag_residual.h.
#include "calib/diag_residual.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

#include "calib/diag_stats.h"

namespace cdm {
namespace diag {

std::vector<double> lomb(const std::vector<double> &t, const std::vector<double> &y, const std::vector<double> &freqs) {
    const size_t n = t.size();
    double mean = 0, var = 0;
    for (double v : y) mean += v;
    mean /= double(n);
    for (double v : y) var += (v - mean) * (v - mean);
    var /= double(n - 1);
    std::vector<double> P(freqs.size(), 0);
    for (size_t f = 0; f < freqs.size(); ++f) {
        const double w = 2 * M_PI * freqs[f];
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
        P[f] = var > 0 ? 0.5 * (yc * yc / cc + ys * ys / ss) / var : 0;
    }
    return P;
}

void detrend_quadratic(const std::vector<double> &t, std::vector<double> &y) {
    const size_t n = t.size();
    if (n < 4) return;
    double lo = *std::min_element(t.begin(), t.end()), hi = *std::max_element(t.begin(), t.end());
    const double span = hi > lo ? hi - lo : 1.0;
    Eigen::MatrixXd A(n, 3);
    Eigen::VectorXd b(n);
    for (size_t k = 0; k < n; ++k) {
        const double u = (t[k] - lo) / span;
        A(long(k), 0) = 1;
        A(long(k), 1) = u;
        A(long(k), 2) = u * u;
        b(long(k)) = y[k];
    }
    Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
    Eigen::VectorXd r = b - A * c;
    for (size_t k = 0; k < n; ++k) y[k] = r(long(k));
}

Trend poly_trend(const std::vector<double> &x, const std::vector<double> &y, const std::vector<double> &w, int deg) {
    const size_t n = x.size();
    Trend t;
    if (n < size_t(deg + 3)) return t;
    double xm = 0, sw = 0;
    for (size_t k = 0; k < n; ++k) {
        xm += w[k] * x[k];
        sw += w[k];
    }
    xm /= sw;
    double xs = 0;
    for (size_t k = 0; k < n; ++k) xs = std::max(xs, std::fabs(x[k] - xm));
    if (xs == 0) return t;
    Eigen::MatrixXd A(n, deg + 1);
    Eigen::VectorXd b(n), sq(n);
    for (size_t k = 0; k < n; ++k) {
        const double u = (x[k] - xm) / xs, s = std::sqrt(w[k]);
        for (int d = 0; d <= deg; ++d) A(long(k), d) = s * std::pow(u, d);
        b(long(k)) = s * y[k];
    }
    Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
    const double rss = (A * c - b).squaredNorm();
    double mean = 0;
    for (size_t k = 0; k < n; ++k) mean += w[k] * y[k];
    mean /= sw;
    double tss = 0;
    for (size_t k = 0; k < n; ++k) tss += w[k] * (y[k] - mean) * (y[k] - mean);
    if (tss <= 0) return t;
    const double F = ((tss - rss) / deg) / (rss / double(n - size_t(deg) - 1));
    t.p = f_sf(F, deg, double(n) - deg - 1);
    t.r2 = 1 - rss / tss;
    double lo = INFINITY, hi = -INFINITY;
    for (size_t k = 0; k < n; ++k) {
        double u = (x[k] - xm) / xs, v = 0;
        for (int d = 0; d <= deg; ++d) v += c(d) * std::pow(u, d);
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    t.range = hi - lo;
    return t;
}

} // namespace diag
} // namespace cdm
