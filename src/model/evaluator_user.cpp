// The evaluator's user effects (evaluator_impl.h): their central
// differences at one position and over many, chained onto the built-in
// Jacobian, and eval_batch.
//
// A geometry-aware effect (apply_geom) gets the cables' frames at the
// position each call is made at: the position's own for every call but the
// position steps, the frames at the moved position for those (so its
// position derivative includes what it reads from the geometry: the holder
// points, unit vectors and chords move with the position). The frames are
// those of the current parameter values, but they are not stepped when a
// Geometry-stage parameter (anchor_position, holder_geometry) is: the
// Jacobian leaves out the derivative of the effect's output through the
// frames with respect to those parameters (it keeps the one through the
// incoming values). Why the fit still lands on the right values: the
// residuals are computed exactly (the frames at the current values), so
// the fit's fixed point is where J'W r = 0 with J this Jacobian; the term
// left out is the derivative of a small correction (for the cable-sag
// example 3 sag / L per mm of anchor, ~1e-3 of the anchor's direct effect),
// which moves that point by the same small fraction of a residual that is
// noise where the model is right, and not at all where it fits the data
// exactly. Stepping every Geometry-stage parameter too would cost 2 x 24
// more calls per evaluation.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "model/evaluator_impl.h"

namespace cdm {

using namespace ev;

bool ev::finite_values(const EffectDesc &d, const double *Y, size_t n, const double *P, std::string *err) {
    for (size_t i = 0; i < n; ++i)
        for (int c = 0; c < 4; ++c)
            if (!std::isfinite(Y[4 * i + size_t(c)])) {
                if (err) {
                    char b[160];
                    std::snprintf(b, sizeof b, "\": non-finite %s of cable %d at (%.6g, %.6g, %.6g) mm",
                                  d.on_path ? "length" : "reading", c + 1, P[3 * i], P[3 * i + 1], P[3 * i + 2]);
                    *err = "user effect \"" + d.name + b;
                }
                return false;
            }
    return true;
}

bool ReadingEvaluator::Impl::user_one(size_t e, const Eigen::VectorXd &full, const double P[3], double t_s,
                                      const CableFrame *F, const Eigen::Vector4d &y, bool deriv,
                                      Eigen::Vector4d *out, std::string *err) const {
    const EffectDesc &d = *desc[e];
    const int np = int(d.params.size());
    double prm[kMaxUserParams];
    CableFrame Fk;
    for (int k = 0; k < user_calls(d, deriv); ++k) {
        const UserStep st = user_step(d, k);
        for (int a = 0; a < np; ++a) prm[a] = full(off[e] + a);
        double Pk[3] = {P[0], P[1], P[2]};
        double buf[4] = {y(0), y(1), y(2), y(3)};
        if (st.what == Moved::Param) prm[st.idx] += st.h;
        if (st.what == Moved::Position) Pk[st.idx] += st.h;
        if (st.what == Moved::Reading) buf[st.idx] += st.h;
        int rc;
        if (d.apply_geom) {
            if (st.what == Moved::Position) frame_at(full, Pk, t_s, Fk);
            const UserRows rows{1, Pk, &t_s, st.what == Moved::Position ? &Fk : F};
            rc = call_user_effect(d, prm, rows, buf);
        } else {
            rc = d.apply_one(prm, Pk, buf);
        }
        if (rc != 0) {
            if (err) *err = "user effect \"" + d.name + (d.apply_geom ? "\": apply_geom" : "\": apply") +
                            " returned non-zero";
            return false;
        }
        if (!finite_values(d, buf, 1, Pk, err)) return false;
        out[k] = Eigen::Vector4d(buf[0], buf[1], buf[2], buf[3]);
    }
    return true;
}

// User effects act on the readings (or the lengths): chain their
// central-difference derivatives (w.r.t. their parameters, the incoming
// values and the position) onto the Jacobian so far.
void ReadingEvaluator::Impl::chain(size_t e, const Eigen::Vector4d *out, const DPdj &dPdj, Eigen::Vector4d &y,
                                   Jac *J, Jac3 &dP) const {
    const EffectDesc &d = *desc[e];
    if (J) {
        Eigen::Matrix4d Dy;
        Eigen::Matrix<double, 4, 3> DP;
        for (int c = 0; c < 4; ++c) Dy.col(c) = (out[1 + 2 * c] - out[2 + 2 * c]) / (2 * kReadingStep);
        for (int k = 0; k < 3; ++k) DP.col(k) = (out[9 + 2 * k] - out[10 + 2 * k]) / (2 * kPositionStep);
        Eigen::Matrix<double, 4, Eigen::Dynamic> Jn = Dy * (*J);
        for (auto [je, first] : jig) {
            const int jn = int(desc[size_t(je)]->params.size());
            Jn.block(0, off[size_t(je)], 4, jn) += DP * dPdj.middleCols(first, jn);
        }
        for (int k = 0; k < int(d.params.size()); ++k)
            Jn.col(off[e] + k) += (out[15 + 2 * k] - out[16 + 2 * k]) / (2 * param_step(d, k));
        *J = Jn;
        dP = Dy * dP + DP;
    }
    y = out[0];
}

bool ReadingEvaluator::Impl::reading_users(const Eigen::VectorXd &full, const double P[3], double t_s,
                                           const CableFrame *F, const DPdj &dPdj, Eigen::Vector4d &y, Jac *J,
                                           Jac3 &dP, std::string *err) const {
    Eigen::Vector4d out[kMaxUserCalls];
    for (size_t e = 0; e < desc.size(); ++e) {
        if (desc[e]->stage != Stage::User || desc[e]->on_path) continue;
        if (!user_one(e, full, P, t_s, F, y, J != nullptr, out, err)) return false;
        chain(e, out, dPdj, y, J, dP);
    }
    return true;
}

bool ReadingEvaluator::Impl::user_rows(size_t e, const Eigen::VectorXd &full, size_t n, const double *P,
                                       const double *T, const CableFrame *F, const DPdj *dPdj, Eigen::Vector4d *y,
                                       Jac *J, Jac3 *dP, bool deriv, std::vector<double> &scratch,
                                       std::string *err) const {
    const EffectDesc &d = *desc[e];
    Eigen::Vector4d calls[kMaxUserCalls];
    if (!d.apply_batch && !d.apply_geom) {
        for (size_t i = 0; i < n; ++i) {
            if (!user_one(e, full, &P[3 * i], T[i], nullptr, y[i], deriv, calls, err)) return false;
            chain(e, calls, dPdj[i], y[i], J ? &J[i] : nullptr, dP[i]);
        }
        return true;
    }
    // Every call's rows, as user_one would make them one position at a
    // time: call k's values at scratch[4 n k ...], then the context's.
    const int nc = user_calls(d, deriv), np = int(d.params.size());
    scratch.resize(4 * n * size_t(nc) + (d.apply_geom ? user_scratch_size(n) : 0));
    std::vector<double> Pk(3 * n);
    std::vector<CableFrame> Fk(d.apply_geom ? n : 0);
    double prm[kMaxUserParams];
    for (int k = 0; k < nc && n > 0; ++k) {
        const UserStep st = user_step(d, k);
        for (int a = 0; a < np; ++a) prm[a] = full(off[e] + a);
        std::copy(P, P + 3 * n, Pk.begin());
        double *Y = &scratch[4 * n * size_t(k)];
        for (size_t i = 0; i < n; ++i) {
            for (int c = 0; c < 4; ++c) Y[4 * i + size_t(c)] = y[i](c);
            if (st.what == Moved::Position) Pk[3 * i + size_t(st.idx)] += st.h;
            if (st.what == Moved::Reading) Y[4 * i + size_t(st.idx)] += st.h;
        }
        if (st.what == Moved::Param) prm[st.idx] += st.h;
        const bool moved = d.apply_geom && st.what == Moved::Position;
        for (size_t i = 0; moved && i < n; ++i) frame_at(full, &Pk[3 * i], T[i], Fk[i]);
        const UserRows rows{n, Pk.data(), T, moved ? Fk.data() : F};
        const int rc = d.apply_geom ? call_user_effect(d, prm, rows, Y, scratch.data() + 4 * n * size_t(nc))
                                    : d.apply_batch(d.user, prm, n, Pk.data(), Y);
        if (rc != 0) {
            if (err) *err = "user effect \"" + d.name + (d.apply_geom ? "\": apply_geom" : "\": apply_batch") +
                            " returned non-zero";
            return false;
        }
        if (!finite_values(d, Y, n, Pk.data(), err)) return false;
    }
    for (size_t i = 0; i < n; ++i) {
        for (int k = 0; k < nc; ++k) calls[k] = Eigen::Map<const Eigen::Vector4d>(&scratch[4 * (n * size_t(k) + i)]);
        chain(e, calls, dPdj[i], y[i], J ? &J[i] : nullptr, dP[i]);
    }
    return true;
}

bool ReadingEvaluator::eval_batch(const Eigen::VectorXd &full, size_t n, const double *refs, const double *t_s,
                                  bool want_J, bool want_dydP, Batch &out, std::string *err) const {
    const Impl &I = *impl_;
    if (I.lay.has_path_user) return I.eval_batch_path(full, n, refs, t_s, want_J, want_dydP, out, err);
    out.y.resize(n);
    out.J.resize(want_J ? n : 0);
    out.dydP.resize(n);
    std::vector<double> P(3 * n);
    std::vector<DPdj> dPdj(n);
    const bool values_only = !want_J && !want_dydP && !I.lay.has_user;
    for (size_t i = 0; i < n; ++i)
        I.builtin(full, refs + 3 * i, t_s[i], &P[3 * i], dPdj[i], out.y[i], want_J ? &out.J[i] : nullptr,
                  out.dydP[i], values_only);
    std::vector<CableFrame> F(I.lay.has_geom ? n : 0);
    for (size_t i = 0; i < F.size(); ++i) I.frame_at(full, &P[3 * i], t_s[i], F[i]);
    for (size_t e = 0; e < I.desc.size() && I.lay.has_user; ++e) {
        if (I.desc[e]->stage != Stage::User) continue;
        if (!I.user_rows(e, full, n, P.data(), t_s, F.data(), dPdj.data(), out.y.data(),
                         want_J ? out.J.data() : nullptr, out.dydP.data(), want_J, out.scratch, err))
            return false;
    }
    return true;
}

} // namespace cdm
