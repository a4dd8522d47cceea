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

#include "calib/diag_context.h"
#include "calib/diag_findings.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

namespace {

struct Point {
    double p = 0; // the period
    double chi2 = INFINITY;
    Model m{DeviceGeometry{}};
};

} // namespace

bool fit_seeded_period(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &f0,
                       const std::vector<std::pair<size_t, size_t>> &period, double start_chi2,
                       const std::vector<std::pair<const Model *, double>> &known, FitReport &rep) {
    if (period.size() != 1) return fit_model(m, pos, f0, rep); // (a user effect with several: the plain joint fit)
    // Every point is weighed as f0 says (weigh_with): the whitening once.
    FitOptions f = f0;
    if (f.weigh_with && !f.weights) f.weights = fit_weights(*f.weigh_with, pos, f);
    const auto [e, q] = period[0];
    const ParamDesc &pd = m.effect_desc(e).params[q];
    const double span = length_span(pos);
    const double lo = std::max(pd.lower, kShortestPeriodMm), hi = std::min(pd.upper, span);
    int evals = 0;
    double seconds = 0;
    FitOptions fh = f;
    fh.hold = period;
    fh.abandon_above.clear();
    fh.statistics = false; // a point is its chi-square
    fh.single_step = true;  // from its neighbour's result, nearly linear in the rest
    FitReport last;
    // The held fit at period p from `from`'s values (p within the effect's bounds).
    auto held = [&](const Model &from, double p, Point &out) {
        out.p = p;
        out.m = from;
        auto v = out.m.effect_params(e);
        v[q] = p;
        std::string err;
        if (!out.m.set_effect_params(e, v, err)) return false;
        const bool ok = fit_model(out.m, pos, fh, last);
        evals += last.evals;
        seconds += last.seconds;
        out.chi2 = std::isnan(last.chi2) ? INFINITY : last.chi2;
        return ok;
    };
    auto finish_held = [&](const Point &pt, bool abandoned) {
        m = pt.m;
        rep = last;
        rep.chi2 = pt.chi2;
        rep.evals = evals;
        rep.seconds = seconds;
        rep.abandoned = abandoned;
        if (abandoned) rep.message = "abandoned: the period left the span of the measured lengths";
        return true;
    };
    Point b;
    b.p = m.effect_params(e)[q];
    b.chi2 = start_chi2;
    b.m = m;
    if (!(b.p >= lo && b.p <= hi)) return finish_held(b, true);
    // A quarter of a phase turn over the span: the profile's peaks are
    // about four such steps wide.
    const double h = std::min(b.p * b.p / (4 * span), 0.25 * b.p);
    // --- walk downhill to a bracket (a, b, c), b lowest; the other starts'
    // held fits within two steps serve as the first neighbours
    Point a, c;
    a.p = -INFINITY;
    c.p = INFINITY;
    for (auto &[km, kc] : known) {
        const double kp = km->effect_params(e)[q];
        if (kp < b.p && kp >= b.p - 2 * h && kp > a.p) {
            a.p = kp;
            a.chi2 = std::isnan(kc) ? INFINITY : kc;
            a.m = *km;
        } else if (kp > b.p && kp <= b.p + 2 * h && kp < c.p) {
            c.p = kp;
            c.chi2 = std::isnan(kc) ? INFINITY : kc;
            c.m = *km;
        }
    }
    if ((!std::isfinite(a.p) && !held(b.m, std::max(pd.lower, b.p - h), a)) ||
        (!std::isfinite(c.p) && !held(b.m, std::min(pd.upper, b.p + h), c)))
        return false;
    for (int walk = 0; walk < 64 && (a.chi2 < b.chi2 || c.chi2 < b.chi2); ++walk) {
        if (a.chi2 < c.chi2) { // downhill to shorter periods
            c = std::move(b);
            b = std::move(a);
            if (b.p <= lo) return finish_held(b, true);
            if (!held(b.m, std::max(pd.lower, b.p - h), a)) return false;
        } else {
            a = std::move(b);
            b = std::move(c);
            if (b.p >= hi) return finish_held(b, true); // a trend, not a period the data repeat
            if (!held(b.m, std::min(pd.upper, b.p + h), c)) return false;
        }
    }
    if (a.chi2 < b.chi2 || c.chi2 < b.chi2) return finish_held(a.chi2 < c.chi2 ? a : c, true); // (no bracket)
    // --- successive parabolic interpolation within (a, c), golden section
    // when the parabola's vertex is not usefully inside
    // Down to a bracket of an eighth of the step (a thirty-second of a phase
    // turn over the span): the free fit from there is within the reach of
    // its linearisation, and finishes the job in a few evaluations.
    const double tol = h / 16;
    for (int it = 0; it < 12 && c.p - a.p > 2 * tol; ++it) {
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
    // --- everything free from the profile's minimum
    m = std::move(b.m);
    const bool ok = fit_model(m, pos, f, rep);
    rep.evals += evals;
    rep.seconds += seconds;
    return ok;
}

} // namespace diag
} // namespace cdm
