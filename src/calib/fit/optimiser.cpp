// NLopt fit of the model's effect parameters.
//
// Algorithm: Gauss-Newton steps within the bounds first (bounded_gauss_newton:
// the linearised problem's minimum, a small box-constrained quadratic
// programme), each taken when it gains at least a quarter of its promise,
// while the next promises at most a tenth of the last (at most
// kGaussNewtonSteps); on a problem nearly linear in its parameters (most of
// a model search's fits) two or three such steps reach the minimum. Then, for
// whatever is left (a ripple's period, nearly degenerate anchors),
// NLOPT_LD_SLSQP (sequential quadratic programming with a BFGS
// Hessian, bounds as linear constraints) in *whitened* coordinates: at the
// start point the Gauss-Newton Hessian J'WJ (plus a weak prior) is
// eigendecomposed and the parameters rescaled so that it is the identity.
// SLSQP's first Hessian guess is the identity, so it starts right and
// converges in few evaluations even when parameters are strongly correlated
// (anchor positions against pot offsets); parameters in mm, rad and 1/mm
// need no hand scaling. The whitening is redone at the solution and the fit
// repeated until the objective stops falling (usually two passes). A pass
// ends early once SLSQP's line search only probes round-off (kStallF below),
// and its first evaluation, at the whitening point, is the one the pass
// start already made.
// Derivatives: model/evaluator.h (forward-mode automatic differentiation of
// the templated kernel generated from effects/list.h, seeded on the position
// and each cable's own parameters and scattered into the full Jacobian;
// central differences through user-defined effects).
//
// Gauge (built in problem.h, with the residuals, weights and prior):
// parameters that change nothing measurable are fixed, not left to wander
// (each effect's gauge() in its file says which): with jig_misalignment on,
// the anchors' common rigid motion (3
// translations, 3 small rotations) is the jig's and is projected out of
// anchor_position; the holder points' common translation is the jig's (or the
// anchors') and is projected out of holder_geometry; cable_stretch's s0 is the
// common part of cable_gain and its s1 that of pot_nonlinearity, fixed when
// those are on. A weak Gaussian prior (10x each parameter's typical size)
// keeps the remaining near-degenerate combinations finite; it never binds
// for a well-determined parameter.
#include "calib/fit/fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include <nlopt.h>

#include "calib/fit/problem.h"

namespace cdm {

namespace {

using fit_detail::BoundedStep;
using fit_detail::bounded_gauss_newton;
using fit_detail::Problem;
using fit_detail::clustered_covariance;

struct Whitened {
    Problem *pb;
    Eigen::VectorXd base;   // full params at the whitening point
    Eigen::MatrixXd T;      // full = base + T * zeta
    double best = INFINITY;
    Eigen::VectorXd best_full;
    nlopt_opt opt = nullptr; // the running optimiser, for nlopt_force_stop
    // The residual and Jacobian at best_full when that evaluation asked for
    // the gradient (most of SLSQP's do): the next pass starts there, and the
    // final statistics are taken there, without evaluating the point again.
    Eigen::VectorXd best_res = Eigen::VectorXd();
    Eigen::MatrixXd best_J = Eigen::MatrixXd();
    bool best_has_J = false;
    Eigen::MatrixXd scratch_J = Eigen::MatrixXd();
    // The residual and Jacobian at `base` (zeta = 0), which the pass start
    // already has: SLSQP's first call asks for exactly that point.
    Eigen::VectorXd seed_res = Eigen::VectorXd();
    Eigen::MatrixXd seed_J = Eigen::MatrixXd();
    bool seeded = false;
    // Successive evaluations within kStallF of the best so far (see objective).
    int stall = 0;
    bool stalled = false;
    // FitOptions::abandon_above, by index in the full parameter vector.
    std::vector<std::pair<int, double>> abandon = {};
    bool abandoned = false;
};

// SLSQP checks convergence only when a line search completes. At a minimum
// its backtracking line search can go on for ten or more evaluations whose
// objective differs from the best only by round-off (a fifth to a third of
// a diagnosis's evaluations were such). The pass stops once three
// successive evaluations lie within kStallF of the best objective
// (chi-square / 2) so far: a stopping rule, not a bound on the distance to
// the minimum; measured against running to SLSQP's own tolerance, the
// diagnosis's chi-square differences moved by at most 3e-4, where its tests
// compare differences of order one and it prints tenths.
constexpr double kStallF = 1e-4;
constexpr int kStallEvals = 3;
// A pass start whose Gauss-Newton step promises less than this (in the
// objective, chi-square / 2) is the minimum: ten times finer than the stall
// stop's resolution.
constexpr double kConvergedF = 0.1 * kStallF;
// Gauss-Newton steps per fit before SLSQP takes over (refused ones count).
constexpr int kGaussNewtonSteps = 8;
// A refused step's damping (Levenberg-Marquardt, in the Hessian's scaled
// coordinates, where its diagonal is one): from kMinDamping, tenfold per
// refusal, up to kMaxDamping (a step then a thousandth of the gradient's
// descent), after which SLSQP takes over.
constexpr double kMinDamping = 1e-3;
constexpr double kMaxDamping = 1e3;

double objective(unsigned n, const double *z, double *grad, void *data) {
    auto *W = static_cast<Whitened *>(data);
    Problem &pb = *W->pb;
    Eigen::Map<const Eigen::VectorXd> zeta(z, n);
    Eigen::VectorXd full = W->base + W->T * zeta;
    pb.set_full(full);
    Eigen::VectorXd res;
    Eigen::MatrixXd J;
    bool from_seed = false;
    if (W->seeded && std::all_of(z, z + n, [](double v) { return v == 0.0; })) {
        // base + T * 0 is base: the pass start's own evaluation.
        W->seeded = false;
        res = std::move(W->seed_res);
        if (grad) J = std::move(W->seed_J);
        from_seed = true;
    } else if (grad) {
        std::swap(J, W->scratch_J); // reuse the last call's storage
    }
    if (!from_seed && !pb.residuals(res, grad ? &J : nullptr)) {
        // A user effect failed: stop (a NULL handle would be refused, and
        // SLSQP would call the failing effect until max_evals); fit_model
        // reports it.
        if (grad) std::fill(grad, grad + n, 0.0);
        if (W->opt) nlopt_force_stop(W->opt);
        return 1e300;
    }
    Eigen::VectorXd pg;
    double f = 0.5 * (res.squaredNorm() + pb.prior(full, grad ? &pg : nullptr));
    if (!std::isfinite(f)) f = 1e300;
    if (grad) {
        Eigen::VectorXd gfull = -J.transpose() * res + 0.5 * pg;
        Eigen::Map<Eigen::VectorXd>(grad, n) = W->T.transpose() * gfull;
    }
    ++pb.evals;
    // (1e300 stands for a point that could not be evaluated: never a stall.)
    if (f < 1e300 && std::fabs(f - W->best) <= kStallF) {
        if (++W->stall >= kStallEvals && W->opt) {
            W->stalled = true;
            nlopt_force_stop(W->opt);
        }
    } else {
        W->stall = 0;
    }
    if (f < W->best) {
        W->best = f;
        W->best_full = full;
        W->best_has_J = grad != nullptr;
        if (grad) {
            std::swap(W->best_res, res);
            std::swap(W->best_J, J); // the previous best's storage is reused
        }
        // The best point so far past a value its result is not wanted
        // beyond (FitOptions::abandon_above): the fit stops there, on it. (A
        // line-search trial past the value that does not lower the
        // objective is only a trial: SLSQP steps back from it.)
        for (auto [a, v] : W->abandon)
            if (full(a) > v) {
                W->abandoned = true;
                if (W->opt) nlopt_force_stop(W->opt);
            }
    }
    if (grad && J.size()) std::swap(J, W->scratch_J);
    // Progress (and with it a cancel) at a fit's first evaluation and every
    // fifth after: a fit of a few Gauss-Newton steps reports too.
    if (pb.opt.progress && pb.evals % 5 == 1 && !pb.opt.progress(std::min(1.0, pb.evals / double(pb.opt.max_evals))))
        pb.cancelled = true;
    if (pb.cancelled && W->opt) nlopt_force_stop(W->opt);
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

// The Gauss-Newton Hessian of the objective in the free coordinates,
// Q' (J'J + the prior's) Q. J'J (parameters x parameters) by a symmetric rank
// update of the residual rows: half the work of forming J Q and its square,
// which a pass start, and every Gauss-Newton step, pays.
Eigen::MatrixXd free_hessian(const Problem &pb, const Eigen::MatrixXd &J) {
    const int n = pb.n_params();
    Eigen::MatrixXd JtJ = Eigen::MatrixXd::Zero(n, n);
    JtJ.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
    for (int a = 0; a < n; ++a) JtJ(a, a) += 1.0 / (pb.prior_sd(a) * pb.prior_sd(a));
    return pb.Q.transpose() * JtJ.selfadjointView<Eigen::Lower>() * pb.Q;
}

// One fit_model call: the problem, the report, and what the passes carry
// from one to the next.
struct FitRun {
    FitRun(Model &m_, const std::vector<PreparedPos> &pos, const FitOptions &opt_, FitReport &rep_)
        : m(m_), opt(opt_), rep(rep_), pb(m_, pos, opt_) {}

    // What a stage of a pass leaves the passes to do.
    enum class Next { Fail, Stop, Again, Slsqp, NextPass };

    Model &m;
    const FitOptions &opt;
    FitReport &rep;
    const std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
    Problem pb;
    int nfree = 0;
    double prev = INFINITY;
    bool ok = true;
    // The last residual and Jacobian evaluated, and where: a pass starts at
    // the previous pass's best point, whose evaluation SLSQP already made
    // (with the gradient), and the statistics below are taken at the point
    // the fit ends on; neither is evaluated again when it is the same point
    // bit for bit (the evaluation is a pure function of the parameters).
    Eigen::VectorXd have_at, have_res;
    Eigen::MatrixXd have_J;
    // Gauss-Newton steps (within the bounds) go first: on a problem that is
    // nearly linear in its parameters (most of a search's fits) each lands
    // almost on the minimum, where an SLSQP pass spends 5-20 evaluations. They
    // stop at the first step whose gain falls short of what the quadratic
    // model promised (a quarter; the step is then not taken) or that leaves
    // more than a tenth of its promise for the next (slow, nearly degenerate
    // convergence, which SLSQP's updated Hessian handles better); SLSQP
    // passes take it from there.
    bool gauss_newton = true;
    double last_pred = INFINITY;
    double mu = 0; // the Gauss-Newton steps' damping (0: none)

    bool fail() {
        rep.message = "fit failed: " + pb.failure;
        rep.converged = false;
        rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        return false;
    }
    bool take(const Eigen::VectorXd &at, Eigen::VectorXd &res, Eigen::MatrixXd &J) {
        if (have_at.size() != at.size() || have_at.size() == 0 || have_J.size() == 0 ||
            std::memcmp(have_at.data(), at.data(), sizeof(double) * size_t(at.size())) != 0)
            return pb.residuals(res, &J);
        res = std::move(have_res);
        J = std::move(have_J);
        have_at.resize(0);
        return true;
    }
    void keep(const Eigen::VectorXd &at, Eigen::VectorXd &res, Eigen::MatrixXd &J) {
        have_at = at;
        have_res = std::move(res);
        have_J = std::move(J);
    }

    bool run();
    bool nothing_free();
    Next gauss_newton_pass(Whitened &W, const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> &es,
                           const Eigen::VectorXd &lam, const Eigen::MatrixXd &QD, const Eigen::VectorXd &full,
                           Eigen::VectorXd &res, Eigen::MatrixXd &J, int &steps);
    bool single_step(const BoundedStep &st0, double f0, const Eigen::MatrixXd &QD, const Eigen::VectorXd &full);
    Next damped_steps(const Whitened &W, const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> &es,
                      const Eigen::VectorXd &lam, const BoundedStep &st0, double f0, const Eigen::VectorXd &gu,
                      const Eigen::MatrixXd &H, const Eigen::MatrixXd &QD, const Eigen::VectorXd &full, int &steps);
    bool at_minimum(const Whitened &W, const Eigen::VectorXd &full, Eigen::VectorXd &res, Eigen::MatrixXd &J);
    Next slsqp_pass(Whitened &W, const Eigen::VectorXd &full, Eigen::VectorXd &res, Eigen::MatrixXd &J);
    bool finish();
};

bool FitRun::run() {
    rep = FitReport{};
    rep.algorithm = "Gauss-Newton within the bounds, then NLOPT_LD_SLSQP (whitened by the Gauss-Newton Hessian)";
    nfree = int(pb.Q.cols());
    rep.n_free = nfree - pb.n_fixture_free();
    rep.n_fixture = pb.n_fixture_free();
    rep.n_obs = 4 * int(pb.rows.size());
    if (!pb.failure.empty()) return fail(); // while weighting
    if (opt.profile_fixture_start && !pb.profile_fixture()) return fail();
    if (nfree == 0) return nothing_free();
    Eigen::MatrixXd Hfree;
    for (int pass = 0, steps = 0; pass < 4 && pb.evals < opt.max_evals;) {
        Eigen::VectorXd full = pb.get_full();
        pb.set_full(full);
        Eigen::VectorXd res;
        Eigen::MatrixXd J;
        if (!take(full, res, J)) return fail();
        Hfree = free_hessian(pb, J);
        // Eigendecomposed with its diagonal scaled to one (D H D, D =
        // diag(H)^(-1/2)): the free parameters are in mm, rad, 1/mm and the
        // fixture's mm, so H's eigenvalues span 14 to 17 decades, and the
        // solver's eigenvalues are accurate to eps times the largest only.
        // Unscaled, the directions the data barely fix (an anchor
        // translation against the fixture offsets and the pot offsets) had
        // eigenvalues below that floor, raised to it: the Gauss-Newton
        // steps were a fraction of the true one there (each gained 1.7-1.9
        // times what it promised) and the whitening made SLSQP creep along
        // them (20-40 evaluations per fit of a search step with
        // anchor_position). Scaled, the spread is what the data's own
        // correlations make it, a few decades.
        const Eigen::VectorXd D = Hfree.diagonal().cwiseMax(std::numeric_limits<double>::min()).cwiseSqrt().cwiseInverse();
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(D.asDiagonal() * Hfree * D.asDiagonal());
        Eigen::VectorXd lam = es.eigenvalues().cwiseMax(1e-12 * es.eigenvalues().maxCoeff());
        const Eigen::MatrixXd QD = pb.Q * D.asDiagonal(); // free = D * scaled
        Whitened W{&pb, full, QD * es.eigenvectors() * lam.cwiseSqrt().cwiseInverse().asDiagonal(), INFINITY, full};
        for (auto &[at, v] : opt.abandon_above)
            if (at.first < m.effect_count() && pb.ev.offset(at.first) >= 0 && at.second < m.effect_params(at.first).size())
                W.abandon.emplace_back(pb.ev.offset(at.first) + int(at.second), v);
        if (gauss_newton && steps < kGaussNewtonSteps) {
            const Next n = gauss_newton_pass(W, es, lam, QD, full, res, J, steps);
            if (n == Next::Fail) return fail();
            if (n == Next::Stop) break;
            if (n == Next::Again) continue;
        }
        if (at_minimum(W, full, res, J)) break;
        const Next n = slsqp_pass(W, full, res, J);
        if (n == Next::Fail) return fail();
        if (n == Next::Stop) break;
        ++pass;
    }
    return finish();
}

bool FitRun::nothing_free() {
    Eigen::VectorXd res;
    if (!pb.residuals(res, nullptr)) return fail();
    rep.chi2 = res.squaredNorm();
    rep.converged = true;
    for (size_t e = 0; e < m.effect_count(); ++e) rep.std.emplace_back(m.effect_params(e).size(), 0.0);
    return true;
}

FitRun::Next FitRun::gauss_newton_pass(Whitened &W, const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> &es,
                                       const Eigen::VectorXd &lam, const Eigen::MatrixXd &QD,
                                       const Eigen::VectorXd &full, Eigen::VectorXd &res, Eigen::MatrixXd &J,
                                       int &steps) {
    Eigen::VectorXd pg;
    const double f0 = 0.5 * (res.squaredNorm() + pb.prior(full, &pg));
    // In the scaled free coordinates (QD).
    const Eigen::VectorXd gu = QD.transpose() * (-J.transpose() * res + 0.5 * pg);
    const Eigen::MatrixXd H = es.eigenvectors() * lam.asDiagonal() * es.eigenvectors().transpose();
    const BoundedStep st0 = bounded_gauss_newton(H, gu, full, QD, pb.lo, pb.hi);
    if (st0.kkt && std::isfinite(f0) && st0.pred <= std::max(1e-12 * std::fabs(f0), kConvergedF)) {
        // At the minimum of the linearised problem within the
        // bounds: nothing left that a pass could gain.
        rep.converged = true;
        keep(full, res, J);
        return Next::Stop;
    }
    if (opt.single_step) return single_step(st0, f0, QD, full) ? Next::Stop : Next::Fail;
    return damped_steps(W, es, lam, st0, f0, gu, H, QD, full, steps);
}

// One step, its chi-square without a Jacobian (FitOptions::single_step):
// kept when it lowers the objective.
bool FitRun::single_step(const BoundedStep &st0, double f0, const Eigen::MatrixXd &QD, const Eigen::VectorXd &full) {
    if (st0.kkt && std::isfinite(f0)) {
        const Eigen::VectorXd full1 = full + QD * st0.u;
        pb.set_full(full1);
        Eigen::VectorXd r1;
        if (!pb.residuals(r1, nullptr)) return false;
        ++pb.evals;
        if (0.5 * (r1.squaredNorm() + pb.prior(full1, nullptr)) < f0) {
            have_at = full1;
            have_res = std::move(r1);
            have_J.resize(0, 0);
        } else {
            pb.set_full(full);
        }
    }
    rep.converged = true;
    return true;
}

// A step that falls short of its promise is retried shorter,
// Levenberg-Marquardt's way (H + mu I in the scaled coordinates,
// whose diagonal is one; mu from 1e-3, ten times larger at each
// refusal, a third at each success), from the same pass start and
// its Jacobian, within the Gauss-Newton budget. A period that
// the linearised problem sends far past where its sines still
// look alike (a ripple's joint fit on a model far from the data)
// made the first step raise the objective 10-80 fold; handed to
// SLSQP from there, such a fit took 190-230 evaluations.
FitRun::Next FitRun::damped_steps(const Whitened &W, const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> &es,
                                  const Eigen::VectorXd &lam, const BoundedStep &st0, double f0,
                                  const Eigen::VectorXd &gu, const Eigen::MatrixXd &H, const Eigen::MatrixXd &QD,
                                  const Eigen::VectorXd &full, int &steps) {
    while (st0.kkt && std::isfinite(f0) && steps < kGaussNewtonSteps) {
        const BoundedStep st =
            mu > 0 ? bounded_gauss_newton(H + mu * Eigen::MatrixXd::Identity(H.rows(), H.cols()), gu, full, QD,
                                          pb.lo, pb.hi)
                   : st0;
        if (!st.kkt) break;
        // What the (undamped) quadratic model promises for this step.
        const double pred = -(gu.dot(st.u) + 0.5 * st.u.dot(H * st.u));
        Whitened G = W; // the trial's own bookkeeping; W stays for SLSQP
        G.best = f0;
        const Eigen::VectorXd zeta = lam.cwiseSqrt().asDiagonal() * (es.eigenvectors().transpose() * st.u);
        Eigen::VectorXd grad(nfree);
        const double f1 = objective(unsigned(nfree), zeta.data(), grad.data(), &G);
        ++steps;
        if (!pb.failure.empty()) return Next::Fail;
        const bool take_step = f1 < f0 && f0 - f1 >= 0.25 * pred && G.best_has_J && !pb.cancelled;
        // objective() left the problem at the trial point: back to
        // the pass start unless the step is taken, the point the
        // rest of the pass holds the residuals of, so that neither a
        // cancel nor the convergence check below commits a trial
        // that was refused.
        if (!take_step) pb.set_full(full);
        if (pb.cancelled) {
            rep.message = "fit cancelled";
            ok = false;
            return Next::Stop;
        }
        if (!take_step) {
            if (mu >= kMaxDamping) break;
            mu = mu > 0 ? 10 * mu : kMinDamping;
            continue;
        }
        pb.set_full(G.best_full);
        keep(G.best_full, G.best_res, G.best_J);
        if (G.abandoned) {
            rep.abandoned = true;
            rep.message = "abandoned: a parameter went past the value its result was wanted for";
            return Next::Stop;
        }
        // Slow convergence (a full step that leaves more than a tenth
        // of its promise for the next) goes to SLSQP, whose updated
        // Hessian handles it better.
        if (mu == 0 && st.pred > 0.1 * last_pred) gauss_newton = false;
        if (mu == 0) last_pred = st.pred;
        mu = mu > 3 * kMinDamping ? mu / 3 : 0.0;
        prev = f1;
        return Next::Again;
    }
    gauss_newton = false; // the pass goes to SLSQP from this point
    return Next::Slsqp;
}

// Already at the minimum? In the whitened coordinates the
// Gauss-Newton Hessian is the identity, so a Gauss-Newton step
// would lower the objective by |g|^2 / 2. When that is below
// SLSQP's own relative tolerance (1e-12), or kConvergedF, a pass
// can only confirm the point, spending 15-20 evaluations on
// round-off-level changes (after every converged pass, a quarter
// of a search's evaluations), so the fit stops here. A point on a
// bound has a gradient and is polished by SLSQP.
bool FitRun::at_minimum(const Whitened &W, const Eigen::VectorXd &full, Eigen::VectorXd &res, Eigen::MatrixXd &J) {
    Eigen::VectorXd pg;
    const double f0 = 0.5 * (res.squaredNorm() + pb.prior(full, &pg));
    const Eigen::VectorXd gz = W.T.transpose() * (-J.transpose() * res + 0.5 * pg);
    if (std::isfinite(f0) && 0.5 * gz.squaredNorm() <= std::max(1e-12 * std::fabs(f0), kConvergedF)) {
        rep.converged = true;
        keep(full, res, J);
        return true;
    }
    return false;
}

// An SLSQP pass from the whitening point, bounds as linear constraints.
FitRun::Next FitRun::slsqp_pass(Whitened &W, const Eigen::VectorXd &full, Eigen::VectorXd &res, Eigen::MatrixXd &J) {
    W.seed_res = std::move(res);
    W.seed_J = std::move(J);
    W.seeded = true;
    nlopt_opt o = nlopt_create(NLOPT_LD_SLSQP, unsigned(nfree));
    W.opt = o;
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
    if (!pb.failure.empty()) return Next::Fail;
    if (W.best_has_J) keep(W.best_full, W.best_res, W.best_J);
    if (pb.cancelled) {
        rep.message = "fit cancelled";
        ok = false;
        return Next::Stop;
    }
    if (W.abandoned) {
        rep.abandoned = true;
        rep.message = "abandoned: a parameter went past the value its result was wanted for";
        return Next::Stop;
    }
    if (r < 0 && r != NLOPT_ROUNDOFF_LIMITED && !(r == NLOPT_FORCED_STOP && W.stalled)) {
        rep.message = std::string("NLopt stopped: ") + nlopt_result_to_string(r);
    }
    // Converged when the pass gained nothing, or, for a pass ended by the
    // stall stop, no more than the stop's own resolution.
    if (prev - W.best <= 1e-9 * std::fabs(W.best) + 1e-9 || (W.stalled && prev - W.best <= kStallF)) {
        rep.converged = true;
        return Next::Stop;
    }
    prev = W.best;
    return Next::NextPass;
}

// The fitted values committed (clamped to the bounds), the chi-square at
// them, and the parameters' standard errors.
bool FitRun::finish() {
    pb.commit();
    pb.cur = pb.ev.current(); // as committed: clamped to the bounds
    pb.fx = pb.fx.cwiseMax(-kFixtureMaxMm).cwiseMin(kFixtureMaxMm);
    rep.fixture_mm.assign(pb.fx.data(), pb.fx.data() + pb.fx.size());
    Eigen::VectorXd res;
    Eigen::MatrixXd J;
    const Eigen::VectorXd at_end = pb.get_full();
    const bool have_end = have_at.size() == at_end.size() && have_at.size() > 0 &&
                          std::memcmp(have_at.data(), at_end.data(), sizeof(double) * size_t(at_end.size())) == 0;
    if (!opt.statistics && have_end) {
        res = std::move(have_res); // the chi-square alone
    } else if (!opt.statistics) {
        if (!pb.residuals(res, nullptr)) return fail();
    } else if (!take(at_end, res, J)) {
        return fail();
    }
    rep.chi2 = res.squaredNorm();
    rep.evals = pb.evals;
    if (!rep.converged && rep.message.empty()) rep.message = "evaluation budget spent before convergence";
    if (!opt.statistics) {
        for (size_t e = 0; e < m.effect_count(); ++e) rep.std.emplace_back(m.effect_params(e).size(), 0.0);
    } else {
        // Parameter std from the Gauss-Newton covariance, inflated by chi2/dof
        // when the residual is larger than the weights claim.
        const Eigen::MatrixXd H = free_hessian(pb, J);
        Eigen::MatrixXd C = pb.Q * H.ldlt().solve(Eigen::MatrixXd::Identity(nfree, nfree)) * pb.Q.transpose();
        const double dof = std::max(1, rep.n_obs - nfree);
        const double infl = std::max(1.0, rep.chi2 / dof);
        rep.cov_by_hole = clustered_covariance(pb, C, J, res).topLeftCorner(pb.ev.size(), pb.ev.size());
        rep.std.clear();
        for (size_t e = 0; e < m.effect_count(); ++e) {
            std::vector<double> s(m.effect_params(e).size(), 0.0);
            if (pb.ev.offset(e) >= 0)
                for (size_t k = 0; k < s.size(); ++k) {
                    const int a = pb.ev.offset(e) + int(k);
                    s[k] = std::sqrt(std::max(0.0, C(a, a)) * infl);
                }
            rep.std.push_back(s);
        }
    }
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return ok;
}

} // namespace

bool fit_model(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt, FitReport &rep) {
    FitRun run(m, pos, opt, rep);
    return run.run();
}

} // namespace cdm
