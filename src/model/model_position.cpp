// Forward kinematics: the position whose predicted readings match the
// measured lengths. Runs in the driver's reader thread: no allocation for
// built-in effects (fixed-size AutoDiffScalar over the position, parameter
// blocks on the stack).
#include <cmath>

#include "model/model_impl.h"
#include "model/triangulate.h"

namespace cdm {

namespace {

using AD3 = Eigen::AutoDiffScalar<Eigen::Matrix<double, 3, 1>>;

// The readings at x and their 4x3 Jacobian: forward-mode AD over the position
// for the built-ins, central differences through user effects. False when a
// user effect's apply fails.
bool readings_and_jacobian(const Model &m, const Model::Impl &I, const double x[3], double t_s,
                           Eigen::Matrix<double, 4, 1> &y, Eigen::Matrix<double, 4, 3> &J) {
    if (!I.lay.has_user) {
        AD3 q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
        Sample<AD3> s;
        for (int k = 0; k < 3; ++k) s.P[k] = AD3(x[k], 3, k);
        s.t_s = t_s;
        for (int i = 0; i < 4; ++i) {
            I.gather(i, q);
            AD3 r = cable_reading<AD3>(I.g, i, s, I.lay.cable, q);
            y(i) = r.value();
            J.row(i) = r.derivatives().transpose();
        }
        return true;
    }
    double yv[4];
    if (m.readings(x, t_s, yv) != 0) return false;
    for (int i = 0; i < 4; ++i) y(i) = yv[i];
    for (int k = 0; k < 3; ++k) {
        double xp[3] = {x[0], x[1], x[2]}, xm[3] = {x[0], x[1], x[2]};
        const double h = 1e-4;
        xp[k] += h;
        xm[k] -= h;
        double yp[4], ym[4];
        if (m.readings(xp, t_s, yp) != 0 || m.readings(xm, t_s, ym) != 0) return false;
        for (int i = 0; i < 4; ++i) J(i, k) = (yp[i] - ym[i]) / (2 * h);
    }
    return true;
}

} // namespace

// Position-stage corrections at x, and their Jacobian (3x3) when asked.
// False when a Position-stage effect has more parameters than the stack
// buffer holds (a new built-in that needs a larger kMaxPositionParams).
constexpr size_t kMaxPositionParams = 8;
bool fk_correct(const Model::Impl &I, double x[3], Eigen::Matrix3d *D) {
    const EffectParams<double> pd = I.whole_params();
    if (!D) {
        position_map<double>(pd, x);
        return true;
    }
    // The corrections' parameters as AD constants, on the stack.
    AD3 store[kBuiltinCount][kMaxPositionParams];
    EffectParams<AD3> pa{};
    for (int id = 0; id < kBuiltinCount; ++id) {
        const int e = I.lay.idx[size_t(id)];
        if (e < 0 || I.effects[size_t(e)].desc->stage != Stage::Position) continue;
        const auto &p = I.effects[size_t(e)].p;
        if (p.size() > kMaxPositionParams) return false;
        for (size_t k = 0; k < p.size(); ++k) store[id][k] = AD3(p[k]);
        pa[size_t(id)] = store[id];
    }
    AD3 xa[3];
    for (int k = 0; k < 3; ++k) xa[k] = AD3(x[k], 3, k);
    position_map<AD3>(pa, xa);
    for (int k = 0; k < 3; ++k) {
        x[k] = xa[k].value();
        D->row(k) = xa[k].derivatives().transpose();
    }
    return true;
}

void fk_fallback_start(const DeviceGeometry &g, const double lengths[4], double x[3]) {
    const double a = g.a_mm, b = g.b_mm, mm = g.m_mm;
    const double R1 = lengths[0] * lengths[0], R2 = lengths[1] * lengths[1], R3 = lengths[2] * lengths[2],
                 R4 = lengths[3] * lengths[3];
    x[1] = ((R3 - R1) + (R4 - R2)) / (4.0 * (2.0 * a - mm));
    x[2] = ((R1 - R2) + (R3 - R4)) / (4.0 * (2.0 * b - mm));
    x[0] = 50.0;
}

int fk_step(const double lengths[4], const Eigen::Matrix<double, 4, 1> &y, const Eigen::Matrix<double, 4, 3> &J,
            double x[3]) {
    Eigen::Matrix<double, 4, 1> r;
    for (int i = 0; i < 4; ++i) r(i) = lengths[i] - y(i);
    if (!r.allFinite() || !J.allFinite()) return -1;
    Eigen::Matrix3d H = J.transpose() * J;
    Eigen::Vector3d dx = H.ldlt().solve(J.transpose() * r);
    if (!dx.allFinite()) return -1;
    for (int k = 0; k < 3; ++k) x[k] += dx(k);
    return dx.norm() < kFkTolerance ? 1 : 0;
}

int Model::readings_jacobian(const double p[3], double t_s, double out[4], double dr_dp[12]) const {
    Eigen::Matrix<double, 4, 1> y;
    Eigen::Matrix<double, 4, 3> J;
    if (!readings_and_jacobian(*this, *impl_, p, t_s, y, J)) return -1;
    for (int i = 0; i < 4; ++i) {
        out[i] = y(i);
        for (int k = 0; k < 3; ++k) dr_dp[3 * i + k] = J(i, k);
    }
    return 0;
}

int Model::position(const double lengths[4], double t_s, double p[3], double dp_dl[12]) const {
    const Impl &m = *impl_;
    for (int i = 0; i < 4; ++i)
        if (!std::isfinite(lengths[i])) return -1;
    double x[3];
    const bool tri = triangulate(m.g, lengths, x);
    Eigen::Matrix<double, 4, 3> J;
    Eigen::Matrix<double, 4, 1> y;
    if (!m.lay.reading_effects) {
        if (!tri) return -1;
    } else {
        if (!tri) {
            // Effects can push the readings past the nominal spheres' reach:
            // start from eq. (1)-(2) at mid-workspace height instead.
            fk_fallback_start(m.g, lengths, x);
        }
        // Gauss-Newton on the four readings.
        bool ok = false;
        for (int it = 0; it < kFkIterations; ++it) {
            if (!readings_and_jacobian(*this, m, x, t_s, y, J)) return -1;
            const int st = fk_step(lengths, y, J, x);
            if (st < 0) return -1;
            if (st > 0) {
                ok = true;
                break;
            }
        }
        if (!ok || !(x[0] > 0) || !std::isfinite(x[0] + x[1] + x[2])) return -1;
    }
    Eigen::Matrix<double, 3, 4> dxdl;
    if (dp_dl && !m.lay.reading_effects) {
        // The nominal model's position is the triangulation itself.
        using AD4 = Eigen::AutoDiffScalar<Eigen::Matrix<double, 4, 1>>;
        AD4 R[4], q[3];
        for (int i = 0; i < 4; ++i) R[i] = AD4(lengths[i], 4, i);
        if (!triangulate_t<AD4>(m.g, R, q)) return -1;
        for (int k = 0; k < 3; ++k) dxdl.row(k) = q[k].derivatives().transpose();
    } else if (dp_dl) {
        // At the solution the readings match the lengths in the least-squares
        // sense: dx/dl = (J'J)^-1 J' (exact where the residual vanishes).
        if (!readings_and_jacobian(*this, m, x, t_s, y, J)) return -1;
        Eigen::Matrix3d H = J.transpose() * J;
        dxdl = H.ldlt().solve(J.transpose());
    }
    Eigen::Matrix3d D;
    if (!fk_correct(m, x, dp_dl ? &D : nullptr)) return -1;
    if (!std::isfinite(x[0] + x[1] + x[2])) return -1;
    if (dp_dl) {
        Eigen::Matrix<double, 3, 4> G = D * dxdl;
        if (!G.allFinite()) return -1;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 4; ++c) dp_dl[4 * r + c] = G(r, c);
    }
    for (int k = 0; k < 3; ++k) p[k] = x[k];
    return 0;
}

} // namespace cdm
