// See diag_eval.h.
#include "calib/diag_eval.h"

#include <limits>

namespace cdm {
namespace diag {

namespace {
Eigen::Matrix<double, 4, 3> reading_jacobian(const Model &m, const double p[3], double t_s) {
    // The model's own derivative (automatic differentiation through the
    // built-ins); NaN when a user effect fails, so nothing downstream
    // mistakes it for a number.
    Eigen::Matrix<double, 4, 3, Eigen::RowMajor> J;
    double y[4];
    if (m.readings_jacobian(p, t_s, y, J.data()) != 0) J.setConstant(std::numeric_limits<double>::quiet_NaN());
    return J;
}
} // namespace

// Per-position residuals by FK of the mean readings; per-sample statistics
// through the local linearisation e_s = res + Jp (l_s - mean), exact to
// second order in the noise (1e-4 mm at 0.05 mm noise).
Eval evaluate(const Model &m, const Dataset &d, const std::vector<PreparedPos> &pos) {
    Eval E;
    const size_t P = pos.size();
    E.res.assign(P, V3::Zero());
    E.Jp.assign(P, Eigen::Matrix<double, 3, 4>::Zero());
    E.var_mean.assign(P, V3::Constant(1e-6));
    E.ok.assign(P, 0);
    E.est.assign(P, V3::Zero());
    for (size_t j = 0; j < P; ++j) {
        double l[4] = {pos[j].mean(0), pos[j].mean(1), pos[j].mean(2), pos[j].mean(3)};
        double p[3];
        // At the position's acquisition time: effects that drift in time
        // (pot_drift) are undone as of when it was measured.
        if (m.position(l, pos[j].t_s, p, nullptr) != 0) {
            E.bad_samples += size_t(pos[j].n);
            continue;
        }
        double t[3];
        m.jig_to_device(pos[j].ref.data(), t);
        E.est[j] = V3(p[0], p[1], p[2]);
        E.res[j] = E.est[j] - V3(t[0], t[1], t[2]);
        auto J = reading_jacobian(m, p, pos[j].t_s);
        Eigen::Matrix3d H = J.transpose() * J;
        E.Jp[j] = H.inverse() * J.transpose();
        // Covariance of the mean readings: the samples' (cross-cable terms
        // included) over n, plus on the diagonal what prepare() added for
        // quantisation and single samples.
        Eigen::Matrix4d Cl = pos[j].cov / pos[j].n;
        for (int c = 0; c < 4; ++c) Cl(c, c) = std::max(Cl(c, c), pos[j].var_mean(c));
        Eigen::Matrix3d C = E.Jp[j] * Cl * E.Jp[j].transpose();
        for (int a = 0; a < 3; ++a) E.var_mean[j](a) = std::max(C(a, a), 1e-10);
        E.ok[j] = 1;
        for (int s = 0; s < pos[j].n; ++s) {
            const auto &ls = d.samples[pos[j].first + size_t(s)];
            Eigen::Vector4d dl(ls[0] - l[0], ls[1] - l[1], ls[2] - l[2], ls[3] - l[3]);
            V3 dev = E.Jp[j] * dl;
            for (int a = 0; a < 3; ++a) {
                E.err[a].add(E.res[j](a) + dev(a));
                E.within[a].add(dev(a));
            }
        }
    }
    return E;
}

// The seed's procedure, per sample: triangulation (eq. 1-3), optionally the
// ellipsoid (eq. 4) subtracted from x.
Eval evaluate_seed(const DeviceGeometry &g, const Dataset &d, const std::vector<PreparedPos> &pos,
                   const Ellipsoid *ell) {
    Eval E;
    const size_t P = pos.size();
    E.res.assign(P, V3::Zero());
    E.ok.assign(P, 0);
    E.est.assign(P, V3::Zero());
    E.var_mean.assign(P, V3::Constant(1e-6));
    E.Jp.assign(P, Eigen::Matrix<double, 3, 4>::Zero());
    for (size_t j = 0; j < P; ++j) {
        V3 sum = V3::Zero();
        int n = 0;
        for (int s = 0; s < pos[j].n; ++s) {
            const auto &ls = d.samples[pos[j].first + size_t(s)];
            double p[3];
            if (!triangulate(g, ls.data(), p)) {
                ++E.bad_samples;
                continue;
            }
            if (ell) p[0] -= ell->xc(p[1], p[2]);
            for (int a = 0; a < 3; ++a) E.err[a].add(p[a] - pos[j].ref(a));
            sum += V3(p[0], p[1], p[2]);
            ++n;
        }
        if (n == 0) continue;
        E.est[j] = sum / n;
        E.res[j] = E.est[j] - pos[j].ref;
        E.ok[j] = 1;
    }
    return E;
}

// The seed's eq. 5: the ellipsoid fitted to the x error of an evaluation
// over its estimated y, z, each position weighted by its sample count.
Ellipsoid ellipsoid_on(const Eval &E, const std::vector<PreparedPos> &pos) {
    std::vector<double> y, z, x, w;
    for (size_t j = 0; j < pos.size(); ++j)
        if (E.ok[j]) {
            y.push_back(E.est[j](1));
            z.push_back(E.est[j](2));
            x.push_back(E.res[j](0));
            w.push_back(pos[j].n);
        }
    return fit_ellipsoid(y, z, x, w);
}

} // namespace diag
} // namespace cdm
