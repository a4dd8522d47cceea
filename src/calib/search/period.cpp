// fit_seeded_period (context.h): the joint fit of a seeded period, as a
// search over the period of the profile chi-square, each point a fit with
// the period held, then one fit with everything free from the best.
//
// Why not one joint fit from the start: the amplitudes' best values turn
// with the period (a sine and cosine pair is a phase, and a change of period
// shifts the phase by a different amount at each cable length), so in
// (period, amplitudes) the minimum lies along a curved valley that a
// linearised step overshoots. From a model still far from the data (a
// search's early steps) a joint fit spent 100-230 evaluations crawling it,
// the objective falling a percent per step, mostly towards a period longer
// than the data's span that is then not shown and set aside. With the
// period held the rest is nearly linear (a held fit takes one to three
// evaluations from a neighbour's result), so the profile chi2(period) costs
// a few evaluations a point, and it is a function of one variable: walked
// downhill in steps of about a quarter of a phase turn over the span (so
// that no peak is stepped over), then bracketed and refined by successive
// parabolas, it reaches the minimum in a bounded number of points, and a
// walk that leaves the span stops at once. The final free fit starts at the
// minimum, where the linearisation holds: it gives the period its standard
// error and polishes what the held fits left.
#include <algorithm>
#include <cmath>

#include "calib/search/context.h"
#include "calib/evaluation/findings.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

namespace {

// The free fit's budget before the profile search takes over.
constexpr int kQuickEvals = 20;

struct Point {
    double p = 0; // the period
    double chi2 = INFINITY;
    Model m{DeviceGeometry{}};
    FitReport rep; // its held fit's
};

// The profile chi2(period) of parameter q of effect e: each point a fit
// with the period held (from a neighbour's result), their evaluations and
// seconds counted. On failure rep (the caller's) is the failed fit's report.
struct Profile {
    const std::vector<PreparedPos> &pos;
    size_t e, q;
    double lower, hi, span;
    FitOptions fh;
    FitReport &rep;
    int evals = 0;
    double seconds = 0;

    // A quarter of a phase turn over the span at period p: the profile's
    // peaks are about four such steps wide.
    double step(double p) const { return std::min(p * p / (4 * span), 0.25 * p); }
    // The held fit at period p from `from`'s values (p within the effect's
    // bounds).
    bool held(const Model &from, double p, Point &out) {
        out.p = p;
        out.m = from;
        auto v = out.m.effect_params(e);
        v[q] = p;
        std::string err;
        if (!out.m.set_effect_params(e, v, err)) {
            rep = FitReport{};
            rep.message = "fit failed: " + err;
            return false;
        }
        const bool ok = fit_model(out.m, pos, fh, out.rep);
        evals += out.rep.evals;
        seconds += out.rep.seconds;
        out.chi2 = std::isnan(out.rep.chi2) ? INFINITY : out.rep.chi2;
        if (!ok) rep = out.rep;
        return ok;
    }
};

// The neighbours a and c of the start b: the other starts' held fits
// within two steps, else a held fit a step away (none past a bound).
bool first_neighbours(Profile &pf, const std::vector<std::pair<const Model *, double>> &known, const Point &b,
                      Point &a, Point &c) {
    a.p = -INFINITY;
    c.p = INFINITY;
    for (auto &[km, kc] : known) {
        const double kp = km->effect_params(pf.e)[pf.q];
        if (kp < b.p && kp >= b.p - 2 * pf.step(b.p) && kp > a.p) {
            a.p = kp;
            a.chi2 = std::isnan(kc) ? INFINITY : kc;
            a.m = *km;
        } else if (kp > b.p && kp <= std::min(pf.hi, b.p + 2 * pf.step(b.p)) && kp < c.p) {
            c.p = kp;
            c.chi2 = std::isnan(kc) ? INFINITY : kc;
            c.m = *km;
        }
    }
    if (!std::isfinite(a.p)) {
        if (b.p > pf.lower) {
            if (!pf.held(b.m, std::max(pf.lower, b.p - pf.step(b.p)), a)) return false;
        } else {
            a.chi2 = INFINITY; // at the bound: nothing to its left
        }
    }
    if (!std::isfinite(c.p)) {
        if (b.p < pf.hi) {
            if (!pf.held(b.m, std::min(pf.hi, b.p + pf.step(b.p)), c)) return false;
        } else {
            c.chi2 = INFINITY;
        }
    }
    return true;
}

enum class Walk { Failed, Trend, Bracket, Bound };

// Downhill from b to a bracket (a, b, c), b lowest. The walk ends at the
// effect's bounds (the free fit takes it from there: Bound) or a quarter
// past the span: a profile still falling there is a trend, not a period the
// data repeat (Trend: b is its last point).
Walk walk_downhill(Profile &pf, Point &a, Point &b, Point &c) {
    for (int walk = 0; walk < 64; ++walk) {
        if (a.chi2 < b.chi2 && a.chi2 <= c.chi2) { // downhill to shorter periods
            c = std::move(b);
            b = std::move(a);
            if (b.p <= pf.lower) return Walk::Bound;
            if (!pf.held(b.m, std::max(pf.lower, b.p - pf.step(b.p)), a)) return Walk::Failed;
        } else if (c.chi2 < b.chi2) {
            a = std::move(b);
            b = std::move(c);
            if (b.p >= pf.hi) return pf.hi < 1.25 * pf.span ? Walk::Bound : Walk::Trend;
            if (!pf.held(b.m, std::min(pf.hi, b.p + pf.step(b.p)), c)) return Walk::Failed;
        } else {
            return std::isfinite(a.chi2) && std::isfinite(c.chi2) ? Walk::Bracket : Walk::Bound;
        }
    }
    return Walk::Bound;
}

// Successive parabolic interpolation within the bracket (a, c), golden
// section when the parabola's vertex is not usefully inside, down to a
// bracket of an eighth of the step (a thirty-second of a phase turn over
// the span): the free fit from there is within the reach of its
// linearisation, and finishes the job in a few evaluations.
bool refine(Profile &pf, Point &a, Point &b, Point &c) {
    const double h = pf.step(b.p);
    const double tol = h / 16;
    for (int it = 0; it < 12 && c.p - a.p > 2 * tol; ++it) {
        const double d1 = b.p - a.p, d2 = b.p - c.p, f1 = b.chi2 - c.chi2, f2 = b.chi2 - a.chi2;
        const double den = d1 * f1 - d2 * f2;
        double v = den != 0 ? b.p - 0.5 * (d1 * d1 * f1 - d2 * d2 * f2) / den : NAN;
        const bool left_larger = b.p - a.p > c.p - b.p;
        if (!(v > a.p + tol && v < c.p - tol) || std::fabs(v - b.p) < tol)
            v = left_larger ? b.p - 0.382 * (b.p - a.p) : b.p + 0.382 * (c.p - b.p);
        Point t;
        if (!pf.held(b.m, v, t)) return false;
        if (t.chi2 < b.chi2) { // t is the new middle
            if (v < b.p) c = std::move(b);
            else a = std::move(b);
            b = std::move(t);
        } else if (v < b.p) {
            a = std::move(t);
        } else {
            c = std::move(t);
        }
    }
    return true;
}

// The free fit first, on a short budget, when the start is already a
// minimum of the profile (both neighbours, a quarter of a phase turn away
// or another start's held fit within two such steps, fit no better): there
// the start is within the linearisation's reach (a ripple's own peak) and
// the free fit converges in a few evaluations, where the search would take
// ten or more points. From a start on a slope (most starts of a search with
// no ripple to find, on a model still far from the data) it crawled: run
// first whatever the start, it converged within its budget in 3 of the 15
// seeded fits of a diagnosis hiding cable_gain and exit_pulley, and the
// other 12 spent 20 evaluations each before the search ran after all. A
// start on a slope goes to the search at once. A free fit that has not
// converged within the budget goes to the search too, its evaluations
// counted. 1: m and rep are the free fit's; 0: the search goes on; -1: failed.
int quick_free_fit(Profile &pf, Model &m, const FitOptions &f, FitReport &rep) {
    Model mq = m;
    FitOptions fq = f;
    fq.max_evals = kQuickEvals;
    FitReport rq;
    if (!fit_model(mq, pf.pos, fq, rq)) {
        rep = rq;
        return -1;
    }
    if (rq.converged || rq.abandoned) {
        m = std::move(mq);
        rep = std::move(rq);
        rep.evals += pf.evals;
        rep.seconds += pf.seconds;
        return 1;
    }
    pf.evals += rq.evals;
    pf.seconds += rq.seconds;
    return 0;
}

} // namespace

bool fit_seeded_period(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &f0,
                       const std::vector<std::pair<size_t, size_t>> &period, double start_chi2,
                       const std::vector<std::pair<const Model *, double>> &known, FitReport &rep) {
    if (period.size() != 1) return fit_model(m, pos, f0, rep); // (a user effect with several: the plain joint fit)
    const size_t e = period[0].first, q = period[0].second;
    const ParamDesc &pd = m.effect_desc(e).params[q];
    const double span = length_span(pos);
    // The walk's upper end: a quarter past the span, so that a minimum at the
    // span itself (a period of one turn over the data) is bracketed and
    // fitted; whether it is shown is then the free fit's period's to say.
    const double hi = std::min(pd.upper, 1.25 * span);
    // A start outside what the search walks: the plain joint fit.
    if (!(m.effect_params(e)[q] >= pd.lower && m.effect_params(e)[q] <= hi)) return fit_model(m, pos, f0, rep);
    // Every point is weighed as f0 says (weigh_with): the whitening once.
    FitOptions f = f0;
    if (f.weigh_with && !f.weights) f.weights = fit_weights(*f.weigh_with, pos, f);
    FitOptions fh = f;
    fh.hold = period;
    fh.abandon_above.clear();
    fh.statistics = false; // a point is its chi-square
    fh.single_step = true;  // from its neighbour's result, nearly linear in the rest
    Profile pf{pos, e, q, pd.lower, hi, span, fh, rep};
    Point b;
    b.p = m.effect_params(e)[q];
    b.chi2 = std::isnan(start_chi2) ? INFINITY : start_chi2;
    b.m = m;
    Point a, c;
    if (!first_neighbours(pf, known, b, a, c)) return false;
    if (b.chi2 <= a.chi2 && b.chi2 <= c.chi2) {
        const int quick = quick_free_fit(pf, m, f, rep);
        if (quick != 0) return quick > 0;
    }
    switch (walk_downhill(pf, a, b, c)) {
    case Walk::Failed:
        return false;
    case Walk::Trend: // (fit_shown is false for it)
        m = std::move(b.m);
        rep = b.rep;
        rep.n_free += int(period.size()); // counted as the free fit would
        rep.evals = pf.evals;
        rep.seconds = pf.seconds;
        rep.abandoned = true;
        rep.message = "abandoned: the period's profile falls past the span of the measured lengths";
        return true;
    case Walk::Bracket:
        if (!refine(pf, a, b, c)) return false;
        break;
    case Walk::Bound:
        break;
    }
    // Everything free from the profile's minimum. (Not on a budget: capped
    // at 30 evaluations, a final fit on a small jig whose ripple's period
    // lies past the span stops half-way at a period inside it, and is taken
    // as shown with a chi-square 70 % too high; 11 of 12 such jigs then
    // recommend another model.)
    m = std::move(b.m);
    const bool ok = fit_model(m, pos, f, rep);
    rep.evals += pf.evals;
    rep.seconds += pf.seconds;
    return ok;
}

} // namespace diag
} // namespace cdm
