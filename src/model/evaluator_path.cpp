// The evaluator for a model with a user effect on the cable's path
// (CDM_EFFECT_STAGE_PATH): the kernel in two halves, the user effects on
// the lengths between them. The first half (Jig, Geometry, Path) is
// differentiated as the whole kernel is (automatic differentiation over
// the position and the cable's parameters, evaluator.cpp); the path's user
// effects chain their central differences onto the lengths' Jacobian
// (evaluator_user.cpp); the second half (Transfer) is differentiated with
// the incoming length as one more variable, so that d reading / d length
// (1 + cable_gain, the stretch, the non-linearity...) carries the lengths'
// Jacobian, and the Transfer parameters' own derivatives are added to it.
// A model without such an effect never comes here (eval and eval_batch
// keep the one-piece kernel, whose numbers are unchanged).
#include "model/evaluator_impl.h"

namespace cdm {

using namespace ev;

void ReadingEvaluator::Impl::frame_at(const Eigen::VectorXd &full, const double P[3], double t_s, CableFrame &F,
                                      double *len) const {
    Sample<double> s;
    for (int k = 0; k < 3; ++k) s.P[k] = P[k];
    s.t_s = t_s;
    double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    CablePoints pts;
    for (int i = 0; i < 4; ++i) {
        for (int sl = 0; sl < lay.cable.nslots; ++sl) q[sl] = full(col[size_t(i)][size_t(sl)]);
        const double l = cable_path<double>(m.geometry(), i, s, lay.cable, q, &pts);
        F.set(i, pts);
        if (len) len[i] = l;
    }
}

void ReadingEvaluator::Impl::transfer(const Eigen::VectorXd &full, const double P[3], double t_s, const DPdj &dPdj,
                                      const Eigen::Vector4d &len, const Jac &Jl, const Jac3 &dPl, Eigen::Vector4d &y,
                                      Jac *J, Jac3 &dP, bool deriv) const {
    const int ns = lay.cable.nslots;
    if (!deriv) {
        Sample<double> s;
        for (int k = 0; k < 3; ++k) s.P[k] = P[k];
        s.t_s = t_s;
        double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
        for (int i = 0; i < 4; ++i) {
            for (int sl = 0; sl < ns; ++sl) q[sl] = full(col[size_t(i)][size_t(sl)]);
            y(i) = cable_transfer<double>(i, s, lay.cable, q, len(i));
        }
        return;
    }
    // Derivatives: the position (0..2), the incoming length (3), the
    // cable's parameters (4...); fixed length, on the stack.
    constexpr int N = kMaxLocal + 1;
    using AD = Eigen::AutoDiffScalar<Eigen::Matrix<double, N, 1>>;
    Sample<AD> s;
    for (int k = 0; k < 3; ++k) s.P[k] = AD(P[k], N, k);
    s.t_s = t_s;
    AD q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    for (int sl = 0; sl < ns; ++sl) q[sl] = AD(0.0, N, 4 + sl);
    if (J) J->setZero(4, n);
    for (int i = 0; i < 4; ++i) {
        for (int sl = 0; sl < ns; ++sl) q[sl].value() = full(col[size_t(i)][size_t(sl)]);
        const AD r = cable_transfer<AD>(i, s, lay.cable, q, AD(len(i), N, 3));
        y(i) = r.value();
        const auto &d = r.derivatives();
        const Eigen::RowVector3d dTdP(d(0), d(1), d(2));
        dP.row(i) = dTdP + d(3) * dPl.row(i);
        if (!J) continue;
        J->row(i) = d(3) * Jl.row(i);
        for (auto [e, first] : jig) {
            const int np = int(desc[size_t(e)]->params.size());
            J->block(i, off[size_t(e)], 1, np) += dTdP * dPdj.middleCols(first, np);
        }
        for (int sl = 0; sl < ns; ++sl) (*J)(i, col[size_t(i)][size_t(sl)]) += d(4 + sl);
    }
}

bool ReadingEvaluator::Impl::eval_path(const Eigen::VectorXd &full, const double ref[3], double t_s,
                                       Eigen::Vector4d &y, Jac *J, Jac3 *dydP, std::string *err) const {
    const bool deriv = J || dydP;
    double P[3];
    DPdj dPdj;
    Eigen::Vector4d len;
    Jac Jl;
    Jac3 dPl, dP;
    CableFrame F;
    builtin_path(full, ref, t_s, P, dPdj, len, Jl, dPl, F, deriv);
    Eigen::Vector4d out[kMaxUserCalls];
    for (size_t e = 0; e < desc.size(); ++e) {
        if (desc[e]->stage != Stage::User || !desc[e]->on_path) continue;
        if (!user_one(e, full, P, t_s, &F, len, deriv, out, err)) return false;
        chain(e, out, dPdj, len, deriv ? &Jl : nullptr, dPl);
    }
    transfer(full, P, t_s, dPdj, len, Jl, dPl, y, J, dP, deriv);
    if (!reading_users(full, P, t_s, &F, dPdj, y, J, dP, err)) return false;
    if (dydP) *dydP = dP;
    return true;
}

bool ReadingEvaluator::Impl::eval_batch_path(const Eigen::VectorXd &full, size_t n, const double *refs,
                                             const double *t_s, bool want_J, bool want_dydP, Batch &out,
                                             std::string *err) const {
    const bool deriv = want_J || want_dydP;
    out.y.resize(n);
    out.J.resize(want_J ? n : 0);
    out.dydP.resize(n);
    std::vector<double> P(3 * n);
    std::vector<DPdj> dPdj(n);
    std::vector<Eigen::Vector4d> len(n);
    std::vector<Jac> Jl(n);
    std::vector<Jac3> dPl(n);
    std::vector<CableFrame> F(n);
    for (size_t i = 0; i < n; ++i)
        builtin_path(full, refs + 3 * i, t_s[i], &P[3 * i], dPdj[i], len[i], Jl[i], dPl[i], F[i], deriv);
    for (size_t e = 0; e < desc.size(); ++e) {
        if (desc[e]->stage != Stage::User || !desc[e]->on_path) continue;
        if (!user_rows(e, full, n, P.data(), t_s, F.data(), dPdj.data(), len.data(), deriv ? Jl.data() : nullptr,
                       dPl.data(), deriv, out.scratch, err))
            return false;
    }
    for (size_t i = 0; i < n; ++i)
        transfer(full, &P[3 * i], t_s[i], dPdj[i], len[i], Jl[i], dPl[i], out.y[i], want_J ? &out.J[i] : nullptr,
                 out.dydP[i], deriv);
    for (size_t e = 0; e < desc.size(); ++e) {
        if (desc[e]->stage != Stage::User || desc[e]->on_path) continue;
        if (!user_rows(e, full, n, P.data(), t_s, F.data(), dPdj.data(), out.y.data(),
                       want_J ? out.J.data() : nullptr, out.dydP.data(), want_J, out.scratch, err))
            return false;
    }
    return true;
}

} // namespace cdm
