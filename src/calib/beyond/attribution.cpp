// See attribution.h.
#include "calib/beyond/attribution.h"
#include "model/effect.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <boost/math/distributions/students_t.hpp>

#include "calib/evaluation/findings.h"
#include "calib/evaluation/jig.h"
#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {

const char *kAxis[3] = {"x", "y", "z"};

struct Offsets {
    std::vector<double> height, mean, se;
};

// The per-height mean x residual (the axis the spacers set) with its
// standard error, heights in index order (href: their reference x, in the
// same order).
Offsets x_offsets(const Eval &E, const Grid &G, const V3 &jig, const std::vector<double> &href) {
    Offsets o;
    size_t k = 0; // the k-th height present, as the jig's report lists them
    for (auto &kv : height_means(E, G, jig)) {
        if (kv.first.second != 0) continue;
        if (k >= href.size()) break;
        o.height.push_back(href[k++]);
        o.mean.push_back(kv.second.mean());
        o.se.push_back(kv.second.se());
    }
    return o;
}

std::string list(const std::vector<double> &v) {
    std::string s;
    for (double x : v) s += (s.empty() ? "" : ", ") + fmt_num(x, 3, true);
    return s;
}

// The offsets against a straight line in height: the slope's t against
// the offsets' own scatter about the line (K - 2 degrees of freedom), the
// scatter independent spacers would have.
json height_trend(const Offsets &o, double small, bool &flag, std::string &words) {
    const size_t K = o.mean.size();
    flag = false;
    if (K < 4) return nullptr;
    double mh = 0, mm = 0;
    for (size_t k = 0; k < K; ++k) mh += o.height[k] / double(K), mm += o.mean[k] / double(K);
    double shh = 0, shm = 0;
    for (size_t k = 0; k < K; ++k) {
        shh += (o.height[k] - mh) * (o.height[k] - mh);
        shm += (o.height[k] - mh) * (o.mean[k] - mm);
    }
    if (!(shh > 0)) return nullptr;
    const double b = shm / shh;
    double sse = 0;
    for (size_t k = 0; k < K; ++k) sse += std::pow(o.mean[k] - mm - b * (o.height[k] - mh), 2);
    const double dof = double(K) - 2;
    const double se = std::sqrt(std::max(sse / dof, 1e-30) / shh);
    const double t = b / se;
    const boost::math::students_t_distribution<double> st(dof);
    const double p = std::min(1.0, 2 * boost::math::cdf(boost::math::complement(st, std::fabs(t))));
    const double range = std::fabs(b) * (*std::max_element(o.height.begin(), o.height.end()) -
                                         *std::min_element(o.height.begin(), o.height.end()));
    flag = p < kFindingLevel && range >= small;
    if (flag)
        words = "the fixture's x offsets (" + list(o.mean) + " mm, heights in order) follow a straight line in height (" +
                fmt_num(b, 5, true) + " mm per mm of height, t = " + fmt_num(t, 1) + ", " + fmt_p(p) +
                "): spacers machined one by one do not line up so, a device effect that grows with height does; they "
                "are not taken as the jig's without doubt";
    return {{"slope_mm_per_mm", b}, {"t", t}, {"dof", dof}, {"p_value", p}, {"range_mm", range},
            {"test", "slope of the per-height x offsets on the height, t-test against their scatter about the line "
                     "(K - 2 degrees of freedom)"}};
}

json model_dependence(const Offsets &a, const Offsets &b, const std::string &other_name, double small, bool &flag,
                      std::string &words) {
    flag = false;
    if (a.mean.size() != b.mean.size() || a.mean.size() < 2) return nullptr;
    double chi2 = 0, mx = 0;
    for (size_t k = 0; k < a.mean.size(); ++k) {
        const double d = a.mean[k] - b.mean[k];
        chi2 += d * d / (a.se[k] * a.se[k] + b.se[k] * b.se[k]);
        mx = std::max(mx, std::fabs(d));
    }
    const double p = chi2_sf(chi2, double(a.mean.size()));
    flag = p < kFindingLevel && mx >= small;
    if (flag)
        words = "the fixture's x offsets change with the device model (" + list(a.mean) + " mm with the recommended "
                "model, " + list(b.mean) + " mm with " + other_name + "; " + fmt_p(p) +
                "): an error of the jig cannot depend on the model of the device, so the attribution to the spacers is "
                "ambiguous";
    return {{"offsets_mm", a.mean}, {"other_offsets_mm", b.mean}, {"other", other_name}, {"max_difference_mm", mx},
            {"chi2", chi2}, {"p_value", p},
            {"test", "per-height x offsets of the two models, chi-square of their differences over the sum of their "
                     "variances (conservative: the two share the data), K degrees of freedom"}};
}

// Axes whose hole means are smooth over the plate but were not named the
// device's by the hole test (its F-test or size did not pass).
json smooth_plate(const json &jig_report, std::string &words) {
    json out = json::array();
    const json &ho = jig_report.contains("holes") ? jig_report["holes"] : json(nullptr);
    if (!ho.is_object() || ho["named"] == "device") return out;
    for (int a = 0; a < 3; ++a) {
        if (!ho["smooth_p"].contains(kAxis[a])) continue;
        const double p = ho["smooth_p"][kAxis[a]].get<double>();
        if (!(p < kFindingLevel)) continue;
        out.push_back({{"axis", kAxis[a]}, {"smooth_p", p}, {"smooth_z", ho["smooth_z"][kAxis[a]]},
                       {"std_mm", ho["std_mm"][kAxis[a]]}});
        words += std::string(words.empty() ? "" : "; ") + kAxis[a] + " (Moran z = " +
                 fmt_num(ho["smooth_z"][kAxis[a]].get<double>(), 1) + ", " + fmt_p(p) + ", about " +
                 fmt_num(ho["std_mm"][kAxis[a]].get<double>(), 3) + " mm)";
    }
    if (!words.empty())
        words = "the residual's mean at each hole is smooth over the plate in " + words +
                ": a pattern repeating at every height that a plate's independently drilled holes do not make; look "
                "for a device effect that does not change with height";
    return out;
}

} // namespace

Attribution jig_attribution(const Eval &rec, const Eval *other, const std::string &other_name, const Grid &G,
                            const V3 &jig, const V3 &noise, const json &jig_report) {
    Attribution A;
    const double small = 0.1 * noise.norm();
    std::vector<double> href;
    if (jig_report.contains("fixture") && jig_report["fixture"].is_object())
        for (auto &h : jig_report["fixture"]["heights_mm"]) href.push_back(h.get<double>());
    std::vector<std::string> sentences;
    if (!href.empty()) {
        const Offsets o = x_offsets(rec, G, jig, href);
        bool f1 = false, f2 = false;
        std::string w1, w2;
        A.report["height_trend"] = height_trend(o, small, f1, w1);
        if (other) A.report["model_dependence"] = model_dependence(o, x_offsets(*other, G, jig, href), other_name, small, f2, w2);
        if (f2) sentences.push_back(w2);
        if (f1) sentences.push_back(w1);
        A.ambiguous = f1 || f2;
    }
    std::string w3;
    A.report["smooth_over_plate"] = smooth_plate(jig_report, w3);
    if (!w3.empty()) sentences.push_back(w3);
    A.report["ambiguous"] = A.ambiguous;
    for (size_t k = 0; k < sentences.size(); ++k) A.words += (k ? "; " : "") + sentences[k];
    A.report["text"] = A.words;
    return A;
}

} // namespace diag
} // namespace cdm
