// fit_seeded_period (diag_context.h): the joint fit of a seeded period, as a
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

} // namespace

bool fit_seeded_period(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &f0,
                       const std::vector<std::pair<size_t, size_t>> &period, double start_chi2,
                       const std::vector<std::pair<const Model *, double>> &known, FitReport &rep) {
    if (period.size() != 1) return fit_model(m, pos, f0, rep); // (a user effect with several: the plain joint fit)
    // (named, not a structured binding: a lambda below captures them, which
    // C++17 does not allow of a binding)
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
    int evals = 0;
    double seconds = 0;
    FitOptions fh = f;
    fh.hold = period;
    fh.abandon_above.clear();
    fh.statistics = false; // a point is its chi-square
    fh.single_step = true;  // from its neighbour's result, nearly linear in the rest
    // The held fit at period p from `from`'s values (p within the effect's
    // bounds); on failure rep is its report (a user effect's message).
    auto held = [&](const Model &from, double p, Point &out) {
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
    };
    Point b;
    b.p = m.effect_params(e)[q];
    b.chi2 = std::isnan(start_chi2) ? INFINITY : start_chi2;
    b.m = m;
    // A quarter of a phase turn over the span at period p: the profile's
    // peaks are about four such steps wide.
    auto step = [&](double p) { return std::min(p * p / (4 * span), 0.25 * p); };
    // --- walk downhill to a bracket (a, b, c), b lowest; the other starts'
    // held fits within two steps serve as the first neighbours. The walk
    // ends at the effect's bounds (the free fit takes it from there) or a
    // quarter past the span: a profile still falling there is a trend, not a
    // period the data repeat, and the search stops on it (abandoned, not
    // shown).
    Point a, c;
    a.p = -INFINITY;
    c.p = INFINITY;
    for (auto &[km, kc] : known) {
        const double kp = km->effect_params(e)[q];
        if (kp < b.p && kp >= b.p - 2 * step(b.p) && kp > a.p) {
            a.p = kp;
            a.chi2 = std::isnan(kc) ? INFINITY : kc;
            a.m = *km;
        } else if (kp > b.p && kp <= std::min(hi, b.p + 2 * step(b.p)) && kp < c.p) {
            c.p = kp;
            c.chi2 = std::isnan(kc) ? INFINITY : kc;
            c.m = *km;
        }
    }
    bool bracketed = false;
    if (!std::isfinite(a.p)) {
        if (b.p > pd.lower) {
            if (!held(b.m, std::max(pd.lower, b.p - step(b.p)), a)) return false;
        } else {
            a.chi2 = INFINITY; // at the bound: nothing to its left
        }
    }
    if (!std::isfinite(c.p)) {
        if (b.p < hi) {
            if (!held(b.m, std::min(hi, b.p + step(b.p)), c)) return false;
        } else {
            c.chi2 = INFINITY;
        }
    }
    // The free fit first, on a short budget, when the start is already a
    // minimum of the profile (both neighbours, a quarter of a phase turn
    // away or another start's held fit within two such steps, fit no
    // better): there the start is within the linearisation's reach
    // (a ripple's own peak) and the free fit converges in a few
    // evaluations, where the search would take ten or more points. From a
    // start on a slope (most starts of a search with no ripple to find, on
    // a model still far from the data) it crawled: run first whatever the
    // start, it converged within its budget in 3 of the 15 seeded fits of a
    // diagnosis hiding cable_gain and exit_pulley, and the other 12 spent 20
    // evaluations each before the search ran after all. A start on a slope
    // goes to the search at once.
    // A free fit that has not converged within the budget goes to the
    // search too, its evaluations counted.
    if (b.chi2 <= a.chi2 && b.chi2 <= c.chi2) {
        Model mq = m;
        FitOptions fq = f;
        fq.max_evals = kQuickEvals;
        FitReport rq;
        if (!fit_model(mq, pos, fq, rq)) {
            rep = rq;
            return false;
        }
        if (rq.converged || rq.abandoned) {
            m = std::move(mq);
            rep = std::move(rq);
            rep.evals += evals;
            rep.seconds += seconds;
            return true;
        }
        evals += rq.evals;
        seconds += rq.seconds;
    }
    for (int walk = 0; walk < 64; ++walk) {
        if (a.chi2 < b.chi2 && a.chi2 <= c.chi2) { // downhill to shorter periods
            c = std::move(b);
            b = std::move(a);
            if (b.p <= pd.lower) break; // the bound: the free fit from there
            if (!held(b.m, std::max(pd.lower, b.p - step(b.p)), a)) return false;
        } else if (c.chi2 < b.chi2) {
            a = std::move(b);
            b = std::move(c);
            if (b.p >= hi) {
                if (hi < 1.25 * span) break; // the effect's upper bound: the free fit
                m = std::move(b.m);          // a trend (fit_shown is false for it)
                rep = b.rep;
                rep.n_free += int(period.size()); // counted as the free fit would
                rep.evals = evals;
                rep.seconds = seconds;
                rep.abandoned = true;
                rep.message = "abandoned: the period's profile falls past the span of the measured lengths";
                return true;
            }
            if (!held(b.m, std::min(hi, b.p + step(b.p)), c)) return false;
        } else {
            bracketed = std::isfinite(a.chi2) && std::isfinite(c.chi2);
            break;
        }
    }
    const double h = step(b.p);
    // --- successive parabolic interpolation within (a, c), golden section
    // when the parabola's vertex is not usefully inside
    // Down to a bracket of an eighth of the step (a thirty-second of a phase
    // turn over the span): the free fit from there is within the reach of
    // its linearisation, and finishes the job in a few evaluations.
    const double tol = h / 16;
    for (int it = 0; bracketed && it < 12 && c.p - a.p > 2 * tol; ++it) {
        const double d1 = b.p - a.p, d2 = b.p - c.p, f1 = b.chi2 - c.chi2, f2 = b.chi2 - a.chi2;
        const double den = d1 * f1 - d2 * f2;
        double v = den != 0 ? b.p - 0.5 * (d1 * d1 * f1 - d2 * d2 * f2) / den : NAN;
        const bool left_larger = b.p - a.p > c.p - b.p;
        if (!(v > a.p + tol && v < c.p - tol) || std::fabs(v - b.p) < tol)
            v = left_larger ? b.p - 0.382 * (b.p - a.p) : b.p + 0.382 * (c.p - b.p);
        Point t;
        if (!held(b.m, v, t)) return false;
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
    // --- everything free from the profile's minimum. (Not on a budget:
    // capped at 30 evaluations, a final fit on a small jig whose ripple's
    // period lies past the span stops half-way at a period inside it, and is
    // taken as shown with a chi-square 70 % too high; 11 of 12 such jigs
    // then recommend another model.)
    m = std::move(b.m);
    const bool ok = fit_model(m, pos, f, rep);
    rep.evals += evals;
    rep.seconds += seconds;
    return ok;
}

} // namespace diag
} // namespace cdm
