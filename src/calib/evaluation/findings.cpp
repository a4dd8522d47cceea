// See findings.h.
#include "calib/evaluation/findings.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include <Eigen/Dense>

#include "calib/evaluation/residual.h"
#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {
const char *kAxis[3] = {"x", "y", "z"};
} // namespace

LengthView length_view(const Model &m, const std::vector<PreparedPos> &pos) {
    const size_t P = pos.size();
    const DeviceGeometry &g = m.geometry();
    LengthView v;
    v.lmean.resize(P);
    v.lres.resize(P);
    v.angle.resize(P);
    v.dir.resize(P);
    v.chord.resize(P);
    // The model's readings at every reference (one call of a user effect
    // that works on arrays over them all).
    std::vector<double> tp(3 * P), ts(P), yp(4 * P);
    std::vector<int> st(P);
    for (size_t j = 0; j < P; ++j) {
        m.jig_to_device(pos[j].ref.data(), &tp[3 * j]);
        ts[j] = pos[j].t_s;
    }
    m.readings_at(P, tp.data(), ts.data(), yp.data(), st.data());
    for (size_t j = 0; j < P; ++j) {
        const double *t = &tp[3 * j];
        double *y = &yp[4 * j];
        if (st[j] != 0)
            for (int c = 0; c < 4; ++c) y[c] = NAN; // a failing user effect: no residual here
        for (int c = 0; c < 4; ++c) {
            v.lres[j][size_t(c)] = pos[j].mean(c) - y[c];
            v.lmean[j][size_t(c)] = pos[j].mean(c);
            auto an = g.anchor(c);
            auto ho = g.holder(c);
            double d[3] = {t[0] + ho[0] - an[0], t[1] + ho[1] - an[1], t[2] + ho[2] - an[2]};
            v.angle[j][size_t(c)] = std::atan2(d[0], std::hypot(d[1], d[2])) * 180 / M_PI;
            const V3 u(d[0], d[1], d[2]);
            v.dir[j][size_t(c)] = u.norm() > 0 ? V3(u / u.norm()) : V3::Zero();
            v.chord[j][size_t(c)] = u.norm();
        }
    }
    return v;
}

LengthView shifted(const LengthView &v, const std::vector<V3> &off) {
    LengthView out = v;
    for (size_t j = 0; j < out.lres.size() && j < off.size(); ++j)
        for (size_t c = 0; c < 4; ++c) out.lres[j][c] -= v.dir[j][c].dot(off[j]);
    return out;
}

double periods_searched(double span_mm) {
    return span_mm > kShortestPeriodMm ? span_mm * (1.0 / kShortestPeriodMm - 1.0 / span_mm) : 0.0;
}

PeriodPeak length_period(const LengthView &v) {
    PeriodPeak pk;
    const size_t P = v.lmean.size();
    double lo = INFINITY, hi = -INFINITY;
    for (size_t j = 0; j < P; ++j)
        for (int c = 0; c < 4; ++c)
            if (std::isfinite(v.lres[j][size_t(c)])) {
                lo = std::min(lo, v.lmean[j][size_t(c)]);
                hi = std::max(hi, v.lmean[j][size_t(c)]);
            }
    const double span = hi - lo;
    // Periods from 8 mm to the span: one full turn seen at least (a longer
    // one is a smooth trend to this test, as to the fit).
    const double fmin = 1.0 / span, fmax = 1.0 / kShortestPeriodMm;
    if (!(span > 0) || !(fmax > fmin)) return pk;
    // Oversampled 5x against the natural resolution 1/span, so that the
    // grid's own step is no part of the period's error.
    const int nf = std::max(200, std::min(20000, int(5 * span * (fmax - fmin))));
    const double df = (fmax - fmin) / (nf - 1);
    std::vector<double> freqs;
    for (int k = 0; k < nf; ++k) freqs.push_back(fmin + (fmax - fmin) * k / (nf - 1));
    std::vector<double> pooled(freqs.size(), 0);
    for (int c = 0; c < 4; ++c) {
        std::vector<double> t, y;
        for (size_t j = 0; j < P; ++j)
            if (std::isfinite(v.lres[j][size_t(c)])) {
                t.push_back(v.lmean[j][size_t(c)]);
                y.push_back(v.lres[j][size_t(c)]);
            }
        if (t.size() < 8) return pk;
        // A smooth trend in length (gain, non-linearity) would swamp the
        // low frequencies: take a quadratic out first.
        detrend_quadratic(t, y);
        auto pw = lomb(t, y, fmin, df, freqs.size());
        for (size_t f = 0; f < freqs.size(); ++f) pooled[f] += pw[f];
    }
    size_t bf = size_t(std::max_element(pooled.begin(), pooled.end()) - pooled.begin());
    const double z = pooled[bf];
    // Each normalised power is ~Exp(1) under noise; the sum of four ~Gamma(4,1).
    const double sf = std::exp(-z) * (1 + z + z * z / 2 + z * z * z / 6);
    pk.fap = false_alarm(sf, periods_searched(span));
    pk.period_mm = 1.0 / freqs[bf];
    for (int c = 0; c < 4; ++c) {
        Eigen::MatrixXd A(P, 5);
        Eigen::VectorXd b(P);
        for (size_t j = 0; j < P; ++j) {
            const double l = v.lmean[j][size_t(c)], ph = 2 * M_PI * freqs[bf] * l, u = (l - lo) / span;
            const bool ok = std::isfinite(v.lres[j][size_t(c)]);
            A(long(j), 0) = ok ? 1 : 0;
            A(long(j), 1) = ok ? std::sin(ph) : 0;
            A(long(j), 2) = ok ? std::cos(ph) : 0;
            A(long(j), 3) = ok ? u : 0;
            A(long(j), 4) = ok ? u * u : 0;
            b(long(j)) = ok ? v.lres[j][size_t(c)] : 0;
        }
        Eigen::VectorXd s = A.colPivHouseholderQr().solve(b);
        pk.amplitude_mm += std::hypot(s(1), s(2)) / 4;
    }
    pk.valid = true;
    return pk;
}

namespace {

// Weighted least squares y ~ X; returns the coefficients, their standard
// errors from the residual scatter (s^2 (X'WX)^-1), and the residual dof.
struct Ls {
    Eigen::VectorXd beta, se;
    double dof = 0, s2 = 0;
};
Ls wls(const Eigen::MatrixXd &X, const Eigen::VectorXd &y, const Eigen::VectorXd &w) {
    Ls r;
    const Eigen::VectorXd sw = w.cwiseSqrt();
    const Eigen::MatrixXd A = sw.asDiagonal() * X;
    const Eigen::VectorXd b = sw.asDiagonal() * y;
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    r.beta = qr.solve(b);
    r.dof = double(X.rows()) - double(qr.rank());
    r.s2 = r.dof > 0 ? (b - A * r.beta).squaredNorm() / r.dof : 0;
    const Eigen::MatrixXd C = (A.transpose() * A).completeOrthogonalDecomposition().pseudoInverse() * r.s2;
    r.se = C.diagonal().cwiseMax(0).cwiseSqrt();
    return r;
}

// Drift over the session: the readings' common residual (the mean over the
// four cables, which a drift of the electronics moves together) against
// acquisition time. Within each height (per-height means removed: what the
// height explains) the slope must be significant, and the session-long
// slope across heights must agree with it (3 standard errors): one drift over
// the whole session, not a height effect that happens to follow the order.
// lv: the residual with the jig's estimated errors out (the within-height
// slope); across: the same before the jig's errors (the fixture's
// per-height offsets, the holes') are taken out. With heights measured one
// after the other a drift's step from height to height is exactly what a
// fixture offset can take, so the session-long slope is judged on the
// residual as it was: where it agrees with the slope inside every height,
// one drift explains both, and the fixture's offsets were following it.
json drift_finding(const std::vector<PreparedPos> &pos, const LengthView &lv, const LengthView &across) {
    const size_t P = pos.size();
    std::vector<size_t> idx;
    for (size_t j = 0; j < P; ++j) {
        bool ok = true;
        for (int c = 0; c < 4; ++c) ok = ok && std::isfinite(lv.lres[j][size_t(c)]);
        if (ok) idx.push_back(j);
    }
    if (idx.size() < 20) return nullptr;
    double tmin = INFINITY, tmax = -INFINITY;
    std::vector<double> hv;
    for (size_t j : idx) {
        tmin = std::min(tmin, pos[j].t_s);
        tmax = std::max(tmax, pos[j].t_s);
        hv.push_back(pos[j].ref(0));
    }
    if (!(tmax > tmin)) return nullptr;
    std::sort(hv.begin(), hv.end());
    hv.erase(std::unique(hv.begin(), hv.end(), [](double a, double b) { return std::fabs(a - b) < 1e-6; }), hv.end());
    const bool layered = hv.size() <= 20 && hv.size() * 4 <= idx.size();
    const long n = long(idx.size());
    const double th = (tmax - tmin) / 3600.0; // session length, h
    Eigen::VectorXd y(n), w(n);
    Eigen::VectorXd ya(n);
    for (long r = 0; r < n; ++r) {
        const size_t j = idx[size_t(r)];
        double s = 0, sa = 0, v = 0;
        for (int c = 0; c < 4; ++c) {
            s += lv.lres[j][size_t(c)] / 4;
            sa += across.lres[j][size_t(c)] / 4;
            v += pos[j].var_mean(c) / 16;
        }
        y(r) = s;
        ya(r) = std::isfinite(sa) ? sa : s;
        w(r) = 1.0 / std::max(v, 1e-12);
    }
    auto hour = [&](size_t j) { return (pos[j].t_s - tmin) / 3600.0; };
    // Within heights (or, without a height fixture, beside a quadratic in x).
    const long kh = layered ? long(hv.size()) : 3;
    Eigen::MatrixXd Xw = Eigen::MatrixXd::Zero(n, kh + 1);
    for (long r = 0; r < n; ++r) {
        const size_t j = idx[size_t(r)];
        if (layered) {
            const long h = long(std::lower_bound(hv.begin(), hv.end(), pos[j].ref(0) - 1e-6) - hv.begin());
            Xw(r, h) = 1;
        } else {
            Xw(r, 0) = 1;
            Xw(r, 1) = pos[j].ref(0);
            Xw(r, 2) = pos[j].ref(0) * pos[j].ref(0);
        }
        Xw(r, kh) = hour(j);
    }
    Ls within = wls(Xw, y, w);
    Eigen::MatrixXd Xp(n, 2);
    for (long r = 0; r < n; ++r) {
        Xp(r, 0) = 1;
        Xp(r, 1) = hour(idx[size_t(r)]);
    }
    Ls pooled = wls(Xp, ya, w);
    const double bw = within.beta(kh), sw = within.se(kh), bp = pooled.beta(1), sp = pooled.se(1);
    if (!(sw > 0) || !(sp > 0) || within.dof < 3) return nullptr;
    const double zt = std::fabs(bw) / sw;
    const double p = std::min(1.0, 2 * normal_sf(zt));
    const bool agree = std::fabs(bw - bp) <= 3 * std::hypot(sw, sp);
    if (!(p < kFindingLevel) || !agree || !(std::fabs(bp) / sp > 3)) return nullptr;
    const double total = bp * th;
    return {{"variable", "acquisition time"},
            {"variable_kind", "time"},
            {"cable", nullptr},
            {"kind", "drift"},
            {"axis", "length"},
            {"period_mm", nullptr},
            {"amplitude_mm", std::fabs(total)},
            {"rate_mm_per_h", bp},
            {"session_h", th},
            {"p_value", p},
            {"r2", nullptr},
            {"test", "slope of the four cables' mean reading residual against time within each height (per-height "
                     "means removed), two-sided z-test; the slope across the whole session agrees within 3 "
                     "standard errors"},
            {"text", "the readings drift by " + fmt_num(total, 3) + " mm over the session (" + fmt_num(bp, 3) +
                         " mm/h, all four cables together, within every height and across heights; " + fmt_p(p) +
                         "): warm the device up before measuring, or re-measure a reference hole at intervals; "
                         "pot_drift models it"}};
}

} // namespace

json residual_findings(const std::vector<PreparedPos> &pos, const LengthView &lv, const Eval &bE, const V3 &jig,
                       const LengthView &across) {
    const size_t P = pos.size();
    json findings = json::array();
    const PeriodPeak pk = length_period(lv);
    if (pk.valid && pk.fap < kFindingLevel)
        findings.push_back({{"variable", "cable length"}, {"variable_kind", "length"}, {"cable", nullptr},
                            {"kind", "periodic"}, {"axis", "length"}, {"period_mm", pk.period_mm},
                            {"amplitude_mm", pk.amplitude_mm}, {"p_value", pk.fap}, {"r2", nullptr},
                            {"test", "pooled Lomb-Scargle power of the four cables against Gamma(4,1), false-alarm "
                                     "probability over the independent frequencies searched"},
                            {"text", "the cable-length residual repeats every " + fmt_num(pk.period_mm, 1) +
                                         " mm of cable (amplitude " + fmt_num(pk.amplitude_mm, 3) +
                                         " mm) in all four cables: something turns with the drum (an eccentric drum "
                                         "or shaft, a pot track ripple: drum_eccentricity), or the reading is off "
                                         "in a band of cable length (a worn track); plot the length residual "
                                         "against the length"}});
    json drift = drift_finding(pos, lv, across);
    if (!drift.is_null()) findings.push_back(drift);
    // Trends of the position residual against physical variables.
    // kind and cable travel in the finding beside the English name, so
    // that the report routes it without parsing the text.
    struct Var {
        std::string name, kind;
        json cable;
        std::vector<double> v;
    };
    std::vector<Var> vars;
    Var h{"height", "height", nullptr, {}}, rho{"distance from centre", "radius", nullptr, {}};
    for (size_t j = 0; j < P; ++j) {
        h.v.push_back(pos[j].ref(0));
        rho.v.push_back(std::hypot(pos[j].ref(1), pos[j].ref(2)));
    }
    vars.push_back(h);
    vars.push_back(rho);
    for (int c = 0; c < 4; ++c) {
        Var l{"l" + std::to_string(c + 1), "length", c + 1, {}},
            an{"angle of cable " + std::to_string(c + 1), "angle", c + 1, {}};
        for (size_t j = 0; j < P; ++j) {
            l.v.push_back(lv.lmean[j][size_t(c)]);
            an.v.push_back(lv.angle[j][size_t(c)]);
        }
        vars.push_back(l);
        vars.push_back(an);
    }
    const double n_tests = double(vars.size()) * 3;
    std::vector<json> tr;
    for (auto &var : vars)
        for (int a = 0; a < 3; ++a) {
            std::vector<double> x, y, w;
            for (size_t j = 0; j < P; ++j)
                if (bE.ok[j]) {
                    x.push_back(var.v[j]);
                    y.push_back(bE.res[j](a));
                    w.push_back(1.0 / (bE.var_mean[j](a) + jig(a) * jig(a)));
                }
            Trend t = poly_trend(x, y, w, 2);
            const double padj = std::min(1.0, t.p * n_tests); // Bonferroni over every variable and axis
            if (padj < kFindingLevel)
                tr.push_back({{"variable", var.name}, {"variable_kind", var.kind}, {"cable", var.cable},
                              {"kind", "trend"}, {"axis", kAxis[a]}, {"period_mm", nullptr},
                              {"amplitude_mm", t.range}, {"p_value", padj}, {"r2", t.r2},
                              {"test", "F-test of a weighted quadratic against a constant, Bonferroni over " +
                                           fmt_num(n_tests, 0) + " variable-axis pairs"},
                              {"text", std::string(kAxis[a]) + " residual varies with " + var.name + " by " +
                                           fmt_num(t.range, 3) + " mm (R^2 " + fmt_num(t.r2, 2) + ")"}});
        }
    std::sort(tr.begin(), tr.end(), [](const json &a, const json &b) { return a["r2"] > b["r2"]; });
    for (size_t k = 0; k < std::min<size_t>(6, tr.size()); ++k) findings.push_back(tr[k]);
    return findings;
}

} // namespace diag
} // namespace cdm
