// The seed's ellipsoid (eq. 4-5), fitted in position space (see fit.h).
#include <algorithm>
#include <cmath>

#include <nlopt.h>

#include "calib/fit/fit.h"

namespace cdm {

double Ellipsoid::xc(double y, double z) const {
    return L * (1.0 - std::sqrt(1.0 + y * y / (M * M) + z * z / (N * N)));
}

namespace {
struct EllData {
    const std::vector<double> *y, *z, *e, *w;
    double Ls, as, bs; // scales
};
double ell_sse(const double *v, const EllData &d) {
    const double L = v[0] * d.Ls, a = std::fabs(v[1]) * d.as, b = std::fabs(v[2]) * d.bs;
    double s = 0;
    for (size_t j = 0; j < d.y->size(); ++j) {
        const double yy = (*d.y)[j], zz = (*d.z)[j];
        const double xc = L * (1.0 - std::sqrt(1.0 + a * yy * yy + b * zz * zz));
        const double r = (*d.e)[j] - xc;
        s += (*d.w)[j] * r * r;
    }
    return s;
}
double ell_obj(unsigned, const double *v, double *, void *data) { return ell_sse(v, *static_cast<EllData *>(data)); }
} // namespace

Ellipsoid fit_ellipsoid(const std::vector<double> &ye, const std::vector<double> &ze, const std::vector<double> &xerr,
                        const std::vector<double> &w) {
    // Start: the paraboloid limit, x_err = cy*y^2 + cz*z^2 (linear least
    // squares, no intercept: eq. 4 is zero at the centre).
    Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
    Eigen::Vector2d b = Eigen::Vector2d::Zero();
    for (size_t j = 0; j < ye.size(); ++j) {
        Eigen::Vector2d f(ye[j] * ye[j], ze[j] * ze[j]);
        A += w[j] * f * f.transpose();
        b += w[j] * f * xerr[j];
    }
    Eigen::Vector2d c = A.ldlt().solve(b);
    Ellipsoid best;
    best.L = 0;
    if (!c.allFinite()) return best;
    // x_c ~ -L/2 (a y^2 + b z^2): one sign for both axes (an ellipsoid);
    // an axis that wants the other sign starts flat.
    const double sgn = (c(0) + c(1)) <= 0 ? 1.0 : -1.0;
    const double L0 = sgn * 5000.0;
    double a0 = std::max(-2 * c(0) / L0, 1e-12), b0 = std::max(-2 * c(1) / L0, 1e-12);
    EllData d{&ye, &ze, &xerr, &w, std::fabs(L0), a0, b0};
    double v[3] = {sgn, 1.0, 1.0};
    nlopt_opt o = nlopt_create(NLOPT_LN_BOBYQA, 3);
    nlopt_set_min_objective(o, ell_obj, &d);
    double lb[3] = {-100, 0, 0}, ub[3] = {100, 1e3, 1e3};
    nlopt_set_lower_bounds(o, lb);
    nlopt_set_upper_bounds(o, ub);
    nlopt_set_xtol_rel(o, 1e-10);
    nlopt_set_maxeval(o, 4000);
    double f;
    nlopt_optimize(o, v, &f);
    nlopt_destroy(o);
    const double zero_sse = [&] {
        double s = 0;
        for (size_t j = 0; j < ye.size(); ++j) s += w[j] * xerr[j] * xerr[j];
        return s;
    }();
    // Eq. 4 contains "no compensation" (L = 0): never return worse than that.
    if (!(ell_sse(v, d) < zero_sse)) return best;
    best.L = v[0] * d.Ls;
    const double a = std::fabs(v[1]) * d.as, bb = std::fabs(v[2]) * d.bs;
    best.M = a > 0 ? 1.0 / std::sqrt(a) : 1e12;
    best.N = bb > 0 ? 1.0 / std::sqrt(bb) : 1e12;
    return best;
}

} // namespace cdm
