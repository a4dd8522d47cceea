// NLopt fit of the model's effect parameters.
//
// Algorithm: NLOPT_LD_SLSQP (sequential quadratic programming with a BFGS
// Hessian, bounds as linear constraints) in *whitened* coordinates: at the
// start point the Gauss-Newton Hessian J'WJ (plus a weak prior) is
// eigendecomposed and the parameters rescaled so that it is the identity.
// SLSQP's first Hessian guess is the identity, so it starts right and
// converges in few evaluations even when parameters are strongly correlated
// (anchor positions against pot offsets); parameters in mm, rad and 1/mm
// need no hand scaling. The whitening is redone at the solution and the fit
// repeated until the objective stops falling (usually two passes).
// Derivatives: forward-mode automatic differentiation (Eigen AutoDiffScalar)
// over each cable's 15 local variables, chained to the global parameters;
// central differences through user-defined effects.
//
// Gauge: parameters that change nothing measurable are fixed, not left to
// wander: with jig_misalignment on, the anchors' common rigid motion (3
// translations, 3 small rotations) is the jig's and is projected out of
// anchor_position; the holder points' common translation is the jig's (or the
// anchors') and is projected out of holder_geometry; cable_stretch's s0 is the
// common part of cable_gain and its s1 that of pot_nonlinearity, fixed when
// those are on. A weak Gaussian prior (10x each parameter's typical size)
// keeps the remaining near-degenerate combinations finite; it never binds
// for a well-determined parameter.
#include "calib/fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <nlopt.h>
#include <unsupported/Eigen/AutoDiff>

#include "model/model_impl.h"

namespace cdm {

std::vector<PreparedPos> prepare(const Dataset &d) {
    // The readings' resolution per cable: the smallest step between distinct
    // values (the ADC count through the nominal scale; the CSV's last digit
    // for unquantised data).
    double q[4];
    for (int c = 0; c < 4; ++c) {
        std::vector<double> v;
        v.reserve(d.samples.size());
        for (auto &s : d.samples) v.push_back(s[size_t(c)]);
        std::sort(v.begin(), v.end());
        q[c] = INFINITY;
        for (size_t k = 1; k < v.size(); ++k)
            if (v[k] - v[k - 1] > 1e-9) q[c] = std::min(q[c], v[k] - v[k - 1]);
        if (!std::isfinite(q[c])) q[c] = 0;
    }
    // Pooled within-position variance, for positions measured once.
    double pooled[4] = {0, 0, 0, 0}, dof = 0;
    for (auto &p : d.pos)
        if (p.n > 1) {
            for (int c = 0; c < 4; ++c) pooled[c] += p.cov[c][c] * (p.n - 1);
            dof += p.n - 1;
        }
    for (int c = 0; c < 4; ++c) pooled[c] = dof > 0 ? pooled[c] / dof : 0;
    std::vector<PreparedPos> v;
    v.reserve(d.pos.size());
    for (auto &p : d.pos) {
        PreparedPos pp;
        pp.ref = Eigen::Vector3d(p.ref[0], p.ref[1], p.ref[2]);
        for (int c = 0; c < 4; ++c) {
            pp.mean(c) = p.mean[c];
            for (int k = 0; k < 4; ++k) pp.cov(c, k) = p.cov[c][k];
            const double var = p.n > 1 ? p.cov[c][c] : pooled[c];
            // Noise that spans several ADC steps dithers the quantisation
            // away in the mean; noise below half a step does not, and the
            // mean keeps the rounding error of variance q^2/12.
            const double q12 = q[c] * q[c] / 12;
            pp.var_mean(c) = var / p.n + (var < 3 * q12 ? q12 : 0.0);
            pp.var_mean(c) = std::max(pp.var_mean(c), 1e-10);
        }
        pp.n = p.n;
        pp.first = p.first;
        v.push_back(pp);
    }
    return v;
}

namespace {

using AD16 = Eigen::AutoDiffScalar<Eigen::Matrix<double, kLocalCount, 1>>;
using AD6 = Eigen::AutoDiffScalar<Eigen::Matrix<double, 6, 1>>;

struct ParamRef {
    int effect; // index in model effects
    int k;      // parameter index
};

struct Problem {
    Model &m;
    const std::vector<PreparedPos> &pos;
    const FitOptions &opt;
    std::vector<ParamRef> params;     // full parameter list
    std::vector<int> eff_offset;      // first full index of each effect (-1: not fitted)
    Eigen::VectorXd base, scale, lo, hi, init;
    Eigen::MatrixXd Q;                // full = base + Q * free
    std::vector<int> rows;            // positions used
    Eigen::VectorXd w;                // weights per observation (4 per used position)
    int evals = 0;
    bool cancelled = false;

    Problem(Model &m_, const std::vector<PreparedPos> &p_, const FitOptions &o_) : m(m_), pos(p_), opt(o_) {
        auto &I = m.impl();
        eff_offset.assign(I.effects.size(), -1);
        for (size_t e = 0; e < I.effects.size(); ++e) {
            if (I.effects[e].desc->stage == Stage::Position) continue;
            eff_offset[e] = int(params.size());
            for (size_t k = 0; k < I.effects[e].p.size(); ++k) params.push_back({int(e), int(k)});
        }
        const int n = int(params.size());
        base.resize(n);
        scale.resize(n);
        lo.resize(n);
        hi.resize(n);
        init.resize(n);
        for (int a = 0; a < n; ++a) {
            auto &e = I.effects[params[a].effect];
            auto &pd = e.desc->params[params[a].k];
            base(a) = e.p[params[a].k];
            scale(a) = pd.scale;
            lo(a) = pd.lower;
            hi(a) = pd.upper;
            init(a) = pd.init;
        }
        build_gauge();
        for (size_t j = 0; j < pos.size(); ++j)
            if (opt.use.empty() || opt.use[j]) rows.push_back(int(j));
        compute_weights();
    }

    int off(int builtin) const {
        int e = m.impl().idx[builtin];
        return e >= 0 ? eff_offset[e] : -1;
    }

    void build_gauge() {
        const int n = int(params.size());
        std::vector<Eigen::MatrixXd> blocks;
        Q = Eigen::MatrixXd::Zero(n, n);
        int col = 0;
        auto &I = m.impl();
        const bool jig = off(E_JIG) >= 0, anchor = off(E_ANCHOR) >= 0;
        for (size_t e = 0; e < I.effects.size(); ++e) {
            if (eff_offset[e] < 0) continue;
            const int o = eff_offset[e], np = int(I.effects[e].p.size());
            const int id = I.effects[e].desc->builtin_id;
            Eigen::MatrixXd B = Eigen::MatrixXd::Identity(np, np);
            if (id == E_ANCHOR && jig) {
                // rigid modes of the four anchors about their centroid
                Eigen::MatrixXd R(12, 6);
                for (int i = 0; i < 4; ++i) {
                    auto A = I.g.anchor(i);
                    Eigen::Vector3d a(A[0], A[1], A[2]);
                    for (int k = 0; k < 3; ++k) {
                        Eigen::Vector3d ek = Eigen::Vector3d::Unit(k);
                        R.block<3, 1>(3 * i, k) = ek;
                        R.block<3, 1>(3 * i, 3 + k) = ek.cross(a) / 100.0;
                    }
                }
                B = complement(R);
            } else if (id == E_HOLDER && (jig || anchor)) {
                Eigen::MatrixXd R(12, 3);
                for (int i = 0; i < 4; ++i) R.block<3, 3>(3 * i, 0) = Eigen::Matrix3d::Identity();
                B = complement(R);
            } else if (id == E_STRETCH) {
                std::vector<int> keep;
                if (off(E_GAIN) < 0) keep.push_back(0);
                if (off(E_NONLIN) < 0) keep.push_back(1);
                B = Eigen::MatrixXd::Zero(2, int(keep.size()));
                for (size_t c = 0; c < keep.size(); ++c) B(keep[c], int(c)) = 1;
            }
            Q.block(o, col, np, B.cols()) = B;
            col += int(B.cols());
        }
        Q.conservativeResize(n, col);
    }

    static Eigen::MatrixXd complement(const Eigen::MatrixXd &R) {
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullU);
        const int r = int(R.cols());
        return svd.matrixU().rightCols(R.rows() - r);
    }

    void set_full(const Eigen::VectorXd &full) {
        auto &I = m.impl();
        for (int a = 0; a < int(params.size()); ++a) I.effects[params[a].effect].p[params[a].k] = full(a);
    }
    Eigen::VectorXd get_full() const {
        Eigen::VectorXd v(params.size());
        auto &I = m.impl();
        for (int a = 0; a < int(params.size()); ++a) v(a) = I.effects[params[a].effect].p[params[a].k];
        return v;
    }

    // Predicted readings and d(readings)/d(full params) at used position j.
    void eval_position(const PreparedPos &pp, Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J,
                       Eigen::Matrix<double, 4, 3> *dydP) {
        const auto &I = m.impl();
        const int n = int(params.size());
        // jig: P = R(w) ref + t
        double P[3];
        Eigen::Matrix<double, 3, 6> dPdj = Eigen::Matrix<double, 3, 6>::Zero();
        const int oj = off(E_JIG);
        if (oj >= 0) {
            const double *jp = I.params(E_JIG);
            AD6 wv[3], x[3], out[3];
            for (int k = 0; k < 3; ++k) {
                wv[k] = AD6(jp[k], 6, k);
                x[k] = AD6(pp.ref(k));
            }
            rotvec_apply<AD6>(wv, x, out);
            for (int k = 0; k < 3; ++k) {
                P[k] = out[k].value() + jp[3 + k];
                dPdj.row(k) = out[k].derivatives().transpose();
                dPdj(k, 3 + k) += 1.0;
            }
        } else {
            for (int k = 0; k < 3; ++k) P[k] = pp.ref(k);
        }
        if (J) J->setZero(4, n);
        Eigen::Matrix<double, 4, 3> dP;
        for (int i = 0; i < 4; ++i) {
            auto v = I.cable_vars(i);
            AD16 Pa[3];
            for (int k = 0; k < 3; ++k) Pa[k] = AD16(P[k], kLocalCount, k);
            CableVars<AD16> cv;
            double raw[kCableVarCount] = {v.dA[0], v.dA[1], v.dA[2], v.dh[0], v.dh[1], v.dh[2], v.r,
                                          v.s0,    v.s1,    v.g,     v.k2,    v.off};
            AD16 *dst[kCableVarCount] = {&cv.dA[0], &cv.dA[1], &cv.dA[2], &cv.dh[0], &cv.dh[1], &cv.dh[2], &cv.r,
                                         &cv.s0,    &cv.s1,    &cv.g,     &cv.k2,    &cv.off};
            for (int k = 0; k < kCableVarCount; ++k) *dst[k] = AD16(raw[k], kLocalCount, 3 + k);
            AD16 r = cable_reading<AD16>(I.g, i, Pa, cv, I.pulley());
            y(i) = r.value();
            const auto &d = r.derivatives();
            dP.row(i) = d.head<3>().transpose();
            if (!J) continue;
            if (oj >= 0) J->block(i, oj, 1, 6) += d.head<3>().transpose() * dPdj;
            int o;
            if ((o = off(E_ANCHOR)) >= 0)
                for (int k = 0; k < 3; ++k) (*J)(i, o + 3 * i + k) += d(3 + k);
            if ((o = off(E_HOLDER)) >= 0)
                for (int k = 0; k < 3; ++k) (*J)(i, o + 3 * i + k) += d(6 + k);
            if ((o = off(E_PULLEY)) >= 0) (*J)(i, o) += d(9);
            if ((o = off(E_STRETCH)) >= 0) {
                (*J)(i, o) += d(10);
                (*J)(i, o + 1) += d(11);
            }
            if ((o = off(E_GAIN)) >= 0) (*J)(i, o + i) += d(12);
            if ((o = off(E_NONLIN)) >= 0) (*J)(i, o + i) += d(13);
            if ((o = off(E_OFFSET)) >= 0) (*J)(i, o + i) += d(14);
        }
        if (I.has_user) apply_user_chain(P, dPdj, oj, y, J, dP);
        if (dydP) *dydP = dP;
    }

    // User effects act on the readings: chain their central-difference
    // derivatives (w.r.t. their parameters, the incoming readings and the
    // position) onto the built-in Jacobian.
    void apply_user_chain(const double P[3], const Eigen::Matrix<double, 3, 6> &dPdj, int oj, Eigen::Vector4d &y,
                          Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> &dP) {
        auto &I = m.impl();
        for (size_t e = 0; e < I.effects.size(); ++e) {
            auto &ef = I.effects[e];
            if (ef.desc->stage != Stage::User) continue;
            auto call = [&](const std::vector<double> &prm, const double *Pv, const Eigen::Vector4d &yin) {
                double buf[4] = {yin(0), yin(1), yin(2), yin(3)};
                ef.desc->apply(ef.desc->user, prm.data(), Pv, buf);
                return Eigen::Vector4d(buf[0], buf[1], buf[2], buf[3]);
            };
            Eigen::Vector4d y1 = call(ef.p, P, y);
            if (J) {
                Eigen::Matrix4d Dy;
                Eigen::Matrix<double, 4, 3> DP;
                for (int c = 0; c < 4; ++c) {
                    const double h = 1e-5;
                    Eigen::Vector4d yp = y, ym = y;
                    yp(c) += h;
                    ym(c) -= h;
                    Dy.col(c) = (call(ef.p, P, yp) - call(ef.p, P, ym)) / (2 * h);
                }
                for (int k = 0; k < 3; ++k) {
                    const double h = 1e-4;
                    double Pp[3] = {P[0], P[1], P[2]}, Pm[3] = {P[0], P[1], P[2]};
                    Pp[k] += h;
                    Pm[k] -= h;
                    DP.col(k) = (call(ef.p, Pp, y) - call(ef.p, Pm, y)) / (2 * h);
                }
                Eigen::Matrix<double, 4, Eigen::Dynamic> Jn = Dy * (*J);
                if (oj >= 0) Jn.block(0, oj, 4, 6) += DP * dPdj;
                for (size_t k = 0; k < ef.p.size(); ++k) {
                    const double h = 1e-6 * std::max(1.0, ef.desc->params[k].scale * 1e3);
                    auto pp = ef.p, pm = ef.p;
                    pp[k] += h;
                    pm[k] -= h;
                    Jn.col(eff_offset[e] + int(k)) += (call(pp, P, y) - call(pm, P, y)) / (2 * h);
                }
                *J = Jn;
                dP = Dy * dP + DP;
            }
            y = y1;
        }
    }

    void compute_weights() {
        w.resize(4 * int(rows.size()));
        for (size_t r = 0; r < rows.size(); ++r) {
            const auto &pp = pos[rows[r]];
            Eigen::Vector4d y;
            Eigen::Matrix<double, 4, 3> dP;
            eval_position(pp, y, nullptr, &dP);
            for (int c = 0; c < 4; ++c) {
                double jig = 0;
                for (int a = 0; a < 3; ++a) jig += dP(c, a) * dP(c, a) * opt.jig_sigma(a) * opt.jig_sigma(a);
                w(4 * r + c) = 1.0 / (pp.var_mean(c) + jig);
            }
        }
    }

    // Weighted residuals (sqrt(w) * (mean - y)) and Jacobian of y.
    void residuals(Eigen::VectorXd &res, Eigen::MatrixXd *J) {
        const int n = int(params.size());
        res.resize(4 * int(rows.size()));
        if (J) J->resize(4 * int(rows.size()), n);
        Eigen::Matrix<double, 4, Eigen::Dynamic> Jp(4, n);
        for (size_t r = 0; r < rows.size(); ++r) {
            const auto &pp = pos[rows[r]];
            Eigen::Vector4d y;
            eval_position(pp, y, J ? &Jp : nullptr, nullptr);
            for (int c = 0; c < 4; ++c) {
                const double sw = std::sqrt(w(4 * r + c));
                res(4 * r + c) = sw * (pp.mean(c) - y(c));
                if (J) J->row(4 * r + c) = sw * Jp.row(c);
            }
        }
    }

    double prior(const Eigen::VectorXd &full, Eigen::VectorXd *grad) const {
        double s = 0;
        if (grad) grad->setZero(full.size());
        for (int a = 0; a < full.size(); ++a) {
            const double sd = 10 * scale(a);
            const double z = (full(a) - init(a)) / sd;
            s += z * z;
            if (grad) (*grad)(a) = 2 * z / sd;
        }
        return s;
    }
};

struct Whitened {
    Problem *pb;
    Eigen::VectorXd base;   // full params at the whitening point
    Eigen::MatrixXd T;      // full = base + T * zeta
    double best = INFINITY;
    Eigen::VectorXd best_full;
};

double objective(unsigned n, const double *z, double *grad, void *data) {
    auto *W = static_cast<Whitened *>(data);
    Problem &pb = *W->pb;
    Eigen::Map<const Eigen::VectorXd> zeta(z, n);
    Eigen::VectorXd full = W->base + W->T * zeta;
    pb.set_full(full);
    Eigen::VectorXd res;
    Eigen::MatrixXd J;
    pb.residuals(res, grad ? &J : nullptr);
    Eigen::VectorXd pg;
    double f = 0.5 * (res.squaredNorm() + pb.prior(full, grad ? &pg : nullptr));
    if (!std::isfinite(f)) f = 1e300;
    if (grad) {
        Eigen::VectorXd gfull = -J.transpose() * res + 0.5 * pg;
        Eigen::Map<Eigen::VectorXd>(grad, n) = W->T.transpose() * gfull;
    }
    ++pb.evals;
    if (f < W->best) {
        W->best = f;
        W->best_full = full;
    }
    if (pb.opt.progress && pb.evals % 5 == 0 && !pb.opt.progress(std::min(1.0, pb.evals / double(pb.opt.max_evals))))
        pb.cancelled = true;
    if (pb.cancelled) nlopt_force_stop(nullptr);
    return f;
}

struct BoundData {
    Whitened *W;
    std::vector<int> idx;
    std::vector<double> sign, bound;
};

void bounds_constraint(unsigned m, double *result, unsigned n, const double *z, double *grad, void *data) {
    auto *B = static_cast<BoundData *>(data);
    Eigen::Map<const Eigen::VectorXd> zeta(z, n);
    for (unsigned c = 0; c < m; ++c) {
        const int a = B->idx[c];
        const double full = B->W->base(a) + B->W->T.row(a).dot(zeta);
        // sign * (full - bound) <= 0
        result[c] = B->sign[c] * (full - B->bound[c]);
        if (grad)
            for (unsigned k = 0; k < n; ++k) grad[c * n + k] = B->sign[c] * B->W->T(a, k);
    }
}

} // namespace

bool fit_model(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt, FitReport &rep) {
    auto t0 = std::chrono::steady_clock::now();
    Problem pb(m, pos, opt);
    rep = FitReport{};
    rep.algorithm = "NLOPT_LD_SLSQP (whitened by the Gauss-Newton Hessian)";
    const int nfree = int(pb.Q.cols());
    rep.n_free = nfree;
    rep.n_obs = 4 * int(pb.rows.size());
    auto &I = m.impl();
    if (nfree == 0) {
        Eigen::VectorXd res;
        pb.residuals(res, nullptr);
        rep.chi2 = res.squaredNorm();
        rep.converged = true;
        for (auto &e : I.effects) rep.std.emplace_back(e.p.size(), 0.0);
        return true;
    }
    double prev = INFINITY;
    bool ok = true;
    Eigen::MatrixXd Hfree;
    for (int pass = 0; pass < 4 && pb.evals < opt.max_evals; ++pass) {
        Eigen::VectorXd full = pb.get_full();
        pb.set_full(full);
        Eigen::VectorXd res;
        Eigen::MatrixXd J;
        pb.residuals(res, &J);
        Eigen::MatrixXd JQ = J * pb.Q;
        Hfree = JQ.transpose() * JQ;
        for (int a = 0; a < int(full.size()); ++a) {
            // the prior's Hessian, mapped through Q
            const double sd = 10 * pb.scale(a);
            Hfree += pb.Q.row(a).transpose() * pb.Q.row(a) / (sd * sd);
        }
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Hfree);
        Eigen::VectorXd lam = es.eigenvalues().cwiseMax(1e-12 * es.eigenvalues().maxCoeff());
        Whitened W{&pb, full, pb.Q * es.eigenvectors() * lam.cwiseSqrt().cwiseInverse().asDiagonal(), INFINITY, full};
        nlopt_opt o = nlopt_create(NLOPT_LD_SLSQP, unsigned(nfree));
        nlopt_set_min_objective(o, objective, &W);
        BoundData B{&W, {}, {}, {}};
        for (int a = 0; a < int(full.size()); ++a) {
            if (pb.Q.row(a).norm() == 0) continue; // fixed by the gauge
            B.idx.push_back(a);
            B.sign.push_back(-1);
            B.bound.push_back(pb.lo(a));
            B.idx.push_back(a);
            B.sign.push_back(+1);
            B.bound.push_back(pb.hi(a));
        }
        std::vector<double> tol(B.idx.size(), 1e-9);
        nlopt_add_inequality_mconstraint(o, unsigned(B.idx.size()), bounds_constraint, &B, tol.data());
        nlopt_set_ftol_rel(o, 1e-12);
        nlopt_set_xtol_abs1(o, 1e-7);
        nlopt_set_maxeval(o, std::max(10, opt.max_evals - pb.evals));
        std::vector<double> z(size_t(nfree), 0.0);
        double f = 0;
        nlopt_result r = nlopt_optimize(o, z.data(), &f);
        nlopt_destroy(o);
        pb.set_full(W.best_full);
        if (pb.cancelled) {
            rep.message = "cancelled";
            ok = false;
            break;
        }
        if (r < 0 && r != NLOPT_ROUNDOFF_LIMITED) {
            rep.message = std::string("NLopt stopped: ") + nlopt_result_to_string(r);
        }
        if (prev - W.best <= 1e-9 * std::fabs(W.best) + 1e-9) {
            rep.converged = true;
            break;
        }
        prev = W.best;
    }
    Eigen::VectorXd res;
    pb.residuals(res, nullptr);
    rep.chi2 = res.squaredNorm();
    rep.evals = pb.evals;
    if (!rep.converged && rep.message.empty()) rep.message = "evaluation budget spent before convergence";
    // Parameter std from the Gauss-Newton covariance, inflated by chi2/dof
    // when the residual is larger than the weights claim.
    {
        Eigen::MatrixXd J;
        pb.residuals(res, &J);
        Eigen::MatrixXd JQ = J * pb.Q;
        Eigen::MatrixXd H = JQ.transpose() * JQ;
        for (int a = 0; a < int(pb.params.size()); ++a) {
            const double sd = 10 * pb.scale(a);
            H += pb.Q.row(a).transpose() * pb.Q.row(a) / (sd * sd);
        }
        Eigen::MatrixXd C = pb.Q * H.ldlt().solve(Eigen::MatrixXd::Identity(nfree, nfree)) * pb.Q.transpose();
        const double dof = std::max(1, rep.n_obs - nfree);
        const double infl = std::max(1.0, rep.chi2 / dof);
        rep.std.clear();
        for (size_t e = 0; e < I.effects.size(); ++e) {
            std::vector<double> s(I.effects[e].p.size(), 0.0);
            if (pb.eff_offset[e] >= 0)
                for (size_t k = 0; k < s.size(); ++k) {
                    const int a = pb.eff_offset[e] + int(k);
                    s[k] = std::sqrt(std::max(0.0, C(a, a)) * infl);
                }
            rep.std.push_back(s);
        }
    }
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return ok;
}

Overlap effect_overlap(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                       const std::string &name) {
    Model copy = m;
    Problem pb(copy, pos, opt);
    Overlap out;
    Eigen::VectorXd res;
    Eigen::MatrixXd J;
    pb.residuals(res, &J);
    auto &I = copy.impl();
    auto cols = [&](size_t e) {
        const int o = pb.eff_offset[e], n = int(I.effects[e].p.size());
        Eigen::MatrixXd C = J.middleCols(o, n);
        for (int k = 0; k < n; ++k) {
            const double nn = C.col(k).norm();
            if (nn > 0) C.col(k) /= nn;
        }
        return C;
    };
    int target = -1;
    for (size_t e = 0; e < I.effects.size(); ++e)
        if (I.effects[e].desc->name == name && pb.eff_offset[e] >= 0) target = int(e);
    if (target < 0) return out;
    const Eigen::MatrixXd Jc = cols(size_t(target));
    const double total = Jc.squaredNorm();
    if (total <= 0) return out;
    auto fraction = [&](const Eigen::MatrixXd &B) {
        if (B.cols() == 0) return 0.0;
        // projection onto span(B) via a rank-revealing QR
        Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(B);
        qr.setThreshold(1e-10);
        const int r = int(qr.rank());
        if (r == 0) return 0.0;
        Eigen::MatrixXd Qm = qr.householderQ() * Eigen::MatrixXd::Identity(B.rows(), r);
        return std::sqrt((Qm.transpose() * Jc).squaredNorm() / total);
    };
    Eigen::MatrixXd all(J.rows(), 0);
    for (size_t e = 0; e < I.effects.size(); ++e) {
        if (int(e) == target || pb.eff_offset[e] < 0) continue;
        Eigen::MatrixXd B = cols(e);
        out.per_effect.emplace_back(I.effects[e].desc->name, fraction(B));
        Eigen::MatrixXd tmp(J.rows(), all.cols() + B.cols());
        tmp << all, B;
        all = tmp;
    }
    out.all = fraction(all);
    return out;
}

double model_chi2(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt, int *n_obs) {
    Model copy = m;
    Problem pb(copy, pos, opt);
    Eigen::VectorXd res;
    pb.residuals(res, nullptr);
    if (n_obs) *n_obs = int(res.size());
    return res.squaredNorm();
}

// ---------------------------------------------------------------- ellipsoid

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
