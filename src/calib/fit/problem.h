// The least-squares problem a fit solves: the model's readings against
// the per-position means, whitened per position (L^-1 (mean - y), L L' the
// four readings' covariance: the pots' noise and the position's own jig
// error through the model's sensitivity to the position), with their
// Jacobian over the fitted parameters and the fixture heights' x offsets,
// each plate hole's block decorrelated (generalised least squares); the
// gauge (full = base + Q * free), the bounds and the weak prior.
// Private to src/calib: optimiser.cpp runs the optimiser on it, queries.cpp
// answers the diagnosis's questions about a model (its chi-square, its
// Jacobian, an effect's overlap with the others).
#pragma once

#include <algorithm>
#include <cmath>
#include <exception>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <Eigen/Dense>

#include "calib/fit/fit.h"
#include "calib/fit/parallel.h"
#include "model/effect.h"
#include "model/evaluator.h"

namespace cdm::fit_detail {

// The Gauss-Newton step within the bounds (defined in optimiser.cpp): the u that minimises the local
// quadratic model 0.5 u'Hu + g'u of the objective subject to
// lo <= x0 + Q u <= hi (every parameter the gauge leaves free), by the
// primal active-set method for a convex quadratic programme (Nocedal and
// Wright, Numerical Optimization, 2nd ed., algorithm 16.3), started at u = 0
// with the bounds x0 already lies on (within SLSQP's constraint tolerance,
// 1e-9). H is positive definite (the prior, and the eigenvalue floor of
// the whitening), so each equality-constrained step is unique. `kkt` says u
// satisfies the programme's optimality conditions; false when the method
// did not settle within its iteration budget (the caller leaves the pass to
// SLSQP). `pred` is the decrease the quadratic model promises.
struct BoundedStep {
    bool kkt = false;
    Eigen::VectorXd u;
    double pred = 0;
};
BoundedStep bounded_gauss_newton(const Eigen::MatrixXd &H, const Eigen::VectorXd &g, const Eigen::VectorXd &x0,
                                 const Eigen::MatrixXd &Q, const Eigen::VectorXd &lo, const Eigen::VectorXd &hi);

struct HoleBlock {
    int start = 0, m = 0; // rows[start, start + m): the hole's positions (contiguous: see rows)
    Eigen::MatrixXd Q;    // 4m x k
    Eigen::VectorXd c;    // k
};

} // namespace cdm::fit_detail

namespace cdm {
// FitOptions::weights (fit.h): a problem's whitening, as Problem computes it.
struct FitWeights {
    std::vector<Eigen::Matrix4d> wh;
    std::vector<fit_detail::HoleBlock> holes;
    std::vector<int> rows; // the positions they are for, in their order
    std::string failure;
};
} // namespace cdm

namespace cdm::fit_detail {

struct Problem {
    Model &m;
    const std::vector<PreparedPos> &pos;
    const FitOptions &opt;
    ReadingEvaluator ev;
    Eigen::VectorXd cur;              // the effects' parameters being evaluated (ev's layout)
    int F = 0;                        // fixture heights with their own x offset (0: none)
    Eigen::VectorXd fx;               // their offsets (mm, jig frame x)
    Eigen::VectorXd scale, lo, hi, init;
    Eigen::MatrixXd Q;                // full = base + Q * free
    std::vector<int> rows;            // positions used
    // Per used position, the inverse of the lower Cholesky factor L of its
    // four mean readings' covariance C = V + dP S dP' (V the pots' noise of
    // the mean, cross-cable terms included; dP the readings' derivative in
    // the position; S = diag(jig_sigma^2), the position's own jig error):
    // generalised least squares, so that a chi-square difference is
    // chi-square distributed. A jig error moves the four readings together
    // (three directions of four); weighing each reading by 1/C_cc alone
    // ignores that, and on clean half jigs candidates' delta chi2 then has
    // 2-2.5 times chi-square(k)'s variance, p < 0.001 in 1-2.5 % of them (a
    // Monte Carlo of 400 seeds; calibrated with the jig's tolerance at
    // zero). The fourth direction,
    // which no position error moves (the cables' redundancy), is then
    // weighed by the pots' noise alone.
    std::vector<Eigen::Matrix4d> wh;
    int evals = 0;
    bool cancelled = false;
    std::string failure;              // a user effect's apply failed: its message
    ReadingEvaluator::Batch batch;    // every used position's readings, when a user effect works on arrays
    std::vector<double> refs, ts;     // their reference positions and times (eval_rows)

    Problem(Model &m_, const std::vector<PreparedPos> &p_, const FitOptions &o_)
        : m(m_), pos(p_), opt(o_), ev(m_) {
        if (opt.fixture_count >= 2 && opt.fixture.size() == pos.size()) F = opt.fixture_count;
        fx = Eigen::VectorXd::Zero(F);
        const int n = ev.size() + F;
        cur = ev.current();
        scale.resize(n);
        lo.resize(n);
        hi.resize(n);
        init.resize(n);
        for (size_t e = 0; e < m.effect_count(); ++e) {
            if (ev.offset(e) < 0) continue;
            const auto &ps = m.effect_desc(e).params;
            for (size_t k = 0; k < ps.size(); ++k) {
                const int a = ev.offset(e) + int(k);
                scale(a) = ps[k].scale;
                lo(a) = ps[k].lower;
                hi(a) = ps[k].upper;
                init(a) = ps[k].init;
            }
        }
        for (int k = 0; k < F; ++k) {
            const int a = ev.size() + k;
            scale(a) = kFixturePriorSdMm; // a machined spacer's tolerance: prior_sd says how it is used
            lo(a) = -kFixtureMaxMm;
            hi(a) = kFixtureMaxMm;
            init(a) = 0;
        }
        build_gauge();
        for (size_t j = 0; j < pos.size(); ++j)
            if (opt.use.empty() || opt.use[j]) rows.push_back(int(j));
        // A hole's positions next to each other: its block of residuals and
        // Jacobian rows is then contiguous (decorrelate works in place).
        if (hole_model())
            std::stable_sort(rows.begin(), rows.end(), [&](int a, int b) {
                return unsigned(opt.hole[size_t(a)]) < unsigned(opt.hole[size_t(b)]); // -1 (none) last
            });
        if (opt.weights && opt.weights->rows == rows) {
            wh = opt.weights->wh;
            holes = opt.weights->holes;
            failure = opt.weights->failure;
        } else if (opt.weigh_with) {
            Model wm = *opt.weigh_with;
            FitOptions wo = opt;
            wo.weigh_with = nullptr;
            wo.weights = nullptr;
            wo.hold.clear();
            Problem wp(wm, pos, wo); // the same positions (opt.use)
            wh = std::move(wp.wh);
            holes = std::move(wp.holes);
            failure = wp.failure;
        } else {
            compute_weights();
        }
    }

    // The plate's holes (FitOptions::hole): a hole's error e (3-vector, sd
    // hole_sigma per axis) moves each of its positions' readings by dP e, so
    // the whitened residuals of a hole's m positions have the covariance
    // I + U U' (U: 4m x 3, the wh dP hole_sigma rows) instead of I.
    // Generalised least squares multiplies them by (I + U U')^(-1/2)
    // = I - Q diag(c) Q', Q the orthonormal directions of U and
    // c = 1 - 1/sqrt(1 + s^2) for its singular values s: the chi-square is
    // then the Gaussian likelihood's, the number of residuals unchanged.
    // Fixed for a problem, like the weights (and taken with them from
    // weigh_with), so the Jacobian is transformed the same way.
    std::vector<HoleBlock> holes;

    bool hole_model() const {
        return opt.hole.size() == pos.size() && (opt.hole_sigma.array() > 0).any();
    }
    void build_holes(const std::vector<Eigen::Matrix<double, 4, 3>> &dPs) {
        holes.clear();
        for (size_t r0 = 0, r1; r0 < rows.size(); r0 = r1) {
            // A position in no known hole (-1) is its own: its share of the
            // hole variance is still its error's (jig_sigma is the rest).
            const int h = opt.hole[size_t(rows[r0])];
            for (r1 = r0 + 1; h >= 0 && r1 < rows.size() && opt.hole[size_t(rows[r1])] == h;) ++r1;
            HoleBlock b;
            b.start = int(r0);
            b.m = int(r1 - r0);
            const int m = b.m;
            Eigen::MatrixXd U(4 * m, 3);
            for (int i = 0; i < m; ++i)
                U.block<4, 3>(4 * i, 0) =
                    wh[size_t(b.start + i)] * dPs[size_t(b.start + i)] * opt.hole_sigma.asDiagonal();
            // U = Q S V': the eigenvectors V of U'U (3 x 3), Q = U V / s.
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(U.transpose() * U);
            // (A solver that did not converge leaves its eigenvalues unset:
            // such a block, non-finite sensitivities, is weighed as its
            // positions' own.)
            if (es.info() != Eigen::Success) continue;
            std::vector<int> keep;
            for (int k = 0; k < 3; ++k)
                if (es.eigenvalues()(k) > 1e-12 * std::max(1.0, es.eigenvalues().maxCoeff())) keep.push_back(k);
            if (keep.empty()) continue;
            b.Q.resize(4 * m, int(keep.size()));
            b.c.resize(int(keep.size()));
            for (size_t q = 0; q < keep.size(); ++q) {
                const double s2 = es.eigenvalues()(keep[q]);
                b.Q.col(int(q)) = U * es.eigenvectors().col(keep[q]) / std::sqrt(s2);
                b.c(int(q)) = 1.0 - 1.0 / std::sqrt(1.0 + s2);
            }
            holes.push_back(std::move(b));
        }
    }
    // res (and J's rows) of each hole block times (I + U U')^(-1/2).
    // The directions are orthonormal, so I - Q diag(c) Q' is the product of
    // the rank-one I - c_q q q' in any order: one dot product and one axpy
    // per direction and column, over the block's contiguous rows (Eigen's
    // general products cost more than they save at 20 x 3).
    void decorrelate(Eigen::VectorXd &res, Eigen::MatrixXd *J) const {
        for (const auto &b : holes) {
            const long r0 = 4L * b.start, len = 4L * b.m;
            for (int q = 0; q < b.Q.cols(); ++q) {
                const auto dir = b.Q.col(q);
                auto v = res.segment(r0, len);
                v -= (b.c(q) * dir.dot(v)) * dir;
                if (!J) continue;
                for (long col = 0; col < J->cols(); ++col) {
                    auto x = J->col(col).segment(r0, len);
                    x -= (b.c(q) * dir.dot(x)) * dir;
                }
            }
        }
    }
    int n_params() const { return ev.size() + F; }

    void build_gauge() {
        const int n = n_params();
        Q = Eigen::MatrixXd::Zero(n, n);
        int col = 0;
        for (size_t e = 0; e < m.effect_count(); ++e) {
            if (ev.offset(e) < 0) continue;
            const int o = ev.offset(e);
            Eigen::MatrixXd B = effect_gauge_basis(m, e);
            for (const auto &h : opt.hold)
                if (h.first == e && h.second < size_t(B.rows())) hold_row(B, int(h.second));
            Q.block(o, col, B.rows(), B.cols()) = B;
            col += int(B.cols());
        }
        // Every fixture offset is free, their common part included: it is
        // the spacers' mean error, which is the jig's placement along x, and
        // the judge takes it out with each height's mean (calib/evaluation/jig.cpp).
        // Under a sum-zero gauge a common x offset of the jig would be left
        // to the device: on clean data with spacers off by 0.03 mm (their
        // mean -0.0085 mm) every candidate that can shift x gains delta chi2
        // ~1730 and the search recommends cable_stretch for it. Where the
        // model has a translation of its own (jig_misalignment,
        // anchor_position, holder_geometry) the two are one direction of the
        // data, told apart by the priors alone: the device's weak prior
        // against the spacers' tolerance, so the device takes it.
        for (int k = 0; k < F; ++k, ++col) Q(ev.size() + k, col) = 1.0;
        Q.conservativeResize(n, col);
    }
    int n_fixture_free() const { return F; }

    // Restricts the basis B (full = base + B * free) to the directions that
    // leave parameter r where it is: the column with the largest entry in
    // row r is eliminated from the others and dropped (exact for any basis,
    // the identity included; the covariance does not depend on the basis).
    static void hold_row(Eigen::MatrixXd &B, int r) {
        if (B.cols() == 0) return;
        Eigen::Index k = 0;
        if (B.row(r).cwiseAbs().maxCoeff(&k) == 0) return; // already fixed by the gauge
        for (Eigen::Index j = 0; j < B.cols(); ++j)
            if (j != k) B.col(j) -= B(r, j) / B(r, k) * B.col(k);
        if (k + 1 < B.cols()) B.block(0, k, B.rows(), B.cols() - k - 1) = B.rightCols(B.cols() - k - 1).eval();
        B.conservativeResize(B.rows(), B.cols() - 1);
        B.row(r).setZero(); // round-off
    }

    void set_full(const Eigen::VectorXd &full) {
        cur = full.head(ev.size());
        fx = full.tail(F);
    }
    Eigen::VectorXd get_full() const {
        Eigen::VectorXd full(n_params());
        full << cur, fx;
        return full;
    }

    // Writes the parameters back into the model, clamped to their bounds
    // (SLSQP honours them to its constraint tolerance, 1e-9).
    void commit() {
        for (size_t e = 0; e < m.effect_count(); ++e) {
            if (ev.offset(e) < 0) continue;
            std::vector<double> v(m.effect_params(e).size());
            for (size_t k = 0; k < v.size(); ++k) {
                const int a = ev.offset(e) + int(k);
                v[k] = std::clamp(cur(a), lo(a), hi(a));
            }
            std::string err;
            if (!m.set_effect_params(e, v, err) && failure.empty()) failure = err;
        }
    }

    // Predicted readings and d(readings)/d(effect params) at position j
    // (its fixture height's offset applied to the reference).
    void reference(size_t j, double ref[3]) const {
        const PreparedPos &pp = pos[j];
        ref[0] = pp.ref(0) + (F > 0 ? fx(opt.fixture[j]) : 0.0);
        ref[1] = pp.ref(1);
        ref[2] = pp.ref(2);
    }
    bool eval_position(size_t j, Eigen::Vector4d &y, Eigen::Matrix<double, 4, Eigen::Dynamic> *J,
                       Eigen::Matrix<double, 4, 3> *dydP, int dydP_cols = 3) {
        double ref[3];
        reference(j, ref);
        std::string err;
        if (ev.eval(cur, ref, pos[j].t_s, y, J, dydP, &err, dydP_cols)) return true;
        if (failure.empty()) failure = err;
        return false;
    }
    // Every used position at once into `batch`, when a user effect works on
    // arrays: its apply_batch is then called once per central-difference
    // step, not once per position and step (a Python effect: numpy over
    // all positions instead of a call into the interpreter for each).
    bool eval_rows(bool want_J, bool want_dydP) {
        refs.resize(3 * rows.size());
        ts.resize(rows.size());
        for (size_t r = 0; r < rows.size(); ++r) {
            reference(size_t(rows[r]), &refs[3 * r]);
            ts[r] = pos[size_t(rows[r])].t_s;
        }
        std::string err;
        if (ev.eval_batch(cur, rows.size(), refs.data(), ts.data(), want_J, want_dydP, batch, &err)) return true;
        if (failure.empty()) failure = err;
        return false;
    }

    void compute_weights() {
        wh.resize(rows.size());
        const Eigen::Matrix3d S = opt.jig_sigma.cwiseAbs2().asDiagonal();
        const bool batched = ev.has_batch();
        const bool batch_ok = batched && eval_rows(false, true);
        std::vector<Eigen::Matrix<double, 4, 3>> dPs;
        if (hole_model()) dPs.resize(rows.size());
        over_rows([&](size_t r0, size_t r1) {
            for (size_t r = r0; r < r1; ++r) {
                const auto &pp = pos[rows[r]];
                Eigen::Vector4d y;
                Eigen::Matrix<double, 4, 3> dP;
                if (batched)
                    dP = batch_ok ? batch.dydP[r] : Eigen::Matrix<double, 4, 3>::Zero();
                else if (!eval_position(size_t(rows[r]), y, nullptr, &dP)) // (a user effect: on one thread)
                    dP.setZero();
                Eigen::Matrix4d C = pp.cov_mean;
                C.diagonal() = pp.var_mean;
                // (A derivative that is not a number, a degenerate geometry:
                // the pots' noise alone, rather than a weight of zero that would
                // drop the position from a chi-square that still counts it.)
                if (dP.allFinite()) C += dP * S * dP.transpose();
                const Eigen::LLT<Eigen::Matrix4d> llt(C);
                if (C.allFinite() && llt.info() == Eigen::Success &&
                    llt.matrixL().toDenseMatrix().diagonal().minCoeff() > 0) {
                    wh[r] = llt.matrixL().solve(Eigen::Matrix4d::Identity());
                } else { // (not positive definite: NaN readings' derivatives) each reading alone
                    wh[r].setZero();
                    for (int c = 0; c < 4; ++c) wh[r](c, c) = C(c, c) > 0 ? 1.0 / std::sqrt(C(c, c)) : 0.0;
                }
                if (!dPs.empty()) dPs[r] = dP.allFinite() ? dP : Eigen::Matrix<double, 4, 3>::Zero();
            }
            return true;
        });
        if (!dPs.empty()) build_holes(dPs);
    }

    // L v for a lower-triangular 4 x 4 L, written out: Eigen's triangular
    // products go through its general matrix-product kernels, whose packing
    // cost more than the ten multiplications (a fifth of a diagnosis).
    static Eigen::Vector4d lower4(const Eigen::Matrix4d &L, const Eigen::Vector4d &v) {
        return {L(0, 0) * v(0), L(1, 0) * v(0) + L(1, 1) * v(1), L(2, 0) * v(0) + L(2, 1) * v(1) + L(2, 2) * v(2),
                L(3, 0) * v(0) + L(3, 1) * v(1) + L(3, 2) * v(2) + L(3, 3) * v(3)};
    }

    // body(r0, r1) for the used positions' rows [r0, r1), in contiguous
    // ranges on opt.threads threads (this one included) when the model has
    // no user effect (FitOptions::threads) and each range has at least
    // kRowsPerThread rows; in one range otherwise. Each range writes only
    // its own rows, so the result does not depend on the number of
    // threads. False when a range's body is. An exception in a range is
    // rethrown here once every range has ended.
    static constexpr size_t kRowsPerThread = 256;
    template <class Body> bool over_rows(Body &&body) const {
        const bool threaded = opt.threads > 1 && !ev.has_user() && !ev.has_batch();
        return in_ranges(rows.size(), threaded ? size_t(opt.threads) : 1, kRowsPerThread, body);
    }

    // Whitened residuals (wh (mean - y)) and Jacobian of y. False
    // when a user effect's apply fails (message in `failure`).
    bool residuals(Eigen::VectorXd &res, Eigen::MatrixXd *J) {
        const int n = n_params();
        res.resize(4 * int(rows.size()));
        if (J) J->resize(4 * int(rows.size()), n);
        if (J && F > 0) J->rightCols(F).setZero(); // the rest is written below
        const bool batched = ev.has_batch();
        if (batched && !eval_rows(J != nullptr, J && F > 0)) return false;
        const bool ok = over_rows([&](size_t r0, size_t r1) {
            Eigen::Matrix<double, 4, Eigen::Dynamic> Jp(4, ev.size());
            Eigen::Matrix<double, 4, 3> dP;
            for (size_t r = r0; r < r1; ++r) {
                const size_t j = size_t(rows[r]);
                const auto &pp = pos[j];
                Eigen::Vector4d y;
                if (batched) {
                    y = batch.y[r];
                    if (J) Jp = batch.J[r];
                    if (J && F > 0) dP = batch.dydP[r];
                } else if (!eval_position(j, y, J ? &Jp : nullptr, J && F > 0 ? &dP : nullptr, 1)) {
                    return false; // (a user effect: on one thread)
                }
                const Eigen::Matrix4d &L = wh[r]; // lower triangular
                res.segment<4>(4 * long(r)) = lower4(L, pp.mean - y);
                if (!J) continue;
                // The position's four rows at once: each column's four entries
                // are adjacent in the column-major J.
                for (int k = 0; k < ev.size(); ++k) J->block<4, 1>(4 * long(r), k) = lower4(L, Jp.col(k));
                // d y / d (jig-frame x): the device-frame x derivative; the
                // jig's rotation (a few mrad) is left out of this column.
                if (F > 0) J->block<4, 1>(4 * long(r), ev.size() + opt.fixture[j]) = lower4(L, dP.col(0));
            }
            return true;
        });
        if (!ok) return false;
        decorrelate(res, J);
        return true;
    }

    // The fixture offsets alone fitted at the current effect parameters
    // (Gauss-Newton; nearly linear in them): the chi-square a model has
    // with the jig as it is.
    bool profile_fixture() {
        if (F == 0) return true;
        Eigen::MatrixXd Qf = Q.bottomRows(F).rightCols(F);
        for (int it = 0; it < 3; ++it) {
            Eigen::VectorXd res;
            Eigen::MatrixXd J;
            if (!residuals(res, &J)) return false;
            Eigen::MatrixXd A = J.rightCols(F) * Qf;
            // With the fixture offsets' prior (prior_sd), as in the fit:
            // minimises |res - A step|^2 + sum_k ((fx + Qf step)_k / sd)^2.
            const double p = 1.0 / (kFixturePriorSdMm * kFixturePriorSdMm);
            // Within the bounds: the bounded step, not the free one clamped
            // (when the offsets summed to zero, the clamp added a common
            // offset no fit could have, so model_chi2 came out below what
            // any fit of the same model could reach and candidates read
            // delta chi2 -629485; clamped coordinate by coordinate it is
            // still not the box's optimum).
            const Eigen::MatrixXd H = A.transpose() * A + p * Qf.transpose() * Qf;
            const Eigen::VectorXd g = -(A.transpose() * res - p * Qf.transpose() * fx);
            const Eigen::VectorXd lo = Eigen::VectorXd::Constant(F, -kFixtureMaxMm);
            const Eigen::VectorXd hi = Eigen::VectorXd::Constant(F, kFixtureMaxMm);
            const BoundedStep st = bounded_gauss_newton(H, g, fx, Qf, lo, hi);
            fx = (fx + Qf * st.u).cwiseMax(-kFixtureMaxMm).cwiseMin(kFixtureMaxMm); // round-off only
        }
        return true;
    }

    // The prior's standard deviation of parameter a. A model parameter's is
    // weak: 10x its typical size, only there to keep near-degenerate
    // combinations finite. A fixture height's offset is a random effect
    // drawn from the spacers' tolerance (kFixturePriorSdMm, fit.h): where the
    // data cannot tell an offset pattern from a combination of the device's
    // parameters (a scale-like trend over the heights against cable_stretch
    // or holder_geometry), the offsets stay at what the spacers plausibly
    // are and the device's parameters take the rest. With a weak prior the
    // fit drifts along that valley to offsets of 0.19 mm on data with none,
    // or, capped at 0.15 mm, stops there with chi2/dof 1.9
    // (docs/calibration.md, "The jig as it is"). Where the data do see an
    // offset (a height's mean, known to a few micrometres) this prior moves
    // it by well under one percent.
    double prior_sd(int a) const { return a >= ev.size() ? scale(a) : 10 * scale(a); }

    double prior(const Eigen::VectorXd &full, Eigen::VectorXd *grad) const {
        double s = 0;
        if (grad) grad->setZero(full.size());
        for (int a = 0; a < full.size(); ++a) {
            const double sd = prior_sd(a);
            const double z = (full(a) - init(a)) / sd;
            s += z * z;
            if (grad) (*grad)(a) = 2 * z / sd;
        }
        return s;
    }
};

// The parameters' covariance robust to errors a plate hole's positions
// share beyond the weights (covariance.cpp): C M C, C the model's
// covariance (n_params x n_params, gauge and priors in it), J and res the
// whitened Jacobian and residuals at the end of a fit.
Eigen::MatrixXd clustered_covariance(const Problem &pb, const Eigen::MatrixXd &C, const Eigen::MatrixXd &J,
                                     const Eigen::VectorXd &res);

} // namespace cdm::fit_detail
