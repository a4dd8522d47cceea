// The fit's data: per-position means of the four readings, each with the
// variance of its mean (calib/fit/fit.h says why the fit works on means).
#include <algorithm>

#include "calib/fit/fit.h"

namespace cdm {

namespace {

// How much weight the pooled covariance gets beside a position's own: the
// empirical-Bayes prior of moderated variances (Smyth 2004), by moments.
// With one noise everywhere, z = s^2 / pooled at a position of n samples
// has mean 1 and variance 2 / (n - 1) (Gaussian noise); an excess V of the
// observed spread over that says the true variances differ between
// positions, as a scaled inverse chi-square of nu0 dof would, V = 2 / (nu0 - 4).
// nu0 is capped at 50 (the shrinkage's bias then 3.5 % at 10 samples) and at
// the pooled estimate's own dof; the most uneven cable decides. So a few
// positions that are really noisier (a worn track, a badly seated hole) keep
// much of their own variance instead of being flagged as failing.
double prior_weight(const Dataset &d, const Eigen::Matrix4d &pooled, double dof) {
    constexpr double kMaxPriorDof = 50;
    double nu0 = std::min(kMaxPriorDof, dof);
    for (int c = 0; c < 4; ++c) {
        if (!(pooled(c, c) > 0)) continue;
        double excess = 0;
        int m = 0;
        for (auto &p : d.pos)
            if (p.n > 1) {
                const double z = p.cov[c][c] / pooled(c, c);
                excess += (z - 1) * (z - 1) - 2.0 / (p.n - 1);
                ++m;
            }
        if (m < 2 || excess <= 0) continue;
        nu0 = std::min(nu0, 4 + 2 / (excess / m));
    }
    return std::max(0.0, nu0);
}

} // namespace

std::vector<PreparedPos> prepare(const Dataset &d) {
    // The readings' resolution per cable: the smallest step between distinct
    // values (the ADC count through the nominal scale; the CSV's last digit
    // for unquantised data), found as the dataset was read.
    const double *q = d.resolution;
    // Pooled within-position covariance, for positions measured once and
    // as the target each position's own is shrunk toward (below).
    Eigen::Matrix4d pooled = Eigen::Matrix4d::Zero();
    double dof = 0;
    for (auto &p : d.pos)
        if (p.n > 1) {
            for (int c = 0; c < 4; ++c)
                for (int k = 0; k < 4; ++k) pooled(c, k) += p.cov[c][k] * (p.n - 1);
            dof += p.n - 1;
        }
    if (dof > 0) pooled /= dof;
    const double prior_dof = prior_weight(d, pooled, dof);
    std::vector<PreparedPos> v;
    v.reserve(d.pos.size());
    for (auto &p : d.pos) {
        PreparedPos pp;
        pp.ref = Eigen::Vector3d(p.ref[0], p.ref[1], p.ref[2]);
        for (int c = 0; c < 4; ++c) {
            pp.mean(c) = p.mean[c];
            for (int k = 0; k < 4; ++k) pp.cov(c, k) = p.cov[c][k];
        }
        // A position's own covariance from few samples is itself noisy,
        // and weights 1/s^2 from it inflate every chi-square by
        // E[sigma^2/s^2] = nu/(nu - 2) (9/7 from 10 samples). The pots'
        // noise is the pot's, much the same over the workspace, so each
        // position's covariance (variances and cross-cable terms alike) is
        // shrunk toward the pooled one, as if the pooled estimate were
        // worth prior_dof samples' worth of degrees of freedom (at most 50:
        // 10 samples then weigh in with 59 dof, bias 3.5 %; 100 with 149,
        // 1.4 %; fewer where the positions' noise really differs, see
        // prior_weight). A convex combination of two covariances stays one.
        const Eigen::Matrix4d shrunk =
            p.n > 1 ? Eigen::Matrix4d(((p.n - 1) * pp.cov + prior_dof * pooled) / (p.n - 1 + prior_dof)) : pooled;
        pp.cov_mean = shrunk / p.n;
        for (int c = 0; c < 4; ++c) {
            const double var = shrunk(c, c);
            // Noise that spans several ADC steps dithers the quantisation
            // away in the mean; noise below half a step does not, and the
            // mean keeps the rounding error of variance q^2/12.
            const double q12 = q[c] * q[c] / 12;
            pp.var_mean(c) = var / p.n + (var < 3 * q12 ? q12 : 0.0);
            pp.var_mean(c) = std::max(pp.var_mean(c), 1e-10);
            pp.cov_mean(c, c) = pp.var_mean(c);
        }
        pp.n = p.n;
        pp.t_s = p.t_s; // lets time-dependent effects (drift) see acquisition order
        v.push_back(pp);
    }
    return v;
}

} // namespace cdm
