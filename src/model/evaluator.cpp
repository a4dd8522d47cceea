// See evaluator.h.
#include "model/evaluator.h"

#include <stdexcept>

#include "model/model_impl.h"

namespace cdm {

namespace {
// Derivative vectors: at most 3 position + every cable parameter; fixed
// maximum size, so no heap allocation per evaluation.
constexpr int kMaxLocal = 3 + kMaxCableSlots;
constexpr int kMaxJig = 16; // Jig-stage parameters of all built-ins together
using ADJ = Eigen::AutoDiffScalar<Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxJig, 1>>;
} // namespace

struct ReadingEvaluator::Impl {
    const Model &m;
    std::vector<const EffectDesc *> desc;
    ModelLayout lay;
    std::vector<int> off; // per model effect
    int n = 0;
    // Jig-stage effects: model effect index and first slot in the jig AD vector.
    std::vector<std::pair<int, int>> jig;
    int njig = 0;
    // Per cable, per slot: column in the full parameter vector.
    std::array<std::array<int, kMaxCableSlots>, 4> col{};

    explicit Impl(const Model &m_) : m(m_) {
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
                col[size_t(i)][size_t(s)] = off[size_t(lay.slot_effect[size_t(i)][size_t(s)])] +
                                             lay.slot_param[size_t(i)][size_t(s)];
    }

    // P = jig map of ref, with dP/d(jig parameters) in dPdj (3 x njig).
    void jig_position(const Eigen::VectorXd &full, const double ref[3], double P[3],
                      Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxJig> &dPdj) const {
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

    bool user_chain(const Eigen::VectorXd &full, const double P[3], double t_s, const Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxJig> &dPdj,
                    Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> &dP,
                    std::string *err) const;
};

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
// The cable kernel with derivatives of a fixed length N >= 3 + the model's
// cable slots (the rest stay zero): Eigen then keeps each derivative vector
// in registers and on the stack, where a dynamically sized one (even with a
// fixed maximum) copies through memcpy on every temporary and loops over a
// run-time length. The values and derivatives are those of the dynamic form
// (the padding entries only ever hold zeros).
template <int N>
void cable_jacobians(const Model &m, const ModelLayout &lay, const std::array<std::array<int, kMaxCableSlots>, 4> &col,
                     const Eigen::VectorXd &full, const double P[3], double t_s, Eigen::Vector4d &y,
                     Eigen::Matrix<double, 4, 3> &dP, Eigen::Matrix<double, 4, kMaxCableSlots> &dq) {
    using AD = Eigen::AutoDiffScalar<Eigen::Matrix<double, N, 1>>;
    static_assert(N >= 3, "position derivatives need 3 entries");
    Sample<AD> s;
    for (int k = 0; k < 3; ++k) s.P[k] = AD(P[k], N, k);
    s.t_s = t_s;
    AD q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
    const int ns = lay.cable.nslots;
    for (int i = 0; i < 4; ++i) {
        for (int sl = 0; sl < ns; ++sl) q[sl] = AD(full(col[size_t(i)][size_t(sl)]), N, 3 + sl);
        const AD r = cable_reading<AD>(m.geometry(), i, s, lay.cable, q);
        y(i) = r.value();
        const auto &d = r.derivatives();
        dP.row(i) = d.template head<3>().transpose();
        for (int sl = 0; sl < ns; ++sl) dq(i, sl) = d(3 + sl);
    }
}
} // namespace

bool ReadingEvaluator::eval(const Eigen::VectorXd &full, const double ref[3], double t_s, Eigen::Vector4d &y,
                            Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> *dydP,
                            std::string *err) const {
    const Impl &I = *impl_;
    double P[3];
    Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxJig> dPdj;
    I.jig_position(full, ref, P, dPdj);
    if (J) J->setZero(4, I.n);
    const int nloc = 3 + I.lay.cable.nslots;
    Eigen::Matrix<double, 4, 3> dP;
    if (!J && !dydP && !I.lay.has_user) {
        // Values only (a trial step of the fit, a chi-square): the same
        // arithmetic as the values of the differentiated kernel.
        Sample<double> s;
        for (int k = 0; k < 3; ++k) s.P[k] = P[k];
        s.t_s = t_s;
        double q[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
        for (int i = 0; i < 4; ++i) {
            for (int sl = 0; sl < I.lay.cable.nslots; ++sl) q[sl] = full(I.col[size_t(i)][size_t(sl)]);
            y(i) = cable_reading<double>(I.m.geometry(), i, s, I.lay.cable, q);
        }
        return true;
    }
    Eigen::Matrix<double, 4, kMaxCableSlots> dq;
    if (nloc <= 4)
        cable_jacobians<4>(I.m, I.lay, I.col, full, P, t_s, y, dP, dq);
    else if (nloc <= 8)
        cable_jacobians<8>(I.m, I.lay, I.col, full, P, t_s, y, dP, dq);
    else if (nloc <= 12)
        cable_jacobians<12>(I.m, I.lay, I.col, full, P, t_s, y, dP, dq);
    else if (nloc <= 16)
        cable_jacobians<16>(I.m, I.lay, I.col, full, P, t_s, y, dP, dq);
    else
        cable_jacobians<kMaxLocal>(I.m, I.lay, I.col, full, P, t_s, y, dP, dq);
    if (J) {
        for (int i = 0; i < 4; ++i) {
            for (auto [e, first] : I.jig) {
                const int np = int(I.desc[size_t(e)]->params.size());
                J->block(i, I.off[size_t(e)], 1, np) += dP.row(i) * dPdj.middleCols(first, np);
            }
            for (int sl = 0; sl < I.lay.cable.nslots; ++sl) (*J)(i, I.col[size_t(i)][size_t(sl)]) += dq(i, sl);
        }
    }
    if (I.lay.has_user && !I.user_chain(full, P, t_s, dPdj, y, J, dP, err)) return false;
    if (dydP) *dydP = dP;
    return true;
}

// User effects act on the readings: chain their central-difference
// derivatives (w.r.t. their parameters, the incoming readings and the
// position) onto the built-in Jacobian.
bool ReadingEvaluator::Impl::user_chain(const Eigen::VectorXd &full, const double P[3], double,
                                        const Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxJig> &dPdj,
                                        Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J,
                                        Eigen::Matrix<double, 4, 3> &dP, std::string *err) const {
    for (size_t e = 0; e < desc.size(); ++e) {
        const EffectDesc &d = *desc[e];
        if (d.stage != Stage::User) continue;
        const int o = off[e], np = int(d.params.size());
        std::vector<double> prm(full.data() + o, full.data() + o + np);
        bool failed = false;
        auto call = [&](const std::vector<double> &pv, const double *Pv, const Eigen::Vector4d &yin) {
            double buf[4] = {yin(0), yin(1), yin(2), yin(3)};
            if (d.apply(d.user, pv.data(), Pv, buf) != 0) failed = true;
            return Eigen::Vector4d(buf[0], buf[1], buf[2], buf[3]);
        };
        Eigen::Vector4d y1 = call(prm, P, y);
        if (J && !failed) {
            Eigen::Matrix4d Dy;
            Eigen::Matrix<double, 4, 3> DP;
            for (int c = 0; c < 4; ++c) {
                const double h = 1e-5;
                Eigen::Vector4d yp = y, ym = y;
                yp(c) += h;
                ym(c) -= h;
                Dy.col(c) = (call(prm, P, yp) - call(prm, P, ym)) / (2 * h);
            }
            for (int k = 0; k < 3; ++k) {
                const double h = 1e-4;
                double Pp[3] = {P[0], P[1], P[2]}, Pm[3] = {P[0], P[1], P[2]};
                Pp[k] += h;
                Pm[k] -= h;
                DP.col(k) = (call(prm, Pp, y) - call(prm, Pm, y)) / (2 * h);
            }
            Eigen::Matrix<double, 4, Eigen::Dynamic> Jn = Dy * (*J);
            for (auto [je, first] : jig) {
                const int jn = int(desc[size_t(je)]->params.size());
                Jn.block(0, off[size_t(je)], 4, jn) += DP * dPdj.middleCols(first, jn);
            }
            for (int k = 0; k < np; ++k) {
                const double h = 1e-6 * std::max(1.0, d.params[size_t(k)].scale * 1e3);
                auto pp = prm, pm = prm;
                pp[size_t(k)] += h;
                pm[size_t(k)] -= h;
                Jn.col(o + k) += (call(pp, P, y) - call(pm, P, y)) / (2 * h);
            }
            *J = Jn;
            dP = Dy * dP + DP;
        }
        if (failed) {
            if (err) *err = "user effect \"" + d.name + "\": apply returned non-zero";
            return false;
        }
        y = y1;
    }
    return true;
}

} // namespace cdm
