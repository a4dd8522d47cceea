// See evaluator.h.
#include "model/evaluator.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "model/model_impl.h"

namespace cdm {

namespace {
// Derivative vectors: at most 3 position + every cable parameter; fixed
// maximum size, so no heap allocation per evaluation.
constexpr int kMaxLocal = 3 + kMaxCableSlots;
constexpr int kMaxJig = 16; // Jig-stage parameters of all built-ins together
using ADJ = Eigen::AutoDiffScalar<Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxJig, 1>>;
using DPdj = Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxJig>; // d P / d (jig parameters)

// Central differences through a user effect: call k's input is the state
// (parameters, position, readings) with at most one entry moved. k = 0: the
// value; then + and - a step on each incoming reading (4), each position
// coordinate (3) and each parameter, so the difference for entry j is
// (out[1 + 2j] - out[2 + 2j]) / (2 h). Steps (those the per-position path
// has always used): 1e-5 mm on a reading, 1e-4 mm on the position, the
// larger of 1e-6 and 1e-3 of a parameter's typical size: well above the
// round-off of a reading near 100-300 mm (~3e-14 mm).
enum class Moved { None, Reading, Position, Param };
struct UserStep {
    Moved what;
    int idx;
    double h; // signed
};
constexpr double kReadingStep = 1e-5, kPositionStep = 1e-4;
double param_step(const EffectDesc &d, int k) { return 1e-6 * std::max(1.0, d.params[size_t(k)].scale * 1e3); }
int user_calls(const EffectDesc &d, bool deriv) { return deriv ? 15 + 2 * int(d.params.size()) : 1; }
UserStep user_step(const EffectDesc &d, int k) {
    if (k == 0) return {Moved::None, 0, 0.0};
    const int j = (k - 1) / 2;
    const double sign = (k - 1) % 2 == 0 ? 1.0 : -1.0;
    if (j < 4) return {Moved::Reading, j, sign * kReadingStep};
    if (j < 7) return {Moved::Position, j - 4, sign * kPositionStep};
    return {Moved::Param, j - 7, sign * param_step(d, j - 7)};
}
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

    // The built-in effects' part of eval: the device-frame position P (and
    // dPdj), the readings y, and when `values_only` is false J (if given)
    // and dP.
    // npos: the position derivatives the caller wants in dP (0, 1: x, or 3).
    void builtin(const Eigen::VectorXd &full, const double ref[3], double t_s, double P[3], DPdj &dPdj,
                 Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> &dP,
                 bool values_only, int npos = 3) const;
    // User effect e at one position: the outputs of its user_calls calls
    // (apply, or apply_batch on one row). False on a non-zero return.
    bool user_one(size_t e, const Eigen::VectorXd &full, const double P[3], const Eigen::Vector4d &y, bool deriv,
                  Eigen::Vector4d *out, std::string *err) const;
    // Chains user effect e's central differences (out: its calls' outputs)
    // onto y, J and dP.
    void chain(size_t e, const Eigen::Vector4d *out, const DPdj &dPdj, Eigen::Vector4d &y,
               Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> &dP) const;
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
// The cable kernel with derivatives of a fixed length N >= np + the
// model's cable slots (the rest stay zero): Eigen then keeps each derivative
// vector in registers and on the stack, where a dynamically sized one (even
// with a fixed maximum) copies through memcpy on every temporary and loops
// over a run-time length. The derivative vector holds the first np
// position coordinates (0, 1 or 3: only those asked for are carried), then
// the cable's parameters. Each entry is computed on its own (forward mode
// is element-wise), so the values and derivatives are those of the
// dynamic form whatever N and np (the padding entries only ever hold zeros).
template <int N>
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
        const AD r = cable_reading<AD>(m.geometry(), i, s, lay.cable, q);
        y(i) = r.value();
        const auto &d = r.derivatives();
        for (int k = 0; k < np; ++k) dP(i, k) = d(k);
        for (int sl = 0; sl < ns; ++sl) dq(i, sl) = d(np + sl);
    }
}
} // namespace

void ReadingEvaluator::Impl::builtin(const Eigen::VectorXd &full, const double ref[3], double t_s, double P[3],
                                     DPdj &dPdj, Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J,
                                     Eigen::Matrix<double, 4, 3> &dP, bool values_only, int npos) const {
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
            y(i) = cable_reading<double>(m.geometry(), i, s, lay.cable, q);
        }
        return;
    }
    // The position derivatives the caller and the chain need: all three
    // for a Jig-stage effect's chain rule or a user effect's, else those
    // asked for.
    const int npd = (njig > 0 || lay.has_user) ? 3 : npos;
    const int nloc = npd + lay.cable.nslots;
    Eigen::Matrix<double, 4, kMaxCableSlots> dq;
    if (nloc <= 2)
        cable_jacobians<2>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else if (nloc <= 4)
        cable_jacobians<4>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else if (nloc <= 6)
        cable_jacobians<6>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else if (nloc <= 8)
        cable_jacobians<8>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else if (nloc <= 12)
        cable_jacobians<12>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else if (nloc <= 16)
        cable_jacobians<16>(m, lay, col, full, P, t_s, npd, y, dP, dq);
    else
        cable_jacobians<kMaxLocal>(m, lay, col, full, P, t_s, npd, y, dP, dq);
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

bool ReadingEvaluator::eval(const Eigen::VectorXd &full, const double ref[3], double t_s, Eigen::Vector4d &y,
                            Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> *dydP,
                            std::string *err, int dydP_cols) const {
    const Impl &I = *impl_;
    double P[3];
    DPdj dPdj;
    Eigen::Matrix<double, 4, 3> dP;
    I.builtin(full, ref, t_s, P, dPdj, y, J, dP, !J && !dydP && !I.lay.has_user,
              dydP ? std::clamp(dydP_cols, 1, 3) : 0);
    if (I.lay.has_user) {
        Eigen::Vector4d out[15 + 2 * kMaxUserParams]; // the most calls one user effect needs
        for (size_t e = 0; e < I.desc.size(); ++e) {
            if (I.desc[e]->stage != Stage::User) continue;
            if (!I.user_one(e, full, P, y, J != nullptr, out, err)) return false;
            I.chain(e, out, dPdj, y, J, dP);
        }
    }
    if (dydP) *dydP = dP;
    return true;
}

namespace {
// A user effect's readings must be numbers: a NaN or an infinity (numpy
// overflows warn, they do not raise) would reach the optimiser's gradient
// and end a fit on a misleading status. Names the effect, cable and position.
bool finite_readings(const EffectDesc &d, const double *Y, size_t n, const double *P, std::string *err) {
    for (size_t i = 0; i < n; ++i)
        for (int c = 0; c < 4; ++c)
            if (!std::isfinite(Y[4 * i + size_t(c)])) {
                if (err) {
                    char b[160];
                    std::snprintf(b, sizeof b, "\": non-finite reading of cable %d at (%.6g, %.6g, %.6g) mm", c + 1,
                                  P[3 * i], P[3 * i + 1], P[3 * i + 2]);
                    *err = "user effect \"" + d.name + b;
                }
                return false;
            }
    return true;
}
} // namespace

bool ReadingEvaluator::Impl::user_one(size_t e, const Eigen::VectorXd &full, const double P[3],
                                      const Eigen::Vector4d &y, bool deriv, Eigen::Vector4d *out,
                                      std::string *err) const {
    const EffectDesc &d = *desc[e];
    const int np = int(d.params.size());
    double prm[kMaxUserParams];
    for (int k = 0; k < user_calls(d, deriv); ++k) {
        const UserStep st = user_step(d, k);
        for (int a = 0; a < np; ++a) prm[a] = full(off[e] + a);
        double Pk[3] = {P[0], P[1], P[2]};
        double buf[4] = {y(0), y(1), y(2), y(3)};
        if (st.what == Moved::Param) prm[st.idx] += st.h;
        if (st.what == Moved::Position) Pk[st.idx] += st.h;
        if (st.what == Moved::Reading) buf[st.idx] += st.h;
        if (d.apply_one(prm, Pk, buf) != 0) {
            if (err) *err = "user effect \"" + d.name + "\": apply returned non-zero";
            return false;
        }
        if (!finite_readings(d, buf, 1, Pk, err)) return false;
        out[k] = Eigen::Vector4d(buf[0], buf[1], buf[2], buf[3]);
    }
    return true;
}

// User effects act on the readings: chain their central-difference
// derivatives (w.r.t. their parameters, the incoming readings and the
// position) onto the built-in Jacobian.
void ReadingEvaluator::Impl::chain(size_t e, const Eigen::Vector4d *out, const DPdj &dPdj, Eigen::Vector4d &y,
                                   Eigen::Matrix<double, 4, Eigen::Dynamic> *J,
                                   Eigen::Matrix<double, 4, 3> &dP) const {
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

bool ReadingEvaluator::has_user() const { return impl_->lay.has_user; }

bool ReadingEvaluator::has_batch() const {
    for (const EffectDesc *d : impl_->desc)
        if (d->stage == Stage::User && d->apply_batch) return true;
    return false;
}

bool ReadingEvaluator::eval_batch(const Eigen::VectorXd &full, size_t n, const double *refs, const double *t_s,
                                  bool want_J, bool want_dydP, Batch &out, std::string *err) const {
    const Impl &I = *impl_;
    out.y.resize(n);
    out.J.resize(want_J ? n : 0);
    out.dydP.resize(n);
    std::vector<double> P(3 * n);
    std::vector<DPdj> dPdj(n);
    const bool values_only = !want_J && !want_dydP && !I.lay.has_user;
    for (size_t i = 0; i < n; ++i)
        I.builtin(full, refs + 3 * i, t_s[i], &P[3 * i], dPdj[i], out.y[i], want_J ? &out.J[i] : nullptr,
                  out.dydP[i], values_only);
    Eigen::Vector4d calls[15 + 2 * kMaxUserParams];
    for (size_t e = 0; e < I.desc.size() && I.lay.has_user; ++e) {
        const EffectDesc &d = *I.desc[e];
        if (d.stage != Stage::User) continue;
        if (!d.apply_batch) {
            for (size_t i = 0; i < n; ++i) {
                if (!I.user_one(e, full, &P[3 * i], out.y[i], want_J, calls, err)) return false;
                I.chain(e, calls, dPdj[i], out.y[i], want_J ? &out.J[i] : nullptr, out.dydP[i]);
            }
            continue;
        }
        // Every call's rows, as user_one would make them one position at a
        // time: call k's readings at scratch[4 n k ...].
        const int nc = user_calls(d, want_J), np = int(d.params.size());
        out.scratch.resize(4 * n * size_t(nc));
        std::vector<double> Pk(3 * n);
        double prm[kMaxUserParams];
        for (int k = 0; k < nc && n > 0; ++k) {
            const UserStep st = user_step(d, k);
            for (int a = 0; a < np; ++a) prm[a] = full(I.off[e] + a);
            Pk = P;
            double *Y = &out.scratch[4 * n * size_t(k)];
            for (size_t i = 0; i < n; ++i) {
                for (int c = 0; c < 4; ++c) Y[4 * i + size_t(c)] = out.y[i](c);
                if (st.what == Moved::Position) Pk[3 * i + size_t(st.idx)] += st.h;
                if (st.what == Moved::Reading) Y[4 * i + size_t(st.idx)] += st.h;
            }
            if (st.what == Moved::Param) prm[st.idx] += st.h;
            if (d.apply_batch(d.user, prm, n, Pk.data(), Y) != 0) {
                if (err) *err = "user effect \"" + d.name + "\": apply_batch returned non-zero";
                return false;
            }
            if (!finite_readings(d, Y, n, Pk.data(), err)) return false;
        }
        for (size_t i = 0; i < n; ++i) {
            for (int k = 0; k < nc; ++k) calls[k] = Eigen::Map<const Eigen::Vector4d>(&out.scratch[4 * (n * size_t(k) + i)]);
            I.chain(e, calls, dPdj[i], out.y[i], want_J ? &out.J[i] : nullptr, out.dydP[i]);
        }
    }
    return true;
}

} // namespace cdm
