// See standins.h.
#include "calib/beyond/standins.h"
#include "model/effect.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>

#include <Eigen/Dense>

#include "calib/evaluation/findings.h"
#include "calib/evaluation/stats.h"
#include "model/evaluator.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {

std::string fmt_g(double v) {
    char b[48];
    std::snprintf(b, sizeof b, "%.3g", v);
    return b;
}

double param_se(const FitReport &rep, size_t e, size_t k) {
    if (e >= rep.std.size() || k >= rep.std[e].size()) return 0.0;
    const double s = rep.std[e][k];
    return std::isfinite(s) ? s : 0.0;
}

// Each parameter outside its declared range by more than kStandInSe
// standard errors; the effect's first such parameter speaks for it, the
// JSON lists them all.
void range_stand_ins(const Model &m, const FitReport &rep, size_t e, std::vector<StandIn> &out) {
    const EffectDesc &d = m.effect_desc(e);
    const auto &v = m.effect_params(e);
    json params = json::array();
    std::string first;
    for (size_t k = 0; k < d.params.size() && k < v.size(); ++k) {
        const ParamDesc &p = d.params[k];
        const double se = param_se(rep, e, k), margin = kStandInSe * se;
        const bool below = v[k] < p.plausible_lo - margin, above = v[k] > p.plausible_hi + margin;
        if (!below && !above) continue;
        const std::string &means = below ? p.below_means : p.above_means;
        params.push_back({{"param", p.name}, {"value", v[k]}, {"std", se}, {"unit", p.unit},
                          {"plausible", {p.plausible_lo, p.plausible_hi}}, {"means", means}});
        if (first.empty())
            first = d.name + "'s " + p.name + " = " + fmt_g(v[k]) + (p.unit == "1" ? "" : " " + p.unit) + " (+-" +
                    fmt_g(se) + ") is " + (below ? "below" : "above") + " its plausible range [" +
                    fmt_g(p.plausible_lo) + ", " + fmt_g(p.plausible_hi) + "]" + (means.empty() ? "" : ": " + means);
    }
    if (params.empty()) return;
    out.push_back({d.name, "range", first, {{"params", params},
                                            {"test", "fitted value outside the effect's declared plausible range by more "
                                                     "than " + fmt_num(kStandInSe, 0) + " standard errors"}}});
}

// The four points' displacements d (12: x, y, z per cable) in the frame's
// twelve symmetric modes: per axis, the four points together, radially in y
// (by the sign of each point's y), radially in z, and twisted (diagonal
// pairs opposite). Independent errors of each point spread over all twelve;
// a deformation, or a smooth effect the geometry is made to carry, puts
// nearly everything in a few. The statistic is the share of |d|^2 in its
// kModes strongest modes; its null distribution, for independent isotropic
// errors within the directions the gauge leaves the fit (a gauge-fixed
// direction is zero whatever the data say), is drawn by Monte Carlo with a
// fixed seed (kDraws draws: the same p on every run).
constexpr int kModes = 3, kDraws = 20000;

using Modes = Eigen::Matrix<double, 12, 12>;

Modes mode_basis(const Model &m, bool anchors) {
    Modes C = Modes::Zero();
    for (int i = 0; i < 4; ++i) {
        const auto q = anchors ? m.geometry().anchor(i) : m.geometry().holder(i);
        const double sy = q[1] >= 0 ? 1 : -1, sz = q[2] >= 0 ? 1 : -1;
        const double pat[4] = {1, sy, sz, sy * sz};
        for (int a = 0; a < 3; ++a)
            for (int k = 0; k < 4; ++k) C(3 * i + a, 4 * a + k) = 0.5 * pat[k]; // orthonormal columns
    }
    return C;
}

double top_share(const Eigen::Matrix<double, 12, 1> &energy) {
    Eigen::Matrix<double, 12, 1> e = energy;
    std::sort(e.data(), e.data() + 12, std::greater<double>());
    const double total = e.sum();
    return total > 0 ? e.head<kModes>().sum() / total : 0.0;
}

std::string mode_words(const Modes &C, const Eigen::Matrix<double, 12, 1> &x, const Eigen::Matrix<double, 12, 1> &energy) {
    static const char *kAx[3] = {"x", "y", "z"};
    std::vector<int> idx(12);
    for (int k = 0; k < 12; ++k) idx[size_t(k)] = k;
    std::sort(idx.begin(), idx.end(), [&](int a, int b) { return energy(a) > energy(b); });
    std::string w;
    for (int r = 0; r < kModes; ++r) {
        const int k = idx[size_t(r)], a = k / 4, kind = k % 4;
        const double v = 0.5 * C.col(k).dot(x); // each point's displacement in the mode
        const std::string mm = fmt_num(std::fabs(v), 3) + " mm";
        const bool radial = (kind == 1 && a == 1) || (kind == 2 && a == 2);
        const char *side = kind == 1 ? "y" : "z";
        w += std::string(r ? ", " : "") + kAx[a] + " " +
             (kind == 0   ? "all four " + fmt_num(v, 3, true) + " mm"
              : kind == 3 ? "twisted " + mm + " (diagonal pairs opposite)"
              : radial    ? mm + (v >= 0 ? " outward" : " inward")
                          : fmt_num(v, 3, true) + " mm on the +" + side + " side, " + fmt_num(-v, 3, true) +
                                " mm on the -" + side + " side");
    }
    return w;
}

void pattern_stand_in(const Model &m, const FitReport &rep, size_t e, std::vector<StandIn> &out) {
    const EffectDesc &d = m.effect_desc(e);
    const auto &v = m.effect_params(e);
    if (!d.points.present || v.size() != 12) return;
    Eigen::Matrix<double, 12, 1> x, var;
    for (int k = 0; k < 12; ++k) {
        x(k) = v[size_t(k)];
        const double se = param_se(rep, e, size_t(k));
        var(k) = se * se;
    }
    const Modes C = mode_basis(m, d.points.anchors);
    const Eigen::MatrixXd B = effect_gauge_basis(m, e);
    if (B.rows() != 12 || B.cols() < kModes + 1) return;
    Eigen::HouseholderQR<Eigen::MatrixXd> qb(B);
    const Eigen::MatrixXd Qb = qb.householderQ() * Eigen::MatrixXd::Identity(12, B.cols());
    const Eigen::Matrix<double, 12, 1> xb = Qb * (Qb.transpose() * x);
    const Eigen::Matrix<double, 12, 1> energy = (C.transpose() * xb).cwiseAbs2();
    const double share = top_share(energy);
    // The null: isotropic errors in the gauge's free directions.
    std::mt19937_64 rng(20261128);
    std::normal_distribution<double> g(0.0, 1.0);
    int above = 0;
    Eigen::VectorXd z(B.cols());
    for (int n = 0; n < kDraws; ++n) {
        for (long k = 0; k < z.size(); ++k) z(k) = g(rng);
        const Eigen::Matrix<double, 12, 1> dn = Qb * z;
        if (top_share((C.transpose() * dn).cwiseAbs2()) >= share) ++above;
    }
    const double p = (above + 1.0) / (kDraws + 1.0);
    // The strong modes' part must be beyond the fit's noise too.
    std::vector<int> idx(12);
    for (int k = 0; k < 12; ++k) idx[size_t(k)] = k;
    std::sort(idx.begin(), idx.end(), [&](int a, int b) { return energy(a) > energy(b); });
    double strong = 0, noise = 0;
    for (int r = 0; r < kModes; ++r) {
        strong += energy(idx[size_t(r)]);
        noise += C.col(idx[size_t(r)]).cwiseAbs2().dot(var);
    }
    const bool sized = noise > 0 ? strong > kStandInSe * kStandInSe * noise : strong > 0;
    if (!(p < kFindingLevel) || !sized) return;
    const std::string what = d.points.anchors ? "exit points" : "holder points";
    const std::string words =
        d.name + "'s four " + what + " move together (" + mode_words(C, xb, energy) + "): " + fmt_num(100 * share, 0) +
        " % of the displacement in " + std::to_string(kModes) + " of the frame's 12 symmetric modes, which independent "
        "errors of each point reach with " + fmt_p(p) + ": a deformation, or a stand-in for a smooth effect the model "
        "lacks, not four separate machining errors";
    json modes = json::array();
    for (int k = 0; k < 12; ++k) modes.push_back(0.5 * C.col(k).dot(xb));
    out.push_back({d.name, "pattern", words,
                   {{"modes_mm", modes},
                    {"mode_order", "per axis x, y, z: all four, radial in y, radial in z, twisted"},
                    {"share", share},
                    {"p_value", p},
                    {"test", "share of the fitted displacement (within the gauge's free directions) in its " +
                                 std::to_string(kModes) + " strongest of the frame's 12 symmetric modes, against its "
                                 "distribution for independent isotropic errors of each point (Monte Carlo, " +
                                 std::to_string(kDraws) + " draws, fixed seed); the strong modes also beyond " +
                                 fmt_num(kStandInSe, 0) + " standard errors"}}});
}

} // namespace

std::vector<StandIn> find_stand_ins(const Model &m, const FitReport &rep) {
    std::vector<StandIn> out;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (m.effect_desc(e).stage == Stage::Position) continue; // the seed's ellipsoid claims no physics
        range_stand_ins(m, rep, e, out);
        pattern_stand_in(m, rep, e, out);
    }
    return out;
}

json stand_ins_json(const std::vector<StandIn> &s) {
    json a = json::array();
    for (auto &x : s) {
        json j = x.detail;
        j["effect"] = x.effect;
        j["kind"] = x.kind;
        j["text"] = x.words;
        a.push_back(j);
    }
    return a;
}

std::string stand_ins_words(const std::vector<StandIn> &s) {
    std::string w;
    for (size_t k = 0; k < s.size(); ++k) w += (k ? "; " : "") + s[k].words;
    return w;
}

std::vector<std::string> stand_in_effects(const std::vector<StandIn> &s) {
    std::vector<std::string> names;
    for (auto &x : s)
        if (std::find(names.begin(), names.end(), x.effect) == names.end()) names.push_back(x.effect);
    return names;
}

} // namespace diag
} // namespace cdm
