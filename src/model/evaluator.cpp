// See evaluator.h.
#include "model/evaluator_impl.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace cdm {

using namespace ev;

ReadingEvaluator::Impl::Impl(const Model &m_) : m(m_) {
    for (size_t e = 0; e < m.effect_count(); ++e) desc.push_back(&m.effect_desc(e));
    lay = build_layout(desc);
    for (size_t e = 0; e < desc.size(); ++e) {
        if (desc[e]->stage == Stage::Position) {
            off.push_back(-1);
            continue;
        }
        off.push_back(n);
        if (desc[e]->stage == Stage::Jig) {
            jig.emplace_back(int(e), njig);
            njig += int(desc[e]->params.size());
        }
        n += int(desc[e]->params.size());
    }
    if (njig > kMaxJig) throw std::logic_error("ReadingEvaluator: more Jig-stage parameters than kMaxJig");
    for (int i = 0; i < 4; ++i)
        for (int s = 0; s < lay.cable.nslots; ++s)
            col[size_t(i)][size_t(s)] =
                off[size_t(lay.slot_effect[size_t(i)][size_t(s)])] + lay.slot_param[size_t(i)][size_t(s)];
}

void ReadingEvaluator::Impl::jig_position(const Eigen::VectorXd &full, const double ref[3], double P[3],
                                          DPdj &dPdj) const {
    if (jig.empty()) { // jig_map is the identity: no Jig-stage effect
        for (int k = 0; k < 3; ++k) P[k] = ref[k];
        dPdj.resize(3, 0);
        return;
    }
    ADJ store[kMaxJig];
    EffectParams<ADJ> p{};
    for (auto [e, first] : jig) {
        const int np = int(desc[size_t(e)]->params.size());
        for (int k = 0; k < np; ++k) store[first + k] = ADJ(full(off[size_t(e)] + k), njig, first + k);
        p[size_t(desc[size_t(e)]->builtin_id)] = store + first;
    }
    ADJ x[3];
    for (int k = 0; k < 3; ++k) {
        x[k] = ADJ(ref[k]);
        x[k].derivatives().setZero(njig);
    }
    jig_map<ADJ>(p, x);
    dPdj.resize(3, njig);
    for (int k = 0; k < 3; ++k) {
        P[k] = x[k].value();
        if (njig > 0) dPdj.row(k) = x[k].derivatives().transpose();
    }
}

ReadingEvaluator::ReadingEvaluator(const Model &m) : impl_(new Impl(m)) {}
ReadingEvaluator::~ReadingEvaluator() { delete impl_; }
int ReadingEvaluator::size() const { return impl_->n; }
int ReadingEvaluator::offset(size_t e) const { return impl_->off.at(e); }
Eigen::VectorXd ReadingEvaluator::current() const {
    Eigen::VectorXd v(impl_->n);
    for (size_t e = 0; e < impl_->desc.size(); ++e) {
        if (impl_->off[e] < 0) continue;
        const auto &p = impl_->m.effect_params(e);
        for (size_t k = 0; k < p.size(); ++k) v(impl_->off[e] + int(k)) = p[k];
    }
    return v;
}

namespace {
// The cable kernel with derivatives of a fixed length N >= np + the
// model's cable slots (the rest stay zero): Eigen then keeps each derivative
// vector in registers and on the stack, where a dynamically sized one (even
// with a fixed maximum) copies through memcpy on every temporary and loops
// over a run-time length. The derivative vector holds the first np
// position coordinates (0, 1 or 3: only those asked for are carried), then
// the cable's parameters. Each entry is computed on its own (forward mode
// is element-wise), so the values and derivatives are those of the
// dynamic form whatever N and np (the padding entries only ever hold zeros).
template <int N, bool Path>
void cable_jacobians(const Model &m, const ModelLayout &lay, const std::array<std::array<int, kMaxCableSlots>, 4> &col,
                     const Eigen::VectorXd &full, const double P[3], double t_s, int np, Eigen::Vector4d &y,
                     Eigen::Matrix<double, 4, 3> &dP, Eigen::Matrix<double, 4, kMaxCableSlots> &dq) {
    using AD = Eigen::AutoDiffScalar<Eigen::Matrix<double, N, 1>>;
    Sample<AD> s;
    for (int k = 0; k < 3; ++k) s.P[k] = k < np ? AD(P[k], N, k) : AD(P[k], Eigen::Matrix<double, N, 1>::Zero());
    s.t_s = t_s;
    // Each slot's derivative is the same unit vector for the four cables:
    // seeded once, then only the values change from cable to cable (the
    // seeding was a fifth of the kernel's time when done per cable).
    AD q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    const int ns = lay.cable.nslots;
    for (int sl = 0; sl < ns; ++sl) q[sl] = AD(0.0, N, np + sl);
    dP.setZero();
    for (int i = 0; i < 4; ++i) {
        for (int sl = 0; sl < ns; ++sl) q[sl].value() = full(col[size_t(i)][size_t(sl)]);
        const AD r = Path ? cable_path<AD>(m.geometry(), i, s, lay.cable, q)
                          : cable_reading<AD>(m.geometry(), i, s, lay.cable, q);
        y(i) = r.value();
        const auto &d = r.derivatives();
        for (int k = 0; k < np; ++k) dP(i, k) = d(k);
        for (int sl = 0; sl < ns; ++sl) dq(i, sl) = d(np + sl);
    }
}

// cable_jacobians at the smallest N that holds nloc derivatives.
void cable_jacobians_n(int nloc, const Model &m, const ModelLayout &lay,
                       const std::array<std::array<int, kMaxCableSlots>, 4> &col, const Eigen::VectorXd &full,
                       const double P[3], double t_s, int np, Eigen::Vector4d &y, Eigen::Matrix<double, 4, 3> &dP,
                       Eigen::Matrix<double, 4, kMaxCableSlots> &dq) {
    if (nloc <= 2)
        cable_jacobians<2, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
    else if (nloc <= 4)
        cable_jacobians<4, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
    else if (nloc <= 6)
        cable_jacobians<6, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
    else if (nloc <= 8)
        cable_jacobians<8, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
    else if (nloc <= 12)
        cable_jacobians<12, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
    else if (nloc <= 16)
        cable_jacobians<16, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
    else
        cable_jacobians<kMaxLocal, false>(m, lay, col, full, P, t_s, np, y, dP, dq);
}
} // namespace

void ReadingEvaluator::Impl::builtin(const Eigen::VectorXd &full, const double ref[3], double t_s, double P[3],
                                     DPdj &dPdj, Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J,
                                     Eigen::Matrix<double, 4, 3> &dP, bool values_only, int npos,
                                     bool path_only) const {
    jig_position(full, ref, P, dPdj);
    if (J) J->setZero(4, n);
    if (values_only) {
        // Values only (a trial step of the fit, a chi-square): the same
        // arithmetic as the values of the differentiated kernel.
        Sample<double> s;
        for (int k = 0; k < 3; ++k) s.P[k] = P[k];
        s.t_s = t_s;
        double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
        for (int i = 0; i < 4; ++i) {
            for (int sl = 0; sl < lay.cable.nslots; ++sl) q[sl] = full(col[size_t(i)][size_t(sl)]);
            y(i) = path_only ? cable_path<double>(m.geometry(), i, s, lay.cable, q)
                             : cable_reading<double>(m.geometry(), i, s, lay.cable, q);
        }
        return;
    }
    // The position derivatives the caller and the chain need: all three
    // for a Jig-stage effect's chain rule or a user effect's, else those
    // asked for.
    const int npd = (njig > 0 || lay.has_user || path_only) ? 3 : npos;
    const int nloc = npd + lay.cable.nslots;
    Eigen::Matrix<double, 4, kMaxCableSlots> dq;
    if (path_only) // the lengths of a model with a user effect on the path: one size will do
        cable_jacobians<kMaxLocal, true>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else
        cable_jacobians_n(nloc, m, lay, col, full, P, t_s, npd, y, dP, dq);
    if (J) {
        for (int i = 0; i < 4; ++i) {
            for (auto [e, first] : jig) {
                const int np = int(desc[size_t(e)]->params.size());
                J->block(i, off[size_t(e)], 1, np) += dP.row(i) * dPdj.middleCols(first, np);
            }
            for (int sl = 0; sl < lay.cable.nslots; ++sl) (*J)(i, col[size_t(i)][size_t(sl)]) += dq(i, sl);
        }
    }
}

void ReadingEvaluator::Impl::builtin_path(const Eigen::VectorXd &full, const double ref[3], double t_s, double P[3],
                                          DPdj &dPdj, Eigen::Vector4d &len, Jac &Jl, Jac3 &dPl, CableFrame &F,
                                          bool deriv) const {
    builtin(full, ref, t_s, P, dPdj, len, deriv ? &Jl : nullptr, dPl, !deriv, 3, true);
    frame_at(full, P, t_s, F);
}

bool ReadingEvaluator::eval(const Eigen::VectorXd &full, const double ref[3], double t_s, Eigen::Vector4d &y,
                            Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> *dydP,
                            std::string *err, int dydP_cols) const {
    const Impl &I = *impl_;
    if (I.lay.has_path_user) return I.eval_path(full, ref, t_s, y, J, dydP, err);
    double P[3];
    DPdj dPdj;
    Eigen::Matrix<double, 4, 3> dP;
    I.builtin(full, ref, t_s, P, dPdj, y, J, dP, !J && !dydP && !I.lay.has_user,
              dydP ? std::clamp(dydP_cols, 1, 3) : 0);
    if (I.lay.has_user) {
        CableFrame F;
        if (I.lay.has_geom) I.frame_at(full, P, t_s, F);
        if (!I.reading_users(full, P, t_s, &F, dPdj, y, J, dP, err)) return false;
    }
    if (dydP) *dydP = dP;
    return true;
}

bool ReadingEvaluator::has_user() const { return impl_->lay.has_user; }

bool ReadingEvaluator::has_batch() const {
    for (const EffectDesc *d : impl_->desc)
        if (d->stage == Stage::User && (d->apply_batch || d->apply_geom)) return true;
    return false;
}

} // namespace cdm
