// See stages.h: the verdict's sentences, from the stages' results.
#include <algorithm>
#include <cctype>
#include <cmath>

#include "calib/diagnosis/diagnose_json.h"
#include "calib/diagnosis/stages.h"

namespace cdm {
namespace diag {

namespace {

// With the search: the recommended model's verdict, its path, the models
// the data cannot tell it from, and the user's model's own.
void search_words(const UserModel &u, const SearchStage &s, Words &w) {
    const SearchResult &sr = s.sr;
    const Judgement &jr = w.jr, &jm = w.jm;
    w.verdict = "Recommended model: " + join(sr.effects, " + ", "the nominal model") + ": " + jr.words + ".";
    if (jr.explained || jr.negligible_only) w.verdict += effect_advice(sr.model, sr.rep, u.cf.pos);
    if (!sr.path.empty()) {
        w.verdict += " Search from " + join(reading_effects(u.cf.model), " + ", "the nominal model") + ":";
        for (auto &st : sr.path)
            w.verdict += (st.added.empty()     ? " - " + st.removed
                          : st.removed.empty() ? " + " + st.added
                                               : " " + st.removed + " -> " + st.added) +
                         " (BIC " + fmt_num(st.bic_change, 0) + ")";
        w.verdict += ".";
    }
    if (!s.alts.empty()) {
        w.verdict += " The data cannot tell it from:";
        for (size_t k = 0; k < s.alts.size() && k < 4; ++k)
            w.verdict += std::string(k ? ";" : "") + " " + join(s.alts[k].first, " + ", "the nominal model") +
                         " (BIC " + (s.alts[k].second >= 0 ? "+" : "") + fmt_num(s.alts[k].second, 0) + ")";
        w.verdict += ".";
    }
    if (sr.effects != reading_effects(u.cf.model)) w.verdict += " Your model, " + w.modelname + ": " + jm.words + ".";
    w.unexplained_summary = jr.explained ? "nothing left to explain"
                            : jr.negligible_only ? "only effects under a tenth of the noise floor are left"
                            : jr.with_stand_ins ? "the recommended model reaches the noise floor only with stand-ins"
                                                 : "the recommended model leaves significant structure";
}

// Without the search: the user's model's verdict and the best candidate.
void user_words(const DiagnoseOptions &opt, const std::vector<Candidate> &cands, Words &w) {
    const Judgement &jm = w.jm;
    const Candidate *top = cands.empty() ? nullptr : &cands[0];
    w.verdict = w.modelname + " " + jm.words + ".";
    if (!jm.explained && !jm.negligible_only && top && top->bic < 0 && top->significant()) {
        w.verdict += " The best candidate is " + top->name + " (BIC " + fmt_num(top->bic, 0) +
                     "); with it the x RMS is " +
                     fmt_num(top->E.err[0].n > 0 ? std::sqrt(top->E.err[0].ss / top->E.err[0].n) : 0, 3) + " mm";
        if (!top->confused.empty()) w.verdict += "; the data cannot tell it from " + join(top->confused, ", ", "");
        w.verdict += ". Add it with --effects and diagnose again.";
    }
    if (!opt.candidates)
        w.verdict += " The catalogue was not tried (--no-candidates): nothing is said about which effect could be "
                     "missing.";
    w.unexplained_summary = jm.explained ? "nothing left to explain"
                            : !opt.candidates ? "the catalogue was not tried"
                                              : "see the candidates and the findings";
}

// After the verdict: the review, the jig as it is, beyond the catalogue,
// the glitches, and the findings in the summary.
void after_words(const Dataset &data, const nlohmann::json &review, const Residuals &r, Words &w) {
    for (auto &rv : review) {
        if (rv.contains("better_swap"))
            w.verdict += " Review: replacing " + rv["effect"].get<std::string>() + " with " +
                         rv["better_swap"]["effect"].get<std::string>() + " explains the data better (BIC " +
                         fmt_num(rv["better_swap"]["bic_change"].get<double>(), 0) + ").";
        else if (rv["redundant"].get<bool>())
            w.verdict += " Review: " + rv["effect"].get<std::string>() +
                         " no longer earns its parameters (removing it changes BIC by " +
                         fmt_num(rv["bic_change_if_removed"].get<double>(), 0) + "): drop it.";
    }
    // What the jig's own errors are, after the verdict: they are not the
    // device's, and the tests above have taken them out.
    const nlohmann::json &jig_report = r.ja.report;
    if (!jig_report["text"].empty()) {
        w.verdict += " The jig as it is:";
        for (auto &t : jig_report["text"]) {
            std::string sentence = t.get<std::string>();
            if (!sentence.empty()) sentence[0] = char(std::toupper(static_cast<unsigned char>(sentence[0])));
            w.verdict += " " + sentence + ".";
        }
    }
    if (r.bey.discovery.competitive())
        w.verdict += " Beyond the catalogue: " + r.bey.discovery.words + ".";
    else if (r.bey.discovery.found && !r.bey.recommended.empty())
        w.verdict += " Beyond the catalogue: " + r.bey.discovery.lead_words + ".";
    if (!r.bey.attribution.words.empty()) w.verdict += " The jig's errors in doubt: " + r.bey.attribution.words + ".";
    // What the screen set aside as it read the file (calib/dataset/glitches.h).
    if (!data.glitches.empty()) w.verdict += " " + glitches_words(data);
    if (!r.findings.empty()) {
        w.unexplained_summary += "; found: ";
        for (size_t k = 0; k < std::min<size_t>(3, r.findings.size()); ++k)
            w.unexplained_summary += (k ? "; " : "") + r.findings[k]["text"].get<std::string>();
    }
}

} // namespace

Words verdict_words(const Dataset &data, const DiagnoseOptions &opt, const UserModel &u,
                    const std::vector<Candidate> &cands, const SearchStage &s, const nlohmann::json &review,
                    const Residuals &r) {
    const CalibrationFit &cf = u.cf;
    const Model &model = cf.model;
    Words w;
    w.modelname = "the nominal model";
    if (model.effect_count()) w.modelname = "the model with " + join([&] {
        std::vector<std::string> v;
        for (size_t k = 0; k < model.effect_count(); ++k) v.push_back(model.effect_name(k));
        return v;
    }(), ", ", "");
    // The user's model: its own tests, the candidates on top of it, and the
    // findings when they are about it.
    const bool findings_on_model = !s.on ? !r.use_top : s.sr.effects == reading_effects(model);
    w.jm = judge_model(u.v, cf.fitted, opt.candidates ? &cands : nullptr, findings_on_model ? &r.findings : nullptr,
                       u.noise, x_rms_without_fixture(cf.fitted, cf.grid, cf.jig, cf.pos), &r.bey.user);
    if (s.on) {
        w.vr = judge(s.sr.E, cf.grid, s.sctx.jig, s.sr.rep.n_free, s.sctx.fo.hole_sigma);
        w.jr = judge_model(w.vr, s.sr.E, &s.sr.cands, &r.findings, noise_floor(s.sr.E, s.sctx.jig),
                           x_rms_without_fixture(s.sr.E, cf.grid, s.sctx.jig, cf.pos), &r.bey.recommended);
        search_words(u, s, w);
    } else {
        user_words(opt, cands, w);
    }
    after_words(data, review, r, w);
    return w;
}

} // namespace diag
} // namespace cdm
