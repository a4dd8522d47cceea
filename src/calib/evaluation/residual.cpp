// See residual.h.
#include "calib/evaluation/residual.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

std::vector<double> lomb(const std::vector<double> &t, const std::vector<double> &y, double f0, double df, size_t nf) {
    const size_t n = t.size();
    std::vector<double> P(nf, 0);
    if (n < 2) return P;
    double mean = 0, var = 0;
    for (double v : y) mean += v;
    mean /= double(n);
    for (double v : y) var += (v - mean) * (v - mean);
    var /= double(n - 1);
    if (!(var > 0)) return P;
    // Press & Rybicki's form of Lomb's formula: per frequency only four sums
    // over the points, S = sum y' sin wt, C = sum y' cos wt, S2 = sum sin 2wt,
    // C2 = sum cos 2wt (y' = y - mean); the offset tau and the fitted sine and
    // cosine's norms follow from them in closed form. Each point's e^{iwt}
    // steps from one frequency to the next by a fixed rotation e^{i dw t}
    // (one complex product, no sin/cos), and is recomputed exactly every
    // kReseed frequencies, so the rounding of the products never builds up
    // beyond ~kReseed ulps (1e-13 relative).
    constexpr size_t kReseed = 64;
    std::vector<double> zr(n), zi(n), rr(n), ri(n), yc(n);
    for (size_t k = 0; k < n; ++k) {
        yc[k] = y[k] - mean;
        const double a = 2 * M_PI * df * t[k];
        rr[k] = std::cos(a);
        ri[k] = std::sin(a);
    }
    for (size_t f = 0; f < nf; ++f) {
        if (f % kReseed == 0)
            for (size_t k = 0; k < n; ++k) {
                const double a = 2 * M_PI * (f0 + df * double(f)) * t[k];
                zr[k] = std::cos(a);
                zi[k] = std::sin(a);
            }
        double S = 0, C = 0, S2 = 0, C2 = 0;
        for (size_t k = 0; k < n; ++k) {
            const double c = zr[k], s = zi[k];
            C += yc[k] * c;
            S += yc[k] * s;
            C2 += c * c - s * s;
            S2 += 2 * s * c;
            // Next frequency: e^{i(w+dw)t} = e^{iwt} e^{i dw t}.
            zr[k] = c * rr[k] - s * ri[k];
            zi[k] = s * rr[k] + c * ri[k];
        }
        // tan(2 w tau) = S2 / C2; with 2 w tau = atan2(S2, C2):
        const double wt2 = std::atan2(S2, C2), cw = std::cos(wt2 / 2), sw = std::sin(wt2 / 2);
        const double c2t = std::cos(wt2), s2t = std::sin(wt2);
        const double ycos = C * cw + S * sw;   // sum y' cos w(t - tau)
        const double ysin = S * cw - C * sw;   // sum y' sin w(t - tau)
        const double r2 = C2 * c2t + S2 * s2t; // sum cos 2w(t - tau)
        const double cc = 0.5 * (double(n) + r2), ss = 0.5 * (double(n) - r2);
        P[f] = (cc > 0 && ss > 0) ? 0.5 * (ycos * ycos / cc + ysin * ysin / ss) / var : 0;
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
