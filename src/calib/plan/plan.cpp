// See plan.h.
#include "calib/plan/plan.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/non_central_chi_squared.hpp>

#include "calib/fit/fit.h"
#include "jig/planned.h"
#include "model/effect.h"
#include "model/evaluator.h"

namespace cdm {

namespace {

using Mat4X = Eigen::Matrix<double, 4, Eigen::Dynamic>;

// A plate position's state in a design: free to choose, chosen (or measured
// already), or not to be chosen (outside PlanOptions::allowed). Loops over
// the candidates skip every state but kFree.
constexpr char kFree = 0, kChosen = 1, kBarred = 2;

// The design: every candidate position's Jacobian and mean-reading
// covariance, the workspace's average of G'G (G = A J, the position's
// sensitivity to the parameters), the priors' precision, and where each
// effect's parameters are.
struct Design {
    std::vector<JigPosition> cand;
    std::vector<Mat4X> J;          // d readings / d every parameter
    std::vector<Mat4X> Jr;         // the same in the gauge's free coordinates (J Q)
    std::vector<Eigen::Matrix4d> Winv, W;
    Eigen::MatrixXd L;             // r x r: the workspace's mean G'G, free coordinates
    Eigen::VectorXd prior;         // n: 1 / prior_sd^2
    Eigen::MatrixXd Pr;            // r x r: the priors in free coordinates (Q' diag(prior) Q)
    Eigen::MatrixXd Q;             // n x r: the design model's gauge (problem.h's, effect by effect)
    std::vector<int> jig;          // the jig's placement's columns
    struct Eff {
        std::string name;
        std::vector<int> cols;
        Eigen::VectorXd typical;   // each parameter's typical magnitude
        Eigen::MatrixXd basis;     // its gauge beside the jig's placement alone (the test's model)
    };
    std::vector<Eff> eff;
    int n = 0, r = 0;
};

// A parameter's typical size: the middle of the simulator's magnitudes.
double typical(const ParamDesc &p) {
    const double t = 0.5 * (p.rand_lo + p.rand_hi);
    return t != 0 ? std::clamp(t, p.lower, p.upper) : p.init;
}

bool plannable_stage(Stage s) { return s == Stage::Geometry || s == Stage::Path || s == Stage::Transfer; }

// The design model: the nominal device, the jig's placement and the
// effects, each at its typical size.
bool design_model(const DeviceGeometry &g, const std::vector<std::string> &names, Model &m, std::string &err) {
    m = Model(g);
    if (!m.add_effect("jig_misalignment", {}, err)) return false;
    for (const auto &e : names) {
        const auto d = find_effect(e);
        if (!d) return m.add_effect(e, {}, err); // names it, with the known ones
        ParamValues pv;
        for (const auto &p : d->params) pv.push_back({p.name, typical(p)});
        if (!m.add_effect(e, pv, err)) return false;
    }
    return true;
}

// Effect e's gauge in the model of the jig's placement and e alone: the
// parameters a test of e against the nominal model fits.
Eigen::MatrixXd basis_beside_the_jig(const Model &m, size_t e) {
    Model two(m.geometry());
    std::string err;
    const auto &d = m.effect_desc(e);
    ParamValues pv;
    for (size_t q = 0; q < d.params.size(); ++q) pv.push_back({d.params[q].name, m.effect_params(e)[q]});
    if (!two.add_effect("jig_misalignment", {}, err) || !two.add_effect(d.name, pv, err))
        return Eigen::MatrixXd::Identity(Eigen::Index(d.params.size()), Eigen::Index(d.params.size()));
    return effect_gauge_basis(two, 1);
}

// The design model's gauge, effect by effect (block diagonal), as a fit of
// it fixes what the data cannot tell apart.
Eigen::MatrixXd gauge(const Model &m, const ReadingEvaluator &ev) {
    std::vector<Eigen::MatrixXd> blocks;
    Eigen::Index cols = 0;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (ev.offset(e) < 0) continue;
        blocks.push_back(effect_gauge_basis(m, e));
        cols += blocks.back().cols();
    }
    Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(ev.size(), cols);
    Eigen::Index c = 0;
    size_t b = 0;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (ev.offset(e) < 0) continue;
        const auto &B = blocks[b++];
        Q.block(ev.offset(e), c, B.rows(), B.cols()) = B;
        c += B.cols();
    }
    return Q;
}

bool evaluate_candidates(const Model &m, Design &D, std::string &err) {
    const ReadingEvaluator ev(m);
    D.n = ev.size();
    const Eigen::VectorXd full = ev.current();
    D.prior.resize(D.n);
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (ev.offset(e) < 0) continue;
        const auto &d = m.effect_desc(e);
        Design::Eff eff{d.name, {}, Eigen::VectorXd(Eigen::Index(d.params.size())), basis_beside_the_jig(m, e)};
        for (size_t q = 0; q < d.params.size(); ++q) {
            const int c = ev.offset(e) + int(q);
            D.prior(c) = 1.0 / std::pow(10 * d.params[q].scale, 2); // the fit's weak prior (problem.h)
            eff.cols.push_back(c);
            // A period is where the effect is, not how large it is: no size
            // of its own in the test (its amplitudes carry the effect).
            eff.typical(Eigen::Index(q)) =
                d.params[q].role == ParamRole::LengthPeriod ? 0.0 : std::fabs(m.effect_params(e)[q]);
        }
        if (d.stage == Stage::Jig) D.jig.insert(D.jig.end(), eff.cols.begin(), eff.cols.end());
        else D.eff.push_back(std::move(eff));
    }
    // Each fixture height's x offset, as every fit takes it out (FitOptions::
    // fixture, with two heights or more): nuisance columns after the
    // model's, with the jig's placement, held by the fit's own prior.
    const int model_n = D.n;
    std::vector<int> heights;
    for (const auto &c : D.cand) heights.push_back(c.height_index);
    std::sort(heights.begin(), heights.end());
    heights.erase(std::unique(heights.begin(), heights.end()), heights.end());
    const int nh = heights.size() >= 2 ? int(heights.size()) : 0;
    D.n = model_n + nh;
    D.prior.conservativeResize(D.n);
    for (int h = 0; h < nh; ++h)
        D.prior(model_n + h) = 1.0 / (kFixturePriorSdMm * kFixturePriorSdMm), D.jig.push_back(model_n + h);
    const Eigen::MatrixXd Qm = gauge(m, ev);
    D.Q = Eigen::MatrixXd::Zero(D.n, Qm.cols() + nh);
    D.Q.topLeftCorner(model_n, Qm.cols()) = Qm;
    D.Q.bottomRightCorner(nh, nh).setIdentity();
    D.r = int(D.Q.cols());
    D.Pr = D.Q.transpose() * D.prior.asDiagonal() * D.Q;
    D.L = Eigen::MatrixXd::Zero(D.r, D.r);
    Mat4X Jm(4, model_n), J(4, D.n);
    Eigen::Matrix<double, 4, 3> dydP;
    for (const auto &c : D.cand) {
        Eigen::Vector4d y;
        if (!ev.eval(full, c.ref, 0.0, y, &Jm, &dydP, &err)) return false;
        if (!y.allFinite() || !Jm.allFinite()) {
            err = "the design model cannot read position " + std::to_string(c.point) + " (outside its workspace)";
            return false;
        }
        J.setZero();
        J.leftCols(model_n) = Jm;
        if (nh) {
            const auto h = std::lower_bound(heights.begin(), heights.end(), c.height_index) - heights.begin();
            J.col(model_n + int(h)) = dydP.col(0); // the holder moved along x by the height's offset
        }
        D.J.push_back(J);
        D.Jr.push_back(J * D.Q);
        // The position's sensitivity to the parameters, as a fit's
        // calibration would place it: A = (D'D)^-1 D', the jig's columns out.
        const Eigen::Matrix<double, 3, 4> A = (dydP.transpose() * dydP).ldlt().solve(dydP.transpose());
        Eigen::Matrix<double, 3, Eigen::Dynamic> G = A * J;
        for (int k : D.jig) G.col(k).setZero();
        const Eigen::MatrixXd Gr = G * D.Q;
        D.L.noalias() += Gr.transpose() * Gr / double(D.cand.size());
        D.Winv.push_back(Eigen::Matrix4d::Zero());
        D.W.push_back(Eigen::Matrix4d::Zero());
        D.Winv.back() = dydP * dydP.transpose(); // scaled by the jig's tolerance in make_weights
    }
    return true;
}

void make_weights(const PlanOptions &o, Design &D) {
    const double pots = o.noise_mm * o.noise_mm / double(o.jig.samples);
    const double seat = o.jig_tolerance_mm * o.jig_tolerance_mm;
    for (size_t k = 0; k < D.cand.size(); ++k) {
        D.Winv[k] = seat * D.Winv[k] + pots * Eigen::Matrix4d::Identity();
        D.W[k] = D.Winv[k].inverse();
    }
}

// The effects that positions determine: an effect whose readings do not
// move with its parameters at any position (one acting in time alone) is
// left out, with the reason.
std::vector<std::string> determined(const Design &D, std::vector<std::pair<std::string, std::string>> &excluded) {
    std::vector<std::string> keep;
    for (const auto &e : D.eff) {
        double s = 0;
        for (const auto &J : D.J)
            for (int c : e.cols) s = std::max(s, J.col(c).cwiseAbs().maxCoeff());
        if (s > 0) keep.push_back(e.name);
        else excluded.push_back({e.name, "positions alone do not determine it (it acts in time)"});
    }
    return keep;
}

// The likelihood-ratio test of effect e against the jig's placement alone,
// with the raw information F (every parameter, the priors in it): its
// non-centrality at the effect's typical size, averaged over the signs of
// its parameters (the simulator draws each sign at random: the cross terms
// average out, so it is sum_i t_i^2 V_ii, V the test's information on the
// effect's parameters through its gauge), and the power at level alpha.
// The power of a chi-square test of k degrees of freedom at level alpha
// when its non-centrality is lambda: the non-central chi-square's tail past
// the central one's 1 - alpha quantile. Past 40 standard deviations of
// the non-central law beyond the quantile it is 1 (Boost's series also
// stops converging there, near lambda = 4e9).
double test_power(int k, double lambda, double alpha) {
    if (!(lambda > 0)) return alpha;
    const double q = boost::math::quantile(boost::math::complement(boost::math::chi_squared(k), alpha));
    if (lambda + k - q > 40 * std::sqrt(2.0 * (k + 2 * lambda))) return 1.0;
    return boost::math::cdf(boost::math::complement(boost::math::non_central_chi_squared(k, lambda), q));
}

// The columns a test of e looks at: the jig's placement's, then e's.
std::vector<int> test_cols(const Design &D, const Design::Eff &e) {
    std::vector<int> c = D.jig;
    c.insert(c.end(), e.cols.begin(), e.cols.end());
    return c;
}

Eigen::MatrixXd sub(const Eigen::MatrixXd &F, const std::vector<int> &c) {
    Eigen::MatrixXd S(Eigen::Index(c.size()), Eigen::Index(c.size()));
    for (size_t i = 0; i < c.size(); ++i)
        for (size_t k = 0; k < c.size(); ++k) S(Eigen::Index(i), Eigen::Index(k)) = F(c[i], c[k]);
    return S;
}

// Fs: the information on test_cols(D, e) (the jig's block first).
std::pair<double, double> power_of(const Design &D, const Design::Eff &e, const Eigen::MatrixXd &Fs, double alpha) {
    const Eigen::Index nb = Eigen::Index(D.jig.size()), ne = Eigen::Index(e.cols.size());
    const Eigen::MatrixXd &B = e.basis; // ne x k
    const Eigen::MatrixXd FbeB = Fs.block(0, nb, nb, ne) * B;
    const Eigen::MatrixXd S =
        B.transpose() * Fs.block(nb, nb, ne, ne) * B - FbeB.transpose() * Fs.block(0, 0, nb, nb).ldlt().solve(FbeB);
    // A change d of the parameters seen through the gauge: a = B^+ d.
    const Eigen::MatrixXd Bp = B.completeOrthogonalDecomposition().pseudoInverse();
    const Eigen::MatrixXd V = Bp.transpose() * S * Bp;
    double lambda = 0;
    for (Eigen::Index i = 0; i < ne; ++i) lambda += e.typical(i) * e.typical(i) * V(i, i);
    lambda = std::max(0.0, lambda);
    const int k = std::max<int>(1, int(B.cols()));
    return {lambda, test_power(k, lambda, alpha)};
}

// The chosen positions' information and the priors': on every parameter
// (raw: the tests'), or in the gauge's free coordinates (the I-criterion's).
Eigen::MatrixXd information(const Design &D, const std::vector<char> &chosen, bool raw = false) {
    Eigen::MatrixXd F = raw ? Eigen::MatrixXd(D.prior.asDiagonal()) : D.Pr;
    const auto &J = raw ? D.J : D.Jr;
    for (size_t k = 0; k < D.cand.size(); ++k)
        if (chosen[k] == kChosen) F.noalias() += J[k].transpose() * D.W[k] * J[k];
    return F;
}

// Stage 1: positions for the weakest effect's test until every effect the
// whole plate can detect is detected (or the positions run out).
int detect_stage(const PlanOptions &o, const Design &D, const std::vector<double> &power_all, std::vector<char> &chosen,
                 int budget) {
    int picks = 0;
    while (picks < budget) {
        const Eigen::MatrixXd F = information(D, chosen, true);
        int weakest = -1;
        double worst = INFINITY;
        for (size_t e = 0; e < D.eff.size(); ++e) {
            if (power_all[e] < o.power) continue; // out of reach: reported, not chased
            const double p = power_of(D, D.eff[e], sub(F, test_cols(D, D.eff[e])), o.alpha).second;
            if (p < o.power && p < worst) worst = p, weakest = int(e);
        }
        if (weakest < 0) break;
        // The position whose addition raises the weakest test's
        // non-centrality most (each candidate tried: the tests are small).
        const auto &e = D.eff[size_t(weakest)];
        const std::vector<int> cols = test_cols(D, e);
        const Eigen::MatrixXd Fs = sub(F, cols);
        const double base = power_of(D, e, Fs, o.alpha).first;
        double best = 0;
        size_t pick = 0;
        Mat4X Jc(4, Eigen::Index(cols.size()));
        for (size_t k = 0; k < D.cand.size(); ++k) {
            if (chosen[k] != kFree) continue;
            for (size_t c = 0; c < cols.size(); ++c) Jc.col(Eigen::Index(c)) = D.J[k].col(cols[c]);
            const double gain = power_of(D, e, Fs + Jc.transpose() * D.W[k] * Jc, o.alpha).first - base;
            if (gain > best) best = gain, pick = k;
        }
        if (best <= 0) break;
        chosen[pick] = kChosen;
        ++picks;
    }
    return picks;
}

// Stage 2: greedy I-optimal picks for one design model or several at once
// (a compound criterion: each model's gain over its mean variance with the
// whole plate, summed, so that each counts alike whatever its scale), with
// each candidate's J C and J C L kept up to date by the rank-4 update of C
// a pick makes, model by model.
bool i_optimal_stage(const PlanOptions &o, const std::vector<const Design *> &Ds, const std::vector<double> &scale,
                     std::vector<char> &chosen, int budget, std::string &err) {
    const size_t nc = chosen.size();
    std::vector<std::vector<Mat4X>> Z(Ds.size()), Y(Ds.size());
    for (size_t m = 0; m < Ds.size(); ++m) {
        const Design &D = *Ds[m];
        const Eigen::MatrixXd C = information(D, chosen).ldlt().solve(Eigen::MatrixXd::Identity(D.r, D.r));
        Z[m].resize(nc), Y[m].resize(nc);
        for (size_t k = 0; k < nc; ++k)
            if (chosen[k] == kFree) Z[m][k] = D.Jr[k] * C, Y[m][k] = Z[m][k] * D.L;
    }
    for (int pick = 0; pick < budget; ++pick) {
        if (o.progress && !o.progress(double(pick) / double(budget))) {
            err = "plan cancelled";
            return false;
        }
        double best = -INFINITY; // (round-off can make a gain that is nothing a little below zero)
        size_t star = nc;
        for (size_t k = 0; k < nc; ++k) {
            if (chosen[k] != kFree) continue;
            double gain = 0;
            for (size_t m = 0; m < Ds.size(); ++m) {
                const Design &D = *Ds[m];
                const Eigen::Matrix4d M = D.Winv[k] + Z[m][k] * D.Jr[k].transpose();
                gain += M.ldlt().solve(Y[m][k] * Z[m][k].transpose()).trace() / scale[m];
            }
            if (std::isfinite(gain) && gain > best) best = gain, star = k;
        }
        if (star == nc) {
            err = "the I-optimal criterion is not finite at any position left (the design model is degenerate)";
            return false;
        }
        chosen[star] = kChosen;
        for (size_t m = 0; m < Ds.size(); ++m) {
            const Design &D = *Ds[m];
            const Eigen::Matrix4d Mi = (D.Winv[star] + Z[m][star] * D.Jr[star].transpose()).inverse();
            const Mat4X Zs = Z[m][star], Ys = Y[m][star];
            for (size_t k = 0; k < nc; ++k) {
                if (chosen[k] != kFree) continue;
                const Eigen::Matrix4d K = (D.Jr[k] * Zs.transpose()) * Mi;
                Z[m][k].noalias() -= K * Zs;
                Y[m][k].noalias() -= K * Ys;
            }
        }
    }
    return true;
}

double mean_sigma(const Design &D, const std::vector<char> &chosen) {
    const Eigen::MatrixXd C = information(D, chosen).ldlt().solve(Eigen::MatrixXd::Identity(D.r, D.r));
    return std::sqrt(std::max(0.0, (C * D.L).trace()));
}

// The plate's indices of positions given by reference (each within 1e-6 mm
// of a hole at one of the heights: match_plan's rule); empty + err when one
// is not.
std::vector<size_t> plate_indices(const std::vector<JigPosition> &plate, const std::vector<std::array<double, 3>> &refs,
                                  std::string &err) {
    std::vector<PlanRow> rows;
    for (const auto &r : refs) rows.push_back({r[0], r[1], r[2], 1});
    std::vector<PlannedVisit> visits;
    std::vector<size_t> out;
    if (!match_plan(plate, rows, visits, err)) return out;
    for (const auto &v : visits) out.push_back(v.index);
    return out;
}

// Each plate position's state before the picks: the measured ones chosen,
// those outside `allowed` (when given) barred. False + err when a position
// is no hole, or fewer are free than `positions` asks for.
bool initial_states(const PlanOptions &o, const std::vector<JigPosition> &plate, std::vector<char> &state,
                    std::string &err) {
    state.assign(plate.size(), o.allowed.empty() ? kFree : kBarred);
    const std::vector<size_t> allowed = plate_indices(plate, o.allowed, err);
    if (allowed.size() != o.allowed.size()) return err = "\"allowed\": " + err, false;
    for (size_t i : allowed) state[i] = kFree;
    const std::vector<size_t> measured = plate_indices(plate, o.measured, err);
    if (measured.size() != o.measured.size()) return err = "\"measured\": " + err, false;
    for (size_t i : measured) state[i] = kChosen;
    const auto free = size_t(std::count(state.begin(), state.end(), kFree));
    if (size_t(o.positions) > free) {
        err = "positions must be at most " + std::to_string(free) + " (the plate's positions left to choose from";
        err += o.measured.empty() && o.allowed.empty() ? ")" : ", measured and barred ones apart)";
        err += ", not " + std::to_string(o.positions);
        return false;
    }
    return true;
}

// Height by height (lowest first), rows along y, each visited row's holes
// along z the other way from the row visited before it.
void walking_order(std::vector<JigPosition> &v) {
    std::sort(v.begin(), v.end(), [](const JigPosition &a, const JigPosition &b) {
        if (a.ref[0] != b.ref[0]) return a.ref[0] < b.ref[0];
        if (a.row != b.row) return a.row < b.row;
        return a.col < b.col;
    });
    size_t rank = 0; // of the visited row within its height
    for (size_t i = 0; i < v.size();) {
        size_t j = i;
        while (j < v.size() && v[j].ref[0] == v[i].ref[0] && v[j].row == v[i].row) ++j;
        if (i > 0 && v[i].ref[0] != v[i - 1].ref[0]) rank = 0; // each height starts forward
        if (rank % 2 == 1) std::reverse(v.begin() + long(i), v.begin() + long(j));
        ++rank;
        i = j;
    }
}

// The plate's positions a plan chooses from: beyond this the candidates'
// Jacobians and updates take gigabytes (100 x 100 holes x 5 heights took
// 0.9 GB).
constexpr double kMaxCandidates = 20000;

bool check_options(const PlanOptions &o, std::string &err) {
    if (!check_jig_options(o.jig, err)) return false;
    const double plate_d = double(o.jig.n) * double(o.jig.n) * double(o.jig.heights_mm.size());
    if (plate_d > kMaxCandidates) {
        err = "the plate's positions (holes " + std::to_string(o.jig.n) + " x " + std::to_string(o.jig.n) + " x " +
              std::to_string(o.jig.heights_mm.size()) + " heights) are over the planner's 20000";
        return false;
    }
    const size_t plate = size_t(plate_d);
    if (o.positions < 1 || size_t(o.positions) > plate) {
        err = "positions must be in 1.." + std::to_string(plate) + " (the plate's holes at every height), not " +
              std::to_string(o.positions);
        return false;
    }
    if (!(o.noise_mm > 0) || !(o.jig_tolerance_mm >= 0) || !(o.alpha > 0 && o.alpha < 1) ||
        !(o.power > 0 && o.power < 1)) {
        err = "noise_mm must be > 0, jig_tolerance_mm >= 0, alpha and power in (0, 1)";
        return false;
    }
    return true;
}

} // namespace

bool plan_session(const DeviceGeometry &g, const PlanOptions &o, PlanResult &out, std::string &err) {
    out = PlanResult();
    if (!check_options(o, err)) return false;
    Design D;
    D.cand = make_jig_plan(o.jig);
    std::vector<std::string> names = o.effects;
    if (names.empty())
        for (const auto &d : all_effects())
            if (!d->is_user() && plannable_stage(d->stage)) names.push_back(d->name);
    for (auto it = names.begin(); it != names.end();) {
        const auto d = find_effect(*it);
        if (d && (d->stage == Stage::Jig || d->stage == Stage::Position)) {
            out.excluded.push_back({*it, d->stage == Stage::Jig ? "the jig's placement is in every design already"
                                                                : "fitted in position space after the readings"});
            it = names.erase(it);
        } else {
            ++it;
        }
    }
    Model m(g);
    if (!design_model(g, names, m, err) || !evaluate_candidates(m, D, err)) return false;
    out.effects = determined(D, out.excluded);
    if (out.effects.empty()) {
        err = "nothing to plan for: no effect whose readings the positions determine (left out: ";
        for (size_t i = 0; i < out.excluded.size(); ++i)
            err += (i ? ", " : "") + out.excluded[i].first + ": " + out.excluded[i].second;
        err += ")";
        return false;
    }
    if (out.effects.size() != names.size()) { // again without the effects positions do not determine
        D = Design();
        D.cand = make_jig_plan(o.jig);
        if (!design_model(g, out.effects, m, err) || !evaluate_candidates(m, D, err)) return false;
    }
    make_weights(o, D);
    const std::vector<char> all(D.cand.size(), 1);
    const Eigen::MatrixXd Fall = information(D, all, true);
    std::vector<double> power_all;
    for (const auto &e : D.eff) power_all.push_back(power_of(D, e, sub(Fall, test_cols(D, e)), o.alpha).second);
    std::vector<char> chosen;
    if (!initial_states(o, D.cand, chosen, err)) return false;
    out.detect_picks = detect_stage(o, D, power_all, chosen, o.positions);
    // The I-criterion's models: the one given; else each effect beside the
    // jig's placement (the device has some of them, nobody knows which).
    std::vector<Design> singles;
    std::vector<const Design *> Ds{&D};
    if (o.effects.empty()) {
        Ds.clear();
        for (const auto &name : out.effects) {
            Design S;
            S.cand = D.cand;
            Model one(g);
            if (!design_model(g, {name}, one, err) || !evaluate_candidates(one, S, err)) return false;
            make_weights(o, S);
            singles.push_back(std::move(S));
        }
        for (const auto &S : singles) Ds.push_back(&S);
    }
    std::vector<double> scale;
    for (const Design *S : Ds) scale.push_back(std::max(1e-300, std::pow(mean_sigma(*S, all), 2)));
    if (!i_optimal_stage(o, Ds, scale, chosen, o.positions - out.detect_picks, err)) return false;
    const Eigen::MatrixXd F = information(D, chosen, true);
    for (size_t e = 0; e < D.eff.size(); ++e) {
        const auto [l, p] = power_of(D, D.eff[e], sub(F, test_cols(D, D.eff[e])), o.alpha);
        const auto [la, pa] = power_of(D, D.eff[e], sub(Fall, test_cols(D, D.eff[e])), o.alpha);
        out.power.push_back({D.eff[e].name, std::max<int>(1, int(D.eff[e].basis.cols())), l, p, la, pa});
    }
    out.sigma_mm = mean_sigma(D, chosen);
    out.sigma_all_mm = mean_sigma(D, all);
    std::vector<char> measured(D.cand.size(), 0);
    for (size_t i : plate_indices(D.cand, o.measured, err)) measured[i] = 1;
    for (size_t k = 0; k < D.cand.size(); ++k)
        if (chosen[k] == kChosen && !measured[k]) out.chosen.push_back(D.cand[k]);
    walking_order(out.chosen);
    out.samples = o.jig.samples;
    return true;
}

} // namespace cdm
