// See discover.h.
#include "calib/beyond/discover.h"
#include "model/effect.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numeric>

#include <Eigen/Dense>

#include "calib/evaluation/findings.h"
#include "calib/evaluation/jig.h"
#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {

// What a term may depend on, per position and cable. Lengths in metres, so
// that a coefficient reads in mm per m^p.
struct TermIn {
    double L;      // the cable's chord, anchor to holder at the jig position (nominal geometry), m
    V3 u;          // its unit direction, anchor to holder, device frame
    double t_h;    // hours since the session's first position
    double height; // the fixture height (jig x), m
    double approach; // +1: the cable lengthened to reach the position, -1: shortened, 0: first
    double period_m; // the periodogram's period (m), 0 when none
};

struct Term {
    std::string name, variable, shape;
    std::function<double(const TermIn &)> f;
};

const char *kAx[3] = {"x", "y", "z"};

std::vector<Term> library(bool periodic) {
    std::vector<Term> t;
    const std::string smooth = "a smooth function of cable length common to the four pots (a scale, a stretch, a "
                               "transfer curve)";
    t.push_back({"L", "cable length", smooth, [](const TermIn &i) { return i.L; }});
    t.push_back({"L^2", "cable length", smooth, [](const TermIn &i) { return i.L * i.L; }});
    t.push_back({"L^3", "cable length", smooth, [](const TermIn &i) { return i.L * i.L * i.L; }});
    for (int k = 0; k < 3; ++k) {
        const std::string a = kAx[k], dir = "cable direction (u_" + a + ")";
        t.push_back({"u_" + a, dir,
                     "a change with the cable's direction along " + a +
                         ": an attachment or exit offset along " + a + " seen by every cable",
                     [k](const TermIn &i) { return i.u(k); }});
        t.push_back({"u_" + a + "^2", dir, "a change with the cable's alignment with " + a,
                     [k](const TermIn &i) { return i.u(k) * i.u(k); }});
        t.push_back({"L*u_" + a, "cable length and direction (u_" + a + ")",
                     "a force along " + a + " on every cable: each stretches by its length times its component "
                                            "along " + a + " (the holder's weight, for " + a + " vertical)",
                     [k](const TermIn &i) { return i.L * i.u(k); }});
        for (int p = 1; p <= 3; ++p) {
            const std::string Lp = p == 1 ? "L" : "L^" + std::to_string(p);
            t.push_back({Lp + "*u_" + a + "^2", "cable length and direction (u_" + a + ")",
                         "a change growing with the cable's length and its alignment with " + a,
                         [k, p](const TermIn &i) { return std::pow(i.L, p) * i.u(k) * i.u(k); }});
            t.push_back({Lp + "*(1-u_" + a + "^2)", "cable length and direction (u_" + a + ")",
                         p == 3 ? "the shape of cable sag under gravity along " + a +
                                      ": the arc exceeds the chord by w^2 L^3 (1 - u_" + a + "^2) / (24 T^2), w the "
                                      "cable's weight per length, T its tension"
                                : "a change growing with the cable's length and its component across " + a,
                         [k, p](const TermIn &i) { return std::pow(i.L, p) * (1 - i.u(k) * i.u(k)); }});
        }
    }
    t.push_back({"t", "acquisition time", "a drift over the session (warm-up, creep)",
                 [](const TermIn &i) { return i.t_h; }});
    t.push_back({"t^2", "acquisition time", "a drift that settles or accelerates over the session",
                 [](const TermIn &i) { return i.t_h * i.t_h; }});
    t.push_back({"L*t", "cable length and acquisition time",
                 "a drift in proportion to the length: the cables or the frame expanding as they warm",
                 [](const TermIn &i) { return i.L * i.t_h; }});
    t.push_back({"height", "fixture height", "a change with the fixture height common to the cables",
                 [](const TermIn &i) { return i.height; }});
    t.push_back({"approach", "approach direction",
                 "a reading that depends on the direction the cable last moved to reach the position: hysteresis or "
                 "backlash (friction in a guide, the pot's wiper, the drum's spring)",
                 [](const TermIn &i) { return i.approach; }});
    if (periodic) {
        const std::string s = "periodic in cable length: something turns with the drum";
        t.push_back({"sin(2 pi L/P)", "cable length", s,
                     [](const TermIn &i) { return std::sin(2 * M_PI * i.L / i.period_m); }});
        t.push_back({"cos(2 pi L/P)", "cable length", s,
                     [](const TermIn &i) { return std::cos(2 * M_PI * i.L / i.period_m); }});
    }
    return t;
}

// Per position, per cable, the term inputs (positions in acquisition order
// for the approach direction).
std::vector<std::array<TermIn, 4>> term_inputs(const std::vector<PreparedPos> &pos, const LengthView &lv,
                                               double period_m) {
    const size_t P = pos.size();
    std::vector<size_t> order(P);
    std::iota(order.begin(), order.end(), size_t(0));
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return pos[a].t_s < pos[b].t_s; });
    const double t0 = P ? pos[order[0]].t_s : 0.0;
    std::vector<std::array<TermIn, 4>> in(P);
    for (size_t r = 0; r < P; ++r) {
        const size_t j = order[r];
        for (size_t c = 0; c < 4; ++c) {
            TermIn &x = in[j][c];
            x.L = lv.chord[j][c] / 1000.0;
            x.u = lv.dir[j][c];
            x.t_h = (pos[j].t_s - t0) / 3600.0;
            x.height = pos[j].ref(0) / 1000.0;
            x.period_m = period_m;
            const double d = r ? pos[j].mean(long(c)) - pos[order[r - 1]].mean(long(c)) : 0.0;
            x.approach = d > 0 ? 1.0 : d < 0 ? -1.0 : 0.0;
        }
    }
    return in;
}

// An orthonormal basis of span(A)'s columns (rank-revealing).
Eigen::MatrixXd span_basis(const Eigen::MatrixXd &A) {
    if (A.cols() == 0) return Eigen::MatrixXd(A.rows(), 0);
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    qr.setThreshold(1e-10);
    return qr.householderQ() * Eigen::MatrixXd::Identity(A.rows(), qr.rank());
}

// The linearised refit's residual: r with span(J) projected out.
Eigen::VectorXd project_out(const Eigen::MatrixXd &Q, const Eigen::VectorXd &r) { return r - Q * (Q.transpose() * r); }

constexpr double kMinOwnShare = 0.01;

struct Selection {
    std::vector<int> terms;
    std::vector<double> gain, p;
    double chi2_after = 0;
};

// Forward stepwise selection (orthogonal matching pursuit) on the
// projected residual e and projected library F (X: the library before the
// projection): each step adds the term
// that lowers the chi-square most; kept when its likelihood ratio (the gain
// over the residual's scale, s^2 = max(1, chi2/dof): a residual wider than
// its noise model makes every gain look larger) passes kFindingLevel after
// Bonferroni over the terms still in the library, and it lowers the BIC.
Selection select_terms(Eigen::VectorXd e, const Eigen::MatrixXd &F, const Eigen::MatrixXd &X, double dof0,
                       double ln_n) {
    Selection s;
    Eigen::MatrixXd Qs(e.size(), 0);
    const int M = int(F.cols());
    for (int step = 0; step < kMaxDiscoveredTerms; ++step) {
        int best = -1;
        double bg = 0;
        Eigen::VectorXd bv;
        for (int t = 0; t < M; ++t) {
            if (std::find(s.terms.begin(), s.terms.end(), t) != s.terms.end()) continue;
            Eigen::VectorXd v = F.col(t) - Qs * (Qs.transpose() * F.col(t));
            const double vv = v.squaredNorm();
            // A term the model, the fixture's offsets and the terms chosen
            // make all but a hundredth of (a variance inflation over 100)
            // is not told apart from them: its coefficient would be set by
            // what little is left.
            if (!(vv > kMinOwnShare * std::max(1e-300, X.col(t).squaredNorm()))) continue;
            const double g = std::pow(v.dot(e), 2) / vv;
            if (g > bg) bg = g, best = t, bv = v;
        }
        if (best < 0) break;
        const double dof = dof0 - double(step) - 1;
        const double s2 = dof > 0 ? std::max(1.0, (e.squaredNorm() - bg) / dof) : 1.0;
        const double p = false_alarm(chi2_sf(bg / s2, 1), double(M - step));
        if (!(p < kFindingLevel) || !(bg > ln_n)) break;
        e -= bv * (bv.dot(e) / bv.squaredNorm());
        Qs.conservativeResize(Eigen::NoChange, Qs.cols() + 1);
        Qs.col(Qs.cols() - 1) = bv / bv.norm();
        s.terms.push_back(best);
        s.gain.push_back(bg);
        s.p.push_back(p);
    }
    s.chi2_after = e.squaredNorm();
    return s;
}

// The other model against the terms: its linearised refit's chi-square
// (its residual with its own Jacobian and the fixture's offsets projected
// out), and the share of the leading term's whitened column its Jacobian
// cannot make (0: the term is a special case of the other model's effects).
bool against_other(const Model &m, const DiagContext &ctx, const FitOptions &fo,
                   const std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> &terms, double &chi2, double &outside,
                   std::string &err) {
    Eigen::VectorXd r;
    Eigen::MatrixXd J, X;
    if (!fit_residual_jacobian_with(m, ctx.pos, fo, terms, r, J, X, err)) return false;
    const Eigen::MatrixXd Q = span_basis(J);
    chi2 = project_out(Q, r).squaredNorm();
    // The leading term's share: the one the proposal is about (a later,
    // smaller term the other model lacks does not make the lead new).
    const double all = X.col(0).squaredNorm();
    outside = all > 0 ? (X.col(0) - Q * (Q.transpose() * X.col(0))).squaredNorm() / all : 0.0;
    return true;
}

// base moved by the joint step's model part (clamped into the bounds) and
// the data's means less the terms: the step evaluated on the data.
Eval stepped_eval(const DiagContext &ctx, const Model &base, const Eigen::VectorXd &dtheta,
                  const std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> &raw, const Eigen::VectorXd &c) {
    Model m = base;
    long col = 0;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        const EffectDesc &d = m.effect_desc(e);
        if (d.stage == Stage::Position) continue;
        std::vector<double> v = m.effect_params(e);
        for (size_t k = 0; k < v.size(); ++k, ++col)
            if (col < dtheta.size()) v[k] = std::clamp(v[k] + dtheta(col), d.params[k].lower, d.params[k].upper);
        std::string e2;
        m.set_effect_params(e, v, e2);
    }
    std::vector<PreparedPos> moved = ctx.pos;
    for (size_t j = 0; j < moved.size(); ++j) moved[j].mean -= raw[j] * c;
    return evaluate(m, moved, ctx.threads);
}

std::string fmt_g(double v) {
    char b[48];
    std::snprintf(b, sizeof b, "%.3g", v);
    return b;
}

// The discovery's JSON and the verdict's sentence, from the selection s
// with its coefficients c (standard errors se) and out's numbers.
void describe(const DiagContext &ctx, const std::vector<Term> &lib, const Selection &s, const Eigen::VectorXd &c,
              const Eigen::VectorXd &se, const Model &base, Discovery &out) {
    const long k = long(s.terms.size());
    const double xr_raw = out.E.err[0].n > 0 ? std::sqrt(out.E.err[0].ss / out.E.err[0].n) : NAN;
    const double xr_fix = x_rms_without_fixture(out.E, ctx.G, ctx.jig, ctx.pos);
    const double xr = std::isfinite(xr_fix) ? xr_fix : xr_raw;
    json terms = json::array();
    std::string what;
    for (long q = 0; q < k; ++q) {
        const Term &t = lib[size_t(s.terms[size_t(q)])];
        out.terms.push_back(t.name);
        out.coef.push_back(c(q));
        out.se.push_back(se(q));
        terms.push_back({{"term", t.name}, {"variable", t.variable}, {"coefficient", c(q)}, {"std", se(q)},
                         {"delta_chi2", s.gain[size_t(q)]}, {"p_value", s.p[size_t(q)]}, {"shape", t.shape}});
        what += std::string(q ? " plus " : "") + fmt_g(c(q)) + " * " + t.name;
    }
    const Term &lead = lib[size_t(s.terms[0])];
    out.json = {{"terms", terms},
                {"per_cable", "one coefficient common to the four cables, added to each cable's reading (mm); L the "
                              "cable's chord (anchor to holder at the jig position, nominal geometry) in m, u its unit direction anchor to holder in the device frame, "
                              "t hours since the first position, height the fixture height in m, approach the sign of "
                              "the cable's length change from the position measured before"},
                {"delta_chi2", out.dchi2},
                {"bic_change", out.bic_vs_base},
                {"bic_change_vs_compared", std::isfinite(out.bic_vs_other) ? json(out.bic_vs_other) : json(nullptr)},
                {"compared_with", out.other_name.empty() ? json(nullptr) : json(out.other_name)},
                {"share_outside_compared", std::isfinite(out.outside_other) ? json(out.outside_other) : json(nullptr)},
                {"x_rms_mm", std::isfinite(xr_raw) ? json(xr_raw) : json(nullptr)},
                {"x_rms_fixture_out_mm", std::isfinite(xr_fix) ? json(xr_fix) : json(nullptr)},
                {"error_mm", [&]() -> json { // the maxima need every sample: not computed for a hypothesis
                     if (!(out.E.err[0].n > 0)) return nullptr; // no position solved with the step
                     json e = stats3(out.E.err);
                     for (auto &a : e) a["max"] = nullptr;
                     return e;
                 }()},
                {"of", reading_effects(base)},
                {"method", "forward stepwise sparse regression of the whitened reading residual over " +
                               std::to_string(lib.size()) + " per-cable terms, each fitted jointly with the model "
                               "(its Jacobian and the fixture's offsets projected out); a term kept when its likelihood "
                               "ratio passes 1e-3 after Bonferroni over the library and it lowers the BIC; the error "
                               "after one joint Gauss-Newton step"},
                {"hypothesis", true}};
    out.lead_words = "without them, the residual follows " + lead.variable + " (the library's best term, " + lead.name +
                     ", does not fit as well as " + out.other_name + ": BIC " + fmt_num(out.bic_vs_other, 0, true) +
                     "; the effect's shape is not among the library's terms): look there";
    const std::string reaches = std::isfinite(xr) ? "brings x to " + fmt_num(xr, 3) + " mm" +
                                                         (std::isfinite(xr_fix) ? " with the fixture's per-height offsets out" : "")
                                                   : "leaves no position solvable after one step (its error is not known)";
    out.words = "a term " + what + " per cable (mm, L in m; " + fmt_p(s.p[0]) + ") " + reaches +
                (std::isfinite(out.bic_vs_other) ? " (BIC " + fmt_num(out.bic_vs_other, 0, true) + " against " + out.other_name + ")"
                                                 : " (BIC " + fmt_num(out.bic_vs_base, 0, true) + ")") +
                ": " + lead.shape + ". A hypothesis for the physics to confirm: write it as a user effect (docs/effects.md) "
                "and diagnose again";
}

} // namespace

bool discover_terms(const DiagContext &ctx, const Model &base, const FitReport &base_rep, const Model *other,
                    const FitReport *other_rep, const std::string &other_name, Discovery &out, std::string &err) {
    out.other_name = other_name;
    const size_t P = ctx.pos.size();
    if (P < 20) return true;
    const LengthView lv = length_view(base, ctx.pos);
    const PeriodPeak pk = length_period(lv);
    const bool periodic = pk.valid && pk.fap < kFindingLevel;
    const std::vector<Term> lib = library(periodic);
    const auto in = term_inputs(ctx.pos, lv, periodic ? pk.period_mm / 1000.0 : 0.0);
    std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> raw(P, Eigen::Matrix<double, 4, Eigen::Dynamic>(4, long(lib.size())));
    for (size_t j = 0; j < P; ++j)
        for (size_t c = 0; c < 4; ++c)
            for (size_t t = 0; t < lib.size(); ++t) raw[j](long(c), long(t)) = lib[t].f(in[j][c]);
    FitOptions fo = ctx.fo;
    fo.weigh_with = &base;
    fo.weights = nullptr;
    Eigen::VectorXd r;
    Eigen::MatrixXd J, X;
    if (!fit_residual_jacobian_with(base, ctx.pos, fo, raw, r, J, X, err)) return false;
    const Eigen::MatrixXd Qa = span_basis(J);
    const Eigen::VectorXd e = project_out(Qa, r);
    const Eigen::MatrixXd F = X - Qa * (Qa.transpose() * X);
    const double n = double(r.size()), ln_n = std::log(ctx.n_obs);
    const Selection s = select_terms(e, F, X, n - double(Qa.cols()), ln_n);
    if (s.terms.empty()) return true;
    const long k = long(s.terms.size());
    Eigen::MatrixXd Fs(F.rows(), k), Xs(X.rows(), k);
    for (long q = 0; q < k; ++q) {
        Fs.col(q) = F.col(s.terms[size_t(q)]);
        Xs.col(q) = X.col(s.terms[size_t(q)]);
    }
    // The terms' coefficients (Frisch-Waugh: the joint fit's, from the
    // projected columns) and their standard errors at the residual's scale.
    const Eigen::MatrixXd G = Fs.transpose() * Fs;
    const Eigen::VectorXd c = G.ldlt().solve(Fs.transpose() * e);
    const double dof = n - double(Qa.cols()) - double(k);
    const double s2 = dof > 0 ? std::max(1.0, s.chi2_after / dof) : 1.0;
    const Eigen::VectorXd se = (G.inverse().diagonal() * s2).cwiseMax(0).cwiseSqrt();
    if (!c.allFinite() || !se.allFinite()) return true; // terms the data cannot separate: nothing proposed
    // The model's part of the joint step, without the fixture's offsets
    // (its last columns): the evaluation below keeps the fixture in the
    // residual, as every other evaluation does.
    long nm = 0;
    for (size_t q = 0; q < base.effect_count(); ++q)
        if (base.effect_desc(q).stage != Stage::Position) nm += long(base.effect_params(q).size());
    Eigen::VectorXd dtheta = Eigen::VectorXd::Zero(nm);
    if (nm > 0) {
        Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qj(J.leftCols(nm));
        qj.setThreshold(1e-10);
        dtheta = qj.solve(r - Xs * c);
    }
    std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> sel(P, Eigen::Matrix<double, 4, Eigen::Dynamic>(4, k));
    for (size_t j = 0; j < P; ++j)
        for (long q = 0; q < k; ++q) sel[j].col(q) = raw[j].col(s.terms[size_t(q)]);
    out.E = stepped_eval(ctx, base, dtheta, sel, c);
    out.found = true;
    out.dchi2 = e.squaredNorm() - s.chi2_after;
    out.bic_vs_base = -out.dchi2 + double(k) * ln_n;
    if (other && other_rep) {
        double chi2_other = 0;
        if (!against_other(*other, ctx, fo, sel, chi2_other, out.outside_other, err)) return false;
        out.bic_vs_other = (s.chi2_after + double(base_rep.n_free + int(k)) * ln_n) -
                           (chi2_other + double(other_rep->n_free) * ln_n);
    }
    describe(ctx, lib, s, c, se, base, out);
    return true;
}

} // namespace diag
} // namespace cdm
