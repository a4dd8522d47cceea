// See verdict.h.
#include "calib/diagnosis/verdict.h"

#include <cmath>
#include <cstdio>
#include <set>

#include "calib/evaluation/findings.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {

// A model with stand-ins. Where its tests pass, the numbers stand and the
// word "explains" does not: "fits to the noise floor with stand-ins".
// Where they fail, the stand-ins are named after the reasons, since its
// fitted values are then not the effects' physics either.
void apply_stand_ins(Judgement &J, const std::vector<StandIn> &si, const std::string &rms, const std::string &tests,
                     const std::vector<std::string> &negligible, double small) {
    if (!J.explained && !J.negligible_only) {
        J.words += ". Its fitted values include stand-ins: " + stand_ins_words(si);
        return;
    }
    J.with_stand_ins = true;
    J.explained = J.negligible_only = false;
    J.words = "fits to the noise floor with stand-ins, so it does not explain the data; " + rms + " (" + tests +
              "). Stand-ins: " + stand_ins_words(si);
    if (!negligible.empty()) {
        J.words += ". Also significant, but under a tenth of the noise floor (" + fmt_num(small, 4) + " mm): ";
        for (size_t k = 0; k < negligible.size() && k < 3; ++k) J.words += (k ? "; " : "") + negligible[k];
    }
}

} // namespace

Judgement judge_model(const Verdict &v, const Eval &E, const std::vector<Candidate> *cands, const json *findings,
                      const V3 &noise, double x_rms_jig_out, const std::vector<StandIn> *stand_ins) {
    Judgement J;
    const double floor3 = noise.norm();
    const double small = 0.1 * floor3; // a tenth of the noise floor (3-D)
    std::vector<std::string> material, negligible, unpaid;
    if (cands)
        for (auto &c : *cands) {
            if (!c.significant()) continue;
            const std::string what = c.name + " (Delta chi2 " + fmt_num(c.dchi2, 0) + " for " + std::to_string(c.k) +
                                     (c.k == 1 ? " parameter, " : " parameters, ") + fmt_p(c.p_adj) + " after Bonferroni over " +
                                     std::to_string(cands->size()) + "; BIC change " + fmt_num(c.bic, 0) +
                                     "; it moves positions by " + fmt_num(c.shift_rms_mm, 4) + " mm RMS)";
            J.significant.push_back({{"kind", "candidate"},
                                     {"effect", c.name},
                                     {"delta_chi2", c.dchi2},
                                     {"n_params", c.k},
                                     {"p_adjusted", c.p_adj},
                                     {"bic_change", c.bic},
                                     {"position_change_rms_mm", c.shift_rms_mm},
                                     {"negligible", c.shift_rms_mm < small}});
            (c.shift_rms_mm < small ? negligible : material).push_back(what);
            if (c.shift_rms_mm >= small && c.bic > 0) unpaid.push_back(c.name);
        }
    if (findings)
        for (auto &f : *findings) {
            const double amp = f.value("amplitude_mm", 0.0);
            const std::string what = f["text"].get<std::string>() + " (" + fmt_p(f["p_value"].get<double>()) + ")";
            J.significant.push_back({{"kind", "finding"}, {"text", f["text"]}, {"p_value", f["p_value"]},
                                     {"amplitude_mm", amp}, {"negligible", amp < small}});
            (amp < small ? negligible : material).push_back(what);
        }
    const double xr = E.err[0].n > 0 ? std::sqrt(E.err[0].ss / E.err[0].n) : 0.0;
    // The tests judge the residual with the jig's fixture offsets out: a
    // jig that sits off in x makes the raw RMS larger than what they see.
    const bool jig_out = std::isfinite(x_rms_jig_out) && fmt_num(x_rms_jig_out, 3) != fmt_num(xr, 3);
    const std::string rms = "x RMS " + fmt_num(xr, 3) + " mm" +
                            (jig_out ? " (" + fmt_num(x_rms_jig_out, 3) + " mm with the fixture's per-height offsets out)"
                                     : std::string()) +
                            " at the noise floor " + fmt_num(noise(0), 3) + " mm";
    // With the plate's holes shared by every height the tests are widened
    // for it (judge()), and the text says so beside the numbers.
    const bool widened = v.widened();
    const std::string tests = "chi2/dof " + fmt_num(v.chi2 / v.dof, 2) + " (" + fmt_p(v.chi2_p) +
                              "), spatial structure z = " + fmt_num(v.moran_z, 1) + " (" + fmt_p(v.moran_p) + ")" +
                              (widened ? "; both tests widened for the plate's hole errors, which repeat at every "
                                         "height (chi-square scale " + fmt_num(v.chi2_scale, 2) +
                                             ", structure variance x" + fmt_num(v.moran_scale, 2) + ")"
                                       : "");
    J.explained = v.explained && material.empty() && negligible.empty();
    J.negligible_only = v.explained && material.empty() && !negligible.empty();
    if (J.explained) {
        J.words = "explains the data; " + rms + " (" + tests + (cands ? "; no candidate significant" : "") +
                  (findings ? "; no residual finding" : "") + ")";
    } else if (J.negligible_only) {
        J.words = "explains the data to within what matters; " + rms + " (" + tests +
                  "). Statistically significant but under a tenth of the noise floor (" + fmt_num(small, 4) +
                  " mm): ";
        for (size_t k = 0; k < negligible.size(); ++k) J.words += (k ? "; " : "") + negligible[k];
    } else {
        J.words = "does not explain the data; " + rms + " (" + tests + ")";
        if (!material.empty()) {
            J.words += ". Still significant: ";
            // The strongest three in words; the JSON lists every one.
            for (size_t k = 0; k < material.size() && k < 3; ++k) J.words += (k ? "; " : "") + material[k];
            if (material.size() > 3) J.words += "; and " + std::to_string(material.size() - 3) + " more (significant_left)";
            // A likelihood ratio the test calls significant with a BIC change
            // above zero: the criterion asks more of its parameters than the
            // test does (its penalty grows with the log of the readings), so
            // the search leaves it out, and the reader must know why.
            if (!unpaid.empty()) {
                std::string names;
                for (size_t k = 0; k < unpaid.size(); ++k) names += (k ? ", " : "") + unpaid[k];
                J.words += ". The search leaves " + names + " out: " + (unpaid.size() == 1 ? "its" : "their") +
                           " likelihood ratio is significant, but the BIC, whose penalty per parameter grows with the "
                           "number of readings, does not pay for " + (unpaid.size() == 1 ? "its" : "their") +
                           " parameters; add " + (unpaid.size() == 1 ? "it" : "them") +
                           " (--effects) if the physics makes it plausible, and compare";
            }
        } else if (!v.explained) {
            J.words += ": the residual is larger or more structured than the noise and the jig's tolerance allow";
        }
        // What is significant but small is named too: not a reason for the
        // verdict, yet a number on the same page (the candidate table) that
        // a reader would otherwise find unexplained.
        if (!negligible.empty()) {
            J.words += ". Also significant, but under a tenth of the noise floor (" + fmt_num(small, 4) + " mm): ";
            for (size_t k = 0; k < negligible.size() && k < 3; ++k) J.words += (k ? "; " : "") + negligible[k];
            if (negligible.size() > 3) J.words += "; and " + std::to_string(negligible.size() - 3) + " more";
        }
    }
    if (stand_ins && !stand_ins->empty()) apply_stand_ins(J, *stand_ins, rms, tests, negligible, small);
    return J;
}

std::string glitches_words(const Dataset &d) {
    if (d.glitches.empty()) return "";
    std::set<long> points;
    const DatasetGlitch *worst = &d.glitches[0];
    double lo = INFINITY;
    int per_cable[4] = {0, 0, 0, 0};
    for (auto &g : d.glitches) {
        points.insert(g.point);
        lo = std::min(lo, g.z);
        if (g.z > worst->z) worst = &g;
        ++per_cable[g.cable - 1];
    }
    std::string cables;
    for (int c = 0; c < 4; ++c)
        if (per_cable[c]) cables += (cables.empty() ? "" : ", ") + std::to_string(per_cable[c]) + " on cable " + std::to_string(c + 1);
    const bool one = d.glitches.size() == 1;
    const std::string off = one ? fmt_num(worst->z, 0) : fmt_num(lo, 0) + " to " + fmt_num(worst->z, 0);
    return "The data as read: " + std::to_string(d.glitches.size()) + " of " + std::to_string(d.rows) +
           (one ? " samples was set aside as a glitch (" : " samples, at " + std::to_string(points.size()) +
                                                          (points.size() == 1 ? " position" : " positions") +
                                                          ", were set aside as glitches (") +
           cables + "): one reading off its position's median by " + off +
           " times the noise (the threshold: " + fmt_num(d.glitch_z, 1) +
           ", where clean Gaussian data loses one reading in a hundred datasets); " + (one ? "it is " : "the largest, ") +
           fmt_num(std::fabs(worst->reading - worst->median), 2) + " mm on cable " + std::to_string(worst->cable) +
           " at line " + std::to_string(worst->line) + " (point " + std::to_string(worst->point) +
           "). Spikes like these come from a wiper or a connector: check the pots' wiring. The statistics above are "
           "without " + (one ? "it." : "them.");
}

std::string outliers_words(const nlohmann::json &set_aside, size_t read) {
    double lo = INFINITY, hi = 0, nb = 0;
    std::string points;
    for (size_t k = 0; k < set_aside.size(); ++k) {
        const auto &o = set_aside[k];
        double r = 0, n = 0;
        for (int a = 0; a < 3; ++a) {
            r += o["residual_mm"][size_t(a)].get<double>() * o["residual_mm"][size_t(a)].get<double>();
            n += o["neighbours_mm"][size_t(a)].get<double>() * o["neighbours_mm"][size_t(a)].get<double>();
        }
        lo = std::min(lo, std::sqrt(r));
        hi = std::max(hi, std::sqrt(r));
        nb = std::max(nb, std::sqrt(n));
        if (k < 8) points += (k ? ", " : "") + std::to_string(o["point"].get<long>());
    }
    if (set_aside.size() > 8) points += ", ...";
    const bool one = set_aside.size() == 1;
    return "Set aside as " + std::string(one ? "an outlier" : "outliers") + ": " + std::to_string(set_aside.size()) +
           " of " + std::to_string(read) + " positions (point" + (one ? " " : "s ") + points + "), off by " +
           (one ? fmt_num(hi, 3) : fmt_num(lo, 3) + " to " + fmt_num(hi, 3)) +
           " mm where the mean of their neighbours is within " + fmt_num(nb, 3) +
           " mm of the model (each beyond the 1 % family-wise chi-square against the noise and the jig, and against its "
           "neighbours): a mis-seated probe, a wrong hole or a bump during the samples, not the device; re-measure " +
           (one ? "it" : "them") + ". The statistics above are without " + (one ? "it" : "them") + ".";
}

std::string fit_check_words(const Verdict &v) {
    if (v.explained)
        return "the fitted effects explain the data to the noise and the jig's tolerance (no other effect tried: "
               "`cdm calib diagnose` does)";
    return "the fitted effects do not explain the data: chi2/dof " + fmt_num(v.chi2 / v.dof, 2) + " (" +
           fmt_p(v.chi2_p) +
           (v.chi2_widened() ? ", widened x" + fmt_num(v.chi2_scale, 2) + " for the plate's holes" : "") +
           "), spatial structure z = " + fmt_num(v.moran_z, 1) + " (" + fmt_p(v.moran_p) +
           "); the calibration corrects only what they can: `cdm calib diagnose` says what is missing";
}

} // namespace diag
} // namespace cdm

