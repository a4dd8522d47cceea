// The fit's data: per-position means of the four readings, each with the
// variance of its mean (calib/fit.h says why the fit works on means).
#include <algorithm>

#include "calib/fit.h"

namespace cdm {

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
        // worth kPriorDof samples' worth of degrees of freedom: 10 samples
        // then weigh in with 59 dof (bias 3.5 %), 100 with 149 (1.4 %), and
        // a position that really is noisier still shows it. A convex
        // combination of two covariance matrices stays one.
        constexpr double kPriorDof = 50;
        const Eigen::Matrix4d shrunk =
            p.n > 1 ? Eigen::Matrix4d(((p.n - 1) * pp.cov + kPriorDof * pooled) / (p.n - 1 + kPriorDof)) : pooled;
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
