// See jig.h. docs/calibration.md, "The jig as it is", explains the
// tests and their wording.
#include "calib/evaluation/jig.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>

#include "calib/evaluation/findings.h"
#include "calib/evaluation/stats.h"
#include "calib/fit/fit.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {

const char *kAxis[3] = {"x", "y", "z"};

} // namespace

Eval without_fixture(const Eval &E, const Grid &G, const FixtureOffsets &f) {
    Eval out = E;
    for (size_t j = 0; j < out.res.size(); ++j)
        for (int a = 0; a < 3; ++a) {
            auto it = f.find({G.height_index[j], a});
            if (it != f.end()) out.res[j](a) -= it->second;
        }
    return out;
}

double x_rms_without_fixture(const Eval &E, const Grid &G, const V3 &jig, const std::vector<PreparedPos> &pos) {
    // Only where the fit has the offsets too (a layered jig of two heights
    // or more): on one height, or scattered positions, nothing is the
    // fixture's (the judge's own per-height mean there is spatial.cpp's
    // business).
    if (!G.layered || !(E.err[0].n > 0)) return NAN;
    std::set<int> hs;
    for (size_t j = 0; j < E.res.size(); ++j)
        if (E.ok[j]) hs.insert(G.height_index[j]);
    if (hs.size() < 2) return NAN;
    const FixtureOffsets f = fixture_offsets(E, G, jig);
    // sum over a position's n samples of (r - o)^2 = sum r^2 - 2 o n r + n o^2,
    // r its mean residual (evaluate() accumulates the samples' moments so)
    double ss = E.err[0].ss;
    for (size_t j = 0; j < E.res.size() && j < pos.size(); ++j) {
        if (!E.ok[j]) continue;
        auto it = f.find({G.height_index[j], 0});
        if (it == f.end()) continue;
        const double o = it->second, n = double(pos[j].n);
        ss += n * (o * o - 2 * o * E.res[j](0));
    }
    return std::sqrt(std::max(0.0, ss) / E.err[0].n);
}

bool fixture_lr(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &fo, FixtureLR &out,
                std::string &err) {
    out = FixtureLR{};
    if (fo.fixture_count < 2 || fo.fixture.size() != pos.size()) {
        out.why = "no fixture heights";
        return true;
    }
    FitOptions with = fo, without = fo;
    without.fixture.clear();
    without.fixture_count = 0;
    // The same weights for both: those of m, or of what fo names. (m's own
    // fit is not reused for the with-side: it was weighed with the model it
    // started from, so its chi-square is on other weights; refitted from
    // its own optimum, only the offsets move, in a few evaluations.)
    if (!with.weigh_with) with.weigh_with = without.weigh_with = &m;
    Model a = m, b = m;
    FitReport ra, rb;
    const bool oka = fit_model(a, pos, with, ra);
    if (!oka || !fit_model(b, pos, without, rb)) {
        err = !oka ? ra.message : rb.message;
        if (err.empty()) err = "fit cancelled";
        return false;
    }
    if (!ra.converged || !rb.converged) {
        out.why = std::string("the refit ") + (!ra.converged ? "with" : "without") +
                  " the offsets did not converge (" + (!ra.converged ? ra.message : rb.message) + ")";
        return true;
    }
    const int dof = ra.n_obs - ra.n_free - ra.n_fixture;
    out.tested = true;
    out.chi2 = std::max(0.0, rb.chi2 - ra.chi2);
    out.scale = dof > 0 ? std::max(1.0, ra.chi2 / dof) : 1.0;
    return true;
}

namespace {

// The fixture's test's words in the report.
const char *fixture_test(bool lr) {
    return !lr ? "x (the axis the spacers set): chi-square of the per-height weighted mean residuals "
                 "about zero, K degrees of freedom; y, z: about their common mean, K - 1; Bonferroni "
                 "over the three axes"
               : "x (the axis the spacers set, fitted as per-height offsets): likelihood ratio, the "
                 "model refitted without the offsets, delta chi-square over max(1, chi2/dof of the "
                 "model) against chi-square(K) (conservative: the offsets' prior and what the "
                 "device's parameters can take leave fewer than K free); y, z: "
                 "chi-square of the per-height weighted mean residuals about their common mean, K - 1 "
                 "degrees of freedom; Bonferroni over the three axes";
}

// Each fixture height (mm): the mean x reference of its positions.
json fixture_heights_mm(const Grid &G, const std::vector<PreparedPos> &pos, const std::set<int> &heights) {
    std::map<int, double> href; // a height index's fixture height (mm): the mean x reference
    std::map<int, int> hn;
    for (size_t j = 0; j < pos.size(); ++j) {
        href[G.height_index[j]] += pos[j].ref(0);
        hn[G.height_index[j]] += 1;
    }
    json out = json::array();
    for (int h : heights) out.push_back(href[h] / hn[h]);
    return out;
}

// x's per-height means: their common part (weighted), and the heights'
// spread about it.
struct FixtureX {
    double common = 0, spread = 0, spread_chi2 = 0, common_chi2 = 0;
    bool one_sign = true; // every height's offset on the common part's side
};

FixtureX fixture_x(const std::map<std::pair<int, int>, HeightMean> &hm, const std::set<int> &heights, double sw,
                   double swm) {
    FixtureX x;
    x.common = swm / sw;
    x.common_chi2 = x.common * x.common * sw;
    for (int h : heights) {
        const auto &m = hm.at({h, 0});
        if (m.mean() * x.common <= 0) x.one_sign = false;
        const double d = m.mean() - x.common;
        x.spread = std::max(x.spread, std::fabs(d));
        x.spread_chi2 += d * d / (m.se() * m.se());
    }
    return x;
}

// The sentence naming the fixture's offsets on axis `axis` (the worst
// significant one, fx_worst mm), from fx (the report's "fixture"); past:
// the largest per-height mean past kFixtureMaxMm.
std::string fixture_text(const json &fx, int axis, double fx_worst, double past, const FixtureX &x,
                         double x_spread_p, double x_common_p, bool x_apart, bool x_as_whole) {
    std::string per;
    for (auto &v : fx["offsets_mm"][kAxis[axis]]) per += (per.empty() ? "" : ", ") + fmt_num(v.get<double>(), 3, true);
    // In x the offsets are the spacers' and the jig's mounting together
    // (one direction of the data): the same at every height, they are
    // not told as each height's own.
    const std::string what =
        axis != 0 ? "each fixture height has its own offset, up to " + fmt_num(fx_worst, 3) + " mm in " +
                        kAxis[axis] + " (per height: " + per + " mm; " +
                        fmt_p(fx["p_value"][kAxis[axis]].get<double>()) + "): the height fixture's spacers"
        : x_as_whole
            ? "the jig sits " + fmt_num(x.common, 3, true) + " mm off in x at every fixture height (per height: " +
                  per + " mm; " + fmt_p(fx["p_value"]["x"].get<double>()) + "; the common part alone " +
                  fmt_p(x_common_p) + "; their spread of " + fmt_num(x.spread, 3) +
                  " mm about it is not significant at " + fmt_num(kFindingLevel, 3) + ", " + fmt_p(x_spread_p) +
                  "): the jig's mounting along x, or its spacers' common error"
        : x_apart
            ? "each fixture height has its own offset, up to " + fmt_num(fx_worst, 3) +
                  " mm in x (per height: " + per + " mm, their common part " + fmt_num(x.common, 3, true) +
                  " mm; " + fmt_p(fx["p_value"]["x"].get<double>()) + "; their spread about it " +
                  fmt_p(x_spread_p) +
                  "): the height fixture's spacers (the common part: their mean error, or the jig's mounting along x)"
            : "the fixture heights are off in x, up to " + fmt_num(fx_worst, 3) + " mm (per height: " + per +
                  " mm; together " + fmt_p(fx["p_value"]["x"].get<double>()) +
                  "; neither their common part (" + fmt_num(x.common, 3, true) + " mm, " + fmt_p(x_common_p) +
                  ") nor their spread about it (" + fmt_p(x_spread_p) + ") is significant alone at " +
                  fmt_num(kFindingLevel, 3) + "): the height fixture's spacers or the jig's mounting along x";
    return what + ", the jig's error, taken out of the fit and the "
                  "tests (up to " + fmt_num(kFixtureMaxMm, 2) + " mm per height" +
           (fx["taken_as_jig"].get<bool>()
                ? std::string(")")
                : "; a height's mean residual of " + fmt_num(past, 3) +
                      " mm is past that, more than a machined spacer plausibly is off: the part "
                      "past " + fmt_num(kFixtureMaxMm, 2) + " mm stays in the residual; check "
                      "the fixture)");
}

// --- the fixture: per-height means, tested against their standard
// errors. In x (the axis the spacers set, where the fit has an offset
// per height) the means themselves: their common part is the spacers'
// mean error, the jig's placement along x, which the fit gives the
// fixture too (calib/fit/problem.h, build_gauge), K degrees of freedom. In y
// and z, relative to their common part (the jig's placement there,
// which no spacer sets), K - 1. Fills out["fixture"] and its sentence.
void fixture_analysis(const Eval &E, const Grid &G, const std::vector<PreparedPos> &pos, const V3 &jig,
                      double small, const FixtureLR *lr, const std::set<int> &heights, json &out) {
    const int K = int(heights.size());
    const auto hm = height_means(E, G, jig);
    json fx = {{"heights_mm", json::array()}, {"offsets_mm", json::object()}, {"max_mm", json::object()},
               {"p_value", json::object()}, {"taken_as_jig", true}, {"test", fixture_test(lr != nullptr)}};
    if (lr && lr->tested) {
        fx["lr_chi2_x"] = lr->chi2;
        fx["lr_scale_x"] = lr->scale;
    } else if (lr) {
        fx["x_untested"] = lr->why;
    }
    fx["heights_mm"] = fixture_heights_mm(G, pos, heights);
    double fx_worst = 0;
    double past = 0; // the largest per-height mean past kFixtureMaxMm (mm)
    int fx_axis = -1;
    FixtureX x;
    for (int a = 0; a < 3; ++a) {
        double sw = 0, swm = 0;
        for (int h : heights) {
            const auto &m = hm.at({h, a});
            sw += 1 / (m.se() * m.se());
            swm += m.mean() / (m.se() * m.se());
        }
        const double common = a == 0 ? 0.0 : swm / sw; // x: the spacers' mean error is theirs
        if (a == 0) x = fixture_x(hm, heights, sw, swm); // x's common part and spread, for the words
        double chi2 = 0, mx = 0;
        json offs = json::array();
        for (int h : heights) {
            const auto &m = hm.at({h, a});
            const double d = m.mean() - common;
            chi2 += d * d / (m.se() * m.se());
            mx = std::max(mx, std::fabs(d));
            offs.push_back(d);
            if (std::fabs(m.mean()) > kFixtureMaxMm) {
                fx["taken_as_jig"] = false;
                past = std::max(past, std::fabs(m.mean()));
            }
        }
        // x: the likelihood ratio when given (its offsets were fitted beside
        // the device's parameters, which can take a trend over the heights).
        fx["offsets_mm"][kAxis[a]] = offs;
        fx["max_mm"][kAxis[a]] = mx;
        const bool by_lr = a == 0 && lr;
        if (by_lr && !lr->tested) { // no number, and nothing named in x
            fx["p_value"][kAxis[a]] = nullptr;
            continue;
        }
        const double stat = by_lr ? lr->chi2 / lr->scale : chi2;
        const double p = std::min(1.0, 3 * chi2_sf(stat, a == 0 ? K : K - 1));
        fx["p_value"][kAxis[a]] = p;
        if (p < kFindingLevel && mx >= small && mx > fx_worst) {
            fx_worst = mx;
            fx_axis = a;
        }
    }
    // Which words x gets, once the offsets together are significant: the
    // heights are told apart when their spread about the common part is
    // significant (chi-square of the per-height means about it against
    // their standard errors, K - 1 degrees of freedom); the jig sits off as
    // a whole when the common part is significant on its own (its square
    // over its variance, 1 degree of freedom), the spread is not, and every
    // height lies on its side; otherwise neither is shown alone and the
    // offsets are named together. Both at the findings' level, x alone (no
    // Bonferroni over the axes: these choose the words, the joint test
    // above decided that there is something to word). (A tenth of the
    // noise floor as the rule would let the noise decide: a pure 0.15 mm
    // shift on a 7 x 7 jig of 10 samples reads "each fixture height has its
    // own offset" at a spread of 2.3 standard errors; the spread's test
    // alone reads "the jig sits +0.012 mm off at every height" for
    // per-height offsets of +0.034 and -0.010 mm, a common part 2.7
    // standard errors from zero: test_diagnose.cpp,
    // a_jig_off_in_x_is_the_jigs, and test_jig_words.cpp,
    // mixed_signs_are_the_heights_own, hold them.)
    const double x_spread_p = chi2_sf(x.spread_chi2, K - 1);
    const double x_common_p = chi2_sf(x.common_chi2, 1);
    const bool x_apart = x_spread_p < kFindingLevel;
    const bool x_as_whole = !x_apart && x_common_p < kFindingLevel && x.one_sign;
    fx["x_common_mm"] = x.common;
    fx["x_common_p_value"] = x_common_p;
    fx["x_spread_mm"] = x.spread;
    fx["x_spread_p_value"] = x_spread_p;
    out["fixture"] = fx;
    if (fx_axis >= 0)
        out["text"].push_back(
            fixture_text(fx, fx_axis, fx_worst, past, x, x_spread_p, x_common_p, x_apart, x_as_whole));
}

using Holes = std::vector<std::pair<std::pair<long, long>, std::vector<size_t>>>;

// The hole means' neighbour graph over the plate (adjacent holes).
Grid hole_graph(const Holes &H) {
    std::map<std::pair<long, long>, int> hidx;
    for (size_t i = 0; i < H.size(); ++i) hidx[H[i].first] = int(i);
    Grid hg;
    hg.nb.resize(H.size());
    hg.height_index.assign(H.size(), 0);
    for (size_t i = 0; i < H.size(); ++i)
        for (auto d : {std::pair<long, long>{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
            auto it = hidx.find({H[i].first.first + d.first, H[i].first.second + d.second});
            if (it != hidx.end()) hg.nb[i].push_back(it->second);
        }
    return hg;
}

// One axis's analysis of variance by hole.
struct HoleAxis {
    double grand = 0, var_hole = 0, msw = 0, seat = 0, F = 0, p = 1, mz = 0, mp = 1;
};

HoleAxis hole_axis(const Eval &R, const Holes &H, const Grid &hg, int a, double N, double df1, double df2,
                   double n0) {
    HoleAxis x;
    double g = 0;
    for (auto &h : H)
        for (size_t j : h.second) g += R.res[j](a);
    g /= N;
    double ssb = 0, ssw = 0, noise = 0;
    std::vector<double> hmeans;
    for (auto &h : H) {
        double m = 0;
        for (size_t j : h.second) m += R.res[j](a);
        m /= double(h.second.size());
        hmeans.push_back(m);
        ssb += double(h.second.size()) * (m - g) * (m - g);
        for (size_t j : h.second) {
            ssw += (R.res[j](a) - m) * (R.res[j](a) - m);
            noise += R.var_mean[j](a);
        }
    }
    const double msb = ssb / df1, msw = ssw / df2;
    x.F = msw > 0 ? msb / msw : 0;
    x.p = std::min(1.0, 3 * f_sf(x.F, df1, df2));
    x.var_hole = std::max(0.0, (msb - msw) / n0);
    x.msw = msw;
    x.grand = g;
    x.seat = std::sqrt(std::max(0.0, msw - noise / N));
    const std::vector<char> all_ok(H.size(), 1);
    x.mz = moran_z(hmeans, all_ok, hg);
    x.mp = std::min(1.0, 3 * normal_sf(x.mz));
    return x;
}

// The finding of a residual that repeats at every height on device_axes
// and is smooth over the plate: the device's.
json hole_device_finding(const json &ho, const std::vector<int> &device_axes, double dev_amp, double dev_p) {
    std::string ax;
    for (int a : device_axes) ax += (ax.empty() ? "" : ", ") + std::string(kAxis[a]);
    return {{"variable", "hole"},
            {"variable_kind", "hole"},
            {"cable", nullptr},
            {"kind", "repeat"},
            {"axis", kAxis[device_axes[0]]},
            {"period_mm", nullptr},
            {"amplitude_mm", dev_amp},
            {"p_value", dev_p},
            {"r2", nullptr},
            {"test", ho["test"]},
            {"text", "the " + ax + " residual repeats at the same hole at every height and is smooth "
                     "over the plate (about " + fmt_num(dev_amp, 3) + " mm): a device effect that does not "
                     "change with height, not the plate's holes (a plate's hole errors are independent "
                     "from hole to hole)"}};
}

// The plate's holes named on plate_axes: each hole's error, its mean over
// the heights shrunk by the share of the hole variance in it (the best
// linear unbiased predictor of a random effect), out of the residual the
// device is judged on (A.offset); the sentence.
void name_plate(const Eval &R, const Holes &H, const std::vector<int> &plate_axes, const V3 &var_hole_a,
                const V3 &msw_a, const V3 &grand, const json &ho, JigAnalysis &A) {
    for (auto &h : H)
        for (int a : plate_axes) {
            double m = 0;
            for (size_t j : h.second) m += R.res[j](a);
            m /= double(h.second.size());
            const double shrink = var_hole_a(a) / (var_hole_a(a) + msw_a(a) / double(h.second.size()));
            for (size_t j : h.second) A.offset[j](a) += shrink * (m - grand(a));
        }
    std::string what, tests;
    for (int a : plate_axes) {
        what += (what.empty() ? "" : " and ") + fmt_num(ho["std_mm"][kAxis[a]].get<double>(), 3) + " mm in " + kAxis[a];
        tests += (tests.empty() ? "" : "; ") + std::string(kAxis[a]) + " F = " +
                 fmt_num(ho["F"][kAxis[a]].get<double>(), 2) + ", " + fmt_p(ho["p_value"][kAxis[a]].get<double>()) +
                 ", Moran z = " + fmt_num(ho["smooth_z"][kAxis[a]].get<double>(), 1);
    }
    A.report["text"].push_back("the residual repeats at the same hole at every height: the plate's holes are off by "
                               "about " + what + " (analysis of variance by hole: " + tests +
                               "; independent from hole to hole): the jig's error, not the device's; the fit weighs "
                               "it as the jig's (each hole's readings one block where its share is significant: "
                               "jig_tolerance_mm.plate_holes)");
}

// --- the holes: one-way analysis of variance of the residual (the
// fixture's offsets removed) by hole, over the holes seen at two
// heights or more. Sets A.offset to the fixture's offsets, and adds the
// plate's holes' when they are named.
void holes_analysis(const Eval &E, const Grid &G, const std::vector<PreparedPos> &pos, const V3 &jig, double small,
                    int K, JigAnalysis &A) {
    json &out = A.report;
    const size_t P = E.res.size();
    const FixtureOffsets fo = fixture_offsets(E, G, jig);
    for (size_t j = 0; j < P; ++j)
        for (int a = 0; a < 3; ++a) {
            auto it = fo.find({G.height_index[j], a});
            if (it != fo.end()) A.offset[j](a) = it->second;
        }
    const Eval R = without_fixture(E, G, fo);
    std::map<std::pair<long, long>, std::vector<size_t>> holes;
    for (size_t j = 0; j < P; ++j)
        if (R.ok[j]) holes[{std::lround(pos[j].ref(1) / G.pitch), std::lround(pos[j].ref(2) / G.pitch)}].push_back(j);
    Holes H;
    for (auto &kv : holes)
        if (kv.second.size() >= 2) H.push_back(kv);
    const double I = double(H.size());
    double N = 0, sn2 = 0;
    for (auto &h : H) {
        N += double(h.second.size());
        sn2 += double(h.second.size()) * double(h.second.size());
    }
    const double df1 = I - 1, df2 = N - I - (K - 1);
    if (I < 10 || df2 < 10) return;
    const double n0 = (N - sn2 / N) / df1; // the effective heights per hole
    const Grid hg = hole_graph(H);
    json ho = {{"holes", I}, {"heights_per_hole", n0}, {"std_mm", json::object()}, {"F", json::object()},
               {"dof", {df1, df2}}, {"p_value", json::object()}, {"smooth_z", json::object()},
               {"smooth_p", json::object()}, {"named", nullptr},
               {"test", "one-way analysis of variance of the residual by hole (per-height means removed), F-test, "
                        "Bonferroni over the three axes; the hole means' Moran's I over adjacent holes (normal "
                        "approximation, two axes' worth of Bonferroni) tells a plate's independent hole errors "
                        "(white) from a device effect that does not vary with height (smooth)"}};
    V3 seat = V3::Zero(), var_hole_a = V3::Zero(), msw_a = V3::Zero(), grand = V3::Zero();
    std::vector<int> plate_axes, device_axes;
    double dev_p = 1, dev_amp = 0;
    for (int a = 0; a < 3; ++a) {
        const HoleAxis x = hole_axis(R, H, hg, a, N, df1, df2, n0);
        var_hole_a(a) = x.var_hole;
        msw_a(a) = x.msw;
        grand(a) = x.grand;
        seat(a) = x.seat;
        ho["std_mm"][kAxis[a]] = std::sqrt(x.var_hole);
        ho["F"][kAxis[a]] = x.F;
        ho["p_value"][kAxis[a]] = x.p;
        ho["smooth_z"][kAxis[a]] = x.mz;
        ho["smooth_p"][kAxis[a]] = x.mp;
        if (x.p < kFindingLevel && std::sqrt(x.var_hole) >= small) {
            if (x.mp >= kFindingLevel) {
                plate_axes.push_back(a);
            } else {
                device_axes.push_back(a);
                if (std::sqrt(x.var_hole) > dev_amp) dev_amp = std::sqrt(x.var_hole), dev_p = std::max(x.p, x.mp);
            }
        }
    }
    out["seat_std_mm"] = {seat(0), seat(1), seat(2)};
    if (!device_axes.empty()) {
        ho["named"] = "device";
        out["finding"] = hole_device_finding(ho, device_axes, dev_amp, dev_p);
    } else if (!plate_axes.empty()) {
        ho["named"] = "plate";
        name_plate(R, H, plate_axes, var_hole_a, msw_a, grand, ho, A);
    }
    out["holes"] = ho;
}

} // namespace

JigAnalysis jig_analysis(const Eval &E, const Grid &G, const std::vector<PreparedPos> &pos, const V3 &jig,
                         const V3 &noise, const FixtureLR *lr) {
    JigAnalysis A;
    json &out = A.report;
    out = {{"fixture", nullptr}, {"holes", nullptr}, {"text", json::array()}, {"finding", nullptr}};
    const size_t P = E.res.size();
    A.offset.assign(P, V3::Zero());
    const double small = 0.1 * noise.norm(); // what the verdict calls negligible
    std::set<int> heights;
    for (size_t j = 0; j < P; ++j)
        if (E.ok[j]) heights.insert(G.height_index[j]);
    const int K = int(heights.size());
    if (!G.layered || K < 2) return A; // no fixture heights: nothing repeats
    fixture_analysis(E, G, pos, jig, small, lr, heights, out);
    holes_analysis(E, G, pos, jig, small, K, A);
    return A;
}

} // namespace diag
} // namespace cdm
