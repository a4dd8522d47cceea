// See diagnose.h. diagnose() orchestrates the stages, each in its own file:
// fit_calibration (the user's model fitted), diag_candidates (what is
// missing), diag_search (the recommended model), diag_review (is each effect
// earning its parameters), diag_validation (held-out heights),
// diag_findings (beyond the catalogue), diag_verdict (the rule that ties
// them); this file writes the JSON of docs/calibration.md (its pieces and
// the advice's words in diagnose_json).
#include "calib/diagnosis/diagnose.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <functional>
#include <future>

#include "calib/beyond/beyond.h"
#include "calib/search/candidates.h"
#include "calib/search/context.h"
#include "calib/evaluation/findings.h"
#include "calib/evaluation/jig.h"
#include "calib/search/review.h"
#include "calib/search/search.h"
#include "calib/search/validation.h"
#include "calib/diagnosis/verdict.h"
#include "calib/diagnosis/diagnose_json.h"
#include "calib/diagnosis/panels.h"
#include "calib/calibration/fit_calibration.h"
#include "calib/calibration/fit_outliers.h"
#include "cdm/cdm.h"
#include "io/device_json.h"
#include "model/effect.h"

namespace cdm {

namespace {

using nlohmann::json;
using namespace diag;
const char *kAxis[3] = {"x", "y", "z"};

} // namespace

// ============================================================== diagnose

// One round of the diagnosis on `data`; `outliers`: the positions the
// model and their neighbours both disown (find_outliers), for diagnose() to
// set aside.
static bool diagnose_data(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, json &out,
                          Model &fitted, std::string &err, size_t already, size_t read,
                          std::vector<Outlier> &outliers, Declined &declined,
                          std::optional<ReadingNoise> &reading_retry) {
    reading_retry.reset();
    auto t0 = std::chrono::steady_clock::now();
    FitCalibrationOptions fopt;
    fopt.effects = opt.effects;
    fopt.jig_tolerance_mm = opt.jig_tolerance_mm;
    fopt.reading_noise = opt.reading_noise;
    fopt.progress = opt.progress;
    fopt.fitted_maxima = false; // one pass over the rows below serves every evaluation
    fopt.threads = opt.threads;
    // The nominal triangulation's pass over the rows runs on beside the
    // candidates and the search (it fills the cores' gaps between a batch's
    // fits): waited for at the pass at the end, which needs its ellipsoid.
    // Declared in this order so that, on any way out, the pass ends before
    // what it writes goes.
    std::string nominal_err;
    CalibrationFit cf(g);
    std::future<bool> nominal_pending;
    fopt.nominal_pending = &nominal_pending;
    fopt.nominal_err = &nominal_err;
    if (!fit_calibration(data, g, fopt, cf, err)) return false;
    const auto &pos = cf.pos;
    const size_t P = pos.size();
    Model &model = cf.model;
    FitReport &rep = cf.report;
    const V3 jig = cf.jig;
    const Eval &nom = cf.nominal; // once nominal_pending is done
    Ellipsoid ell;
    Eval ellE; // the seed's procedure with its ellipsoid: in the pass over the rows below
    Eval &cur = cf.fitted;
    const bool user_jig = opt.jig_tolerance_mm >= 0;
    // Candidates' own jig tolerance is capped as in fit_calibration().
    const bool repeats = std::any_of(pos.begin(), pos.end(), [](const PreparedPos &p) { return p.n > 1; });
    DiagContext ctx{data, g, pos, cf.grid, jig, user_jig, repeats ? 0.05 : INFINITY, cf.fit_options,
                    4.0 * double(P), opt.progress};
    ctx.threads = opt.threads > 0 ? opt.threads : usable_cores();
    remember_evaluation(ctx, model, cur); // fit_calibration's evaluate(model, pos), as yet untouched
    int model_free = rep.n_free;
    for (size_t k = 0; k < model.effect_count(); ++k)
        if (model.effect_desc(k).stage == Stage::Position) model_free -= int(model.effect_desc(k).params.size());
    const Verdict vcur = judge(cur, cf.grid, jig, rep.n_free, cf.fit_options.hole_sigma);
    // The fitted model's reading-space chi-square, the reference every
    // candidate and every review refit is compared with.
    const double chi2_cur = model_chi2(model, pos, cf.fit_options);
    const V3 noise = noise_floor(cur, jig);

    // --- candidates on top of the user's model
    // Their fits, and the review's, weighed as the user's model weighs the
    // data, as chi2_cur is (diag_search.cpp says why).
    DiagContext uc = ctx;
    uc.fo.weigh_with = &model;
    std::vector<Candidate> cands;
    if (opt.candidates) {
        if (!score_candidates(uc, model, model_free, chi2_cur, cur, "candidates", cands, err)) return false;
        mark_confusions(cur, jig, cands);
    }

    // --- the model search
    SearchResult sr(g);
    std::vector<std::pair<std::vector<std::string>, double>> alts;
    const bool search = opt.search && opt.candidates;
    DiagContext sctx = ctx; // the search's noise model, re-estimated below
    int rounds = 0; // noise-model re-estimations (below)
    // Whether the search goes on from a model with E under the noise model
    // re-estimated from E (below): its estimate (j2, h2) differs by more
    // than 5 %.
    auto new_noise = [&](const Eval &E, V3 &j2, V3 &h2) {
        if (user_jig || rounds >= 3) return false;
        j2 = sctx.own_jig(E);
        h2 = sctx.own_hole(E, j2);
        const auto tol = 0.05 * sctx.jig.array().abs().max(1e-6);
        return !((j2 - sctx.jig).array().abs() <= tol).all() ||
               !((h2 - sctx.fo.hole_sigma).array().abs() <= tol).all();
    };
    const std::function<bool(const Eval &)> renoise = [&](const Eval &E) {
        V3 j2, h2;
        return new_noise(E, j2, h2);
    };
    if (search) {
        if (!model_search(sctx, model, rep, false, sr, err, nullptr, renoise)) return false;
        // The search's steps appended to sr's path; the sets it fitted
        // replace sr's, or join them when fitted under the same noise model
        // (their BICs compare: the alternatives read them).
        auto take = [&](SearchResult &next, bool same_noise) {
            for (auto &st : next.path) {
                st.step += int(sr.path.size());
                sr.path.push_back(st);
            }
            next.path = sr.path;
            if (same_noise) next.visited.insert(next.visited.begin(), sr.visited.begin(), sr.visited.end());
            sr = std::move(next);
        };
        // The jig tolerance was estimated from the user's model's residual;
        // a model far from the data biases that estimate (its smooth error
        // leaks into the white scatter), and with it every chi-square. When
        // the recommended model's own estimate differs by more than 5 %,
        // the search goes on from there with that noise model, until the
        // estimate settles (at most three re-estimations). Once it has
        // settled, the search goes on with the one-effect swaps (its first
        // step's fits are the cache's: the same start, the same noise
        // model); a swap that moves the model sends its estimate to the
        // same check.
        // Bounded: three re-estimations, and a swap search after each
        // and after the first search, at most. A search that ended
        // provisionally (model_search's `restarts`) is searched again: under
        // the new noise model, or by the swap search, or after the loop.
        for (int pass = 0; pass < 4 + 3; ++pass) {
            V3 j2, h2;
            if (new_noise(sr.E, j2, h2)) {
                ++rounds;
                sctx.jig = j2;
                set_jig_noise(sctx.fo, j2, h2);
                Model start = sr.model;
                FitReport r0;
                if (!sctx.fit(start, "search (noise model re-estimated)", r0)) {
                    err = r0.message.empty() ? "fit cancelled" : r0.message;
                    return false;
                }
                SearchResult next(g);
                if (!model_search(sctx, start, r0, false, next, err, nullptr, renoise)) return false;
                take(next, false);
                continue;
            }
            SearchResult next(g);
            if (!model_search(sctx, sr.model, sr.rep, true, next, err, &sr.seen)) return false;
            const bool moved = !next.path.empty();
            take(next, true);
            if (!moved || user_jig || rounds >= 3) break;
        }
        if (sr.provisional) { // the passes ran out on a provisional end: searched once more, in full
            SearchResult next(g);
            if (!model_search(sctx, sr.model, sr.rep, true, next, err, &sr.seen)) return false;
            take(next, true);
        }
        // The table shown is of full fits (not the screen's estimates).
        if (sr.provisional || std::any_of(sr.cands.begin(), sr.cands.end(), [](const Candidate &c) { return c.screened; })) {
            err = "internal error: the search's last candidates are the screen's, not full fits";
            return false;
        }
        {
            DiagContext rc = sctx; // as the search's last step weighed them
            rc.fo.weigh_with = &sr.model;
            complete_candidates(rc, sr.model, sr.E, sr.cands);
        }
        mark_confusions(sr.E, sctx.jig, sr.cands);
        if (!search_alternatives(sctx, sr, alts, err)) return false;
    }

    // --- model review
    json review = json::array();
    if (!review_model(uc, model, model_free, chi2_cur, review, err, opt.candidates ? &cands : nullptr)) return false;

    // --- leave-one-height-out validation
    json validation = nullptr;
    if (opt.validation && rep.n_free > 0 && !validate_heights(ctx, model, cur, validation, err)) return false;

    // --- beyond the catalogue: what is left after the best catalogued
    // explanation (the recommended model; without the search, the user's
    // model, or the top candidate on top of it when neither explains the
    // data), against physical variables
    ctx.report("residual analysis", 0.0);
    const bool use_top = !search && !vcur.explained && !cands.empty() && cands[0].bic < 0 && !cands[0].v.explained;
    const Model &basis = search ? sr.model : use_top ? cands[0].m : model;
    const Eval &bE = search ? sr.E : use_top ? cands[0].E : cur;
    const LengthView lv = length_view(basis, pos);
    // The jig's own errors first (diag_jig.h): the fixture's per-height
    // offsets leave the residual before the trends are looked for, and a
    // repeat at every hole is named as the plate's or the device's.
    const V3 bjig = search ? sctx.jig : jig;
    FixtureLR flr;
    {
        FitOptions bfo = search ? sctx.fo : use_top ? uc.fo : ctx.fo;
        bfo.progress = [&](double f) { return ctx.report("residual analysis", f); };
        bfo.threads = ctx.threads; // (its two fits run alone)
        if (!fixture_lr(basis, pos, bfo, flr, err)) return false;
    }
    JigAnalysis ja = jig_analysis(bE, cf.grid, pos, bjig, noise_floor(bE, bjig), &flr);
    json &jig_report = ja.report;
    Eval bJ = bE;
    for (size_t j = 0; j < P; ++j) bJ.res[j] -= ja.offset[j];
    json findings = residual_findings(pos, shifted(lv, ja.offset), bJ, bjig, lv);
    if (opt.outliers) outliers = find_outliers(bJ, cf.grid, bjig, already, read, &declined);
    if (!jig_report["finding"].is_null()) findings.push_back(jig_report["finding"]);
    // Stand-ins, the term the catalogue lacks, the jig's errors in doubt.
    Beyond bey;
    {
        const FitReport &brep = search ? sr.rep : use_top ? cands[0].rep : rep;
        const Verdict vb = judge(bE, cf.grid, bjig, brep.n_free, search ? sctx.fo.hole_sigma : cf.fit_options.hole_sigma);
        if (!beyond_catalogue(search ? sctx : ctx, model, rep, basis, brep, bE, vb.explained && findings.empty(),
                              jig_report, noise_floor(bE, bjig), bey, err))
            return false;
    }

    // --- what needs every sample: the maxima of the reported evaluations and
    // the seed's ellipsoid applied to each sample, in one pass over the rows
    {
        std::vector<Eval *> linear{&cur};
        for (auto &c : cands) linear.push_back(&c.E);
        if (search) {
            linear.push_back(&sr.E);
            for (auto &c : sr.cands) linear.push_back(&c.E);
        }
        ctx.report("per-sample statistics", 0.0);
        if (nominal_pending.valid() && !nominal_pending.get()) {
            err = nominal_err;
            return false;
        }
        ell = ellipsoid_on(nom, pos);
        if (!sample_pass(data, pos, linear, {{&g, &ell, &ellE}}, err, ctx.threads > 1)) return false;
    }

    // --- verdict
    std::string modelname = "the nominal model";
    if (model.effect_count()) modelname = "the model with " + join([&] {
        std::vector<std::string> v;
        for (size_t k = 0; k < model.effect_count(); ++k) v.push_back(model.effect_name(k));
        return v;
    }(), ", ", "");
    // The user's model: its own tests, the candidates on top of it, and the
    // findings when they are about it.
    const bool findings_on_model = !search ? !use_top : sr.effects == reading_effects(model);
    const Judgement jm = judge_model(vcur, cur, opt.candidates ? &cands : nullptr,
                                     findings_on_model ? &findings : nullptr, noise,
                                     x_rms_without_fixture(cur, cf.grid, jig, pos), &bey.user);
    std::string verdict, unexplained_summary;
    json recommended = nullptr;
    if (search) {
        const Verdict vr = judge(sr.E, cf.grid, sctx.jig, sr.rep.n_free, sctx.fo.hole_sigma);
        const Judgement jr = judge_model(vr, sr.E, &sr.cands, &findings, noise_floor(sr.E, sctx.jig),
                                         x_rms_without_fixture(sr.E, cf.grid, sctx.jig, pos), &bey.recommended);
        json path = json::array(), alternatives = json::array();
        for (auto &st : sr.path) {
            json s = {{"step", st.step}, {"bic_change", st.bic_change}, {"x_rms_mm", st.x_rms_mm}};
            if (!st.added.empty()) s["added"] = st.added;
            if (!st.removed.empty()) s["removed"] = st.removed;
            path.push_back(s);
        }
        for (auto &a : alts) alternatives.push_back(a.first);
        json alt_bic = json::array();
        for (auto &a : alts) alt_bic.push_back(a.second);
        recommended = {{"effects", sr.effects},
                       {"bic", sr.bic},
                       {"error_mm", stats3(sr.E.err)},
                       {"explained", jr.explained},
                       {"negligible_only", jr.negligible_only},
                       {"fits_with_stand_ins", jr.with_stand_ins},
                       {"stand_ins", stand_ins_json(bey.recommended)},
                       {"chi2_per_dof", vr.chi2 / vr.dof},
                       {"noise_floor_mm", vec3(noise_floor(sr.E, sctx.jig))},
                       {"jig_tolerance_mm", vec3(sctx.jig)},
                       {"chi2_p_value", vr.chi2_p},
                       {"chi2_scale", vr.chi2_scale},
                       {"structure", {{"statistic", vr.moran_z}, {"p_value", vr.moran_p}, {"variance_scale", vr.moran_scale}}},
                       {"plate_holes_mm", vec3(sctx.fo.hole_sigma)},
                       {"significant_left", jr.significant},
                       {"alternatives", alternatives},
                       {"alternatives_bic_change", alt_bic},
                       {"params", params_json(sr.model, sr.rep)},
                       {"candidates", candidates_json(sr.cands)},
                       {"path", path},
                       {"criterion", "BIC on the reading-space chi-square (k ln n, n = 4 readings per position); an "
                                     "addition must also pass the likelihood-ratio test at 1e-3, Bonferroni over "
                                     "the candidates tried; alternatives within 10 (very strong evidence on "
                                     "Kass-Raftery's scale is needed to prefer one)"}};
        verdict = "Recommended model: " + join(sr.effects, " + ", "the nominal model") + ": " + jr.words + ".";
        if (jr.explained || jr.negligible_only) verdict += effect_advice(sr.model, sr.rep, pos);
        if (!sr.path.empty()) {
            verdict += " Search from " + join(reading_effects(model), " + ", "the nominal model") + ":";
            for (auto &st : sr.path)
                verdict += (st.added.empty()     ? " - " + st.removed
                            : st.removed.empty() ? " + " + st.added
                                                 : " " + st.removed + " -> " + st.added) +
                           " (BIC " + fmt_num(st.bic_change, 0) + ")";
            verdict += ".";
        }
        if (!alts.empty()) {
            verdict += " The data cannot tell it from:";
            for (size_t k = 0; k < alts.size() && k < 4; ++k)
                verdict += std::string(k ? ";" : "") + " " + join(alts[k].first, " + ", "the nominal model") +
                           " (BIC " + (alts[k].second >= 0 ? "+" : "") + fmt_num(alts[k].second, 0) + ")";
            verdict += ".";
        }
        if (sr.effects != reading_effects(model)) verdict += " Your model, " + modelname + ": " + jm.words + ".";
        unexplained_summary = jr.explained ? "nothing left to explain"
                              : jr.negligible_only ? "only effects under a tenth of the noise floor are left"
                              : jr.with_stand_ins ? "the recommended model reaches the noise floor only with stand-ins"
                                                   : "the recommended model leaves significant structure";
    } else {
        const Candidate *top = cands.empty() ? nullptr : &cands[0];
        verdict = modelname + " " + jm.words + ".";
        if (!jm.explained && !jm.negligible_only && top && top->bic < 0 && top->significant()) {
            verdict += " The best candidate is " + top->name + " (BIC " + fmt_num(top->bic, 0) + "); with it the x RMS is " +
                       fmt_num(top->E.err[0].n > 0 ? std::sqrt(top->E.err[0].ss / top->E.err[0].n) : 0, 3) + " mm";
            if (!top->confused.empty()) verdict += "; the data cannot tell it from " + join(top->confused, ", ", "");
            verdict += ". Add it with --effects and diagnose again.";
        }
        if (!opt.candidates)
            verdict += " The catalogue was not tried (--no-candidates): nothing is said about which effect could be "
                       "missing.";
        unexplained_summary = jm.explained ? "nothing left to explain"
                              : !opt.candidates ? "the catalogue was not tried"
                                                : "see the candidates and the findings";
    }
    for (auto &r : review) {
        if (r.contains("better_swap"))
            verdict += " Review: replacing " + r["effect"].get<std::string>() + " with " +
                       r["better_swap"]["effect"].get<std::string>() + " explains the data better (BIC " +
                       fmt_num(r["better_swap"]["bic_change"].get<double>(), 0) + ").";
        else if (r["redundant"].get<bool>())
            verdict += " Review: " + r["effect"].get<std::string>() +
                       " no longer earns its parameters (removing it changes BIC by " +
                       fmt_num(r["bic_change_if_removed"].get<double>(), 0) + "): drop it.";
    }
    // What the jig's own errors are, after the verdict: they are not the
    // device's, and the tests above have taken them out.
    if (!jig_report["text"].empty()) {
        verdict += " The jig as it is:";
        for (auto &t : jig_report["text"]) {
            std::string sentence = t.get<std::string>();
            if (!sentence.empty()) sentence[0] = char(std::toupper(static_cast<unsigned char>(sentence[0])));
            verdict += " " + sentence + ".";
        }
    }
    if (bey.discovery.competitive())
        verdict += " Beyond the catalogue: " + bey.discovery.words + ".";
    else if (bey.discovery.found && !bey.recommended.empty())
        verdict += " Beyond the catalogue: " + bey.discovery.lead_words + ".";
    if (!bey.attribution.words.empty()) verdict += " The jig's errors in doubt: " + bey.attribution.words + ".";
    // What the screen set aside as it read the file (dataset_glitches.h).
    if (!data.glitches.empty()) verdict += " " + glitches_words(data);
    if (!findings.empty()) {
        unexplained_summary += "; found: ";
        for (size_t k = 0; k < std::min<size_t>(3, findings.size()); ++k)
            unexplained_summary += (k ? "; " : "") + findings[k]["text"].get<std::string>();
    }

// --- JSON
    out = json::object();
    out["tool"] = "cdm calib diagnose";
    // The header's version, not cdm_version(): calib sits below the API layer.
    out["version"] = std::to_string(CDM_VERSION_MAJOR) + "." + std::to_string(CDM_VERSION_MINOR) + "." +
                     std::to_string(CDM_VERSION_PATCH);
    out["data"] = {{"path", data.path},
                   {"rows", data.rows},
                   {"positions", P},
                   {"heights", data.heights},
                   // points whose x_ref no other position shares, grouped with the nearest height
                   {"off_height_points", data.off_height_points},
                   {"ignored_columns", data.ignored_columns},
                   {"out_of_workspace_samples", nom.bad_samples},
                   {"samples_used", [&] {
                        size_t n = 0;
                        for (auto &p : data.pos) n += size_t(p.n);
                        return n;
                    }()},
                   {"glitches", glitches_json(data)}};
    out["device"] = io::device_to_json(g);
    json mlist = json::array();
    for (size_t k = 0; k < model.effect_count(); ++k) mlist.push_back(model.effect_name(k));
    json params = params_json(model, rep);
    out["model"] = mlist;
    out["params"] = params;
    out["fit"] = {{"algorithm", rep.algorithm}, {"evaluations", rep.evals}, {"seconds", rep.seconds},
                  {"converged", rep.converged}, {"free_parameters", rep.n_free}, {"message", rep.message},
                  {"fixture_x_mm", rep.fixture_mm}, {"restarted_from", cf.restarted_from}};
    out["error_mm"] = stats3(cur.err);
    out["nominal_error_mm"] = stats3(nom.err);
    out["ellipsoid_error_mm"] = stats3(ellE.err);
    out["ellipsoid"] = {{"L", ell.L}, {"M", ell.M}, {"N", ell.N}};
    {
        json nf;
        for (int a = 0; a < 3; ++a)
            nf[kAxis[a]] = {{"mean", 0.0}, {"std", noise(a)}, {"rms", noise(a)}, {"max", cur.within[a].mx}};
        out["noise_floor_mm"] = nf;
    }
    out["jig_tolerance_mm"] = {{"value", std::sqrt(0.5 * (jig(1) * jig(1) + jig(2) * jig(2)))},
                               {"per_axis", vec3(jig)},
                               {"source", user_jig ? "user" : "estimated"},
                               {"note", repeats ? "white position-to-position scatter beyond the pots' repeatability, "
                                                  "from second differences along the plate; capped at 0.05 mm"
                                                : "no repeated samples: the pots' noise is not measured apart; it is in "
                                                  "the readings' own error (reading_noise_mm) where that is kept, and in "
                                                  "this estimate where it is not"}};
    out["jig_tolerance_mm"]["plate_holes"] = vec3(cf.fit_options.hole_sigma);
    out["reading_noise_mm"] = reading_noise_json(cf.reading);
    if (!repeats && cf.reading.sigma > 0)
        out["reading_noise_mm"]["note"] = "no repeated samples: the pots' noise is not measured apart, and this "
                                          "holds it with whatever each reading adds of its own";
    // The readings' own error again, from the recommended model's
    // misclosure: estimated first from the user's model, whose error leaks
    // into it where it is not smooth across the plate (a short ripple, a
    // worn spot: 0.0037 mm from a 0.15 mm ripple on the nominal model).
    // The misclosure's noise already holds the variance used, so the
    // estimate is what is beyond it (or short of it, below zero).
    // The total is kept by the first estimate's rule (more than three
    // standard errors above zero), and diagnose() runs the diagnosis again
    // with it when what is kept differs from the variance used by more than
    // three standard errors and a fifth of that variance (never when both
    // are none).
    if (search) {
        const ReadingNoise again = estimate_reading_noise(sr.E, cf.grid);
        const double used = cf.reading.sigma * cf.reading.sigma;
        ReadingNoise r = again;
        r.variance = used + again.variance;
        r.sigma = again.tested && r.variance > 3 * again.se ? std::sqrt(r.variance) : 0.0;
        const double keep = r.sigma * r.sigma;
        out["reading_noise_mm"]["recommended_model"] = {{"value", r.sigma},
                                                         {"variance_mm2", r.variance},
                                                         {"beyond_used_mm2", again.variance},
                                                         {"se_mm2", again.se}};
        if (again.tested && keep != used && std::fabs(keep - used) > 3 * again.se &&
            std::fabs(keep - used) > 0.2 * used)
            reading_retry = r;
    }
    out["jig_tolerance_mm"]["plate_holes_note"] =
        (cf.fit_options.hole_sigma.array() > 0).any()
            ? "the part of the tolerance each hole shares at every height, from the covariance across heights of "
              "the same second differences: the fit weighs each hole's readings as one block (generalised least "
              "squares) and the chi-square and structure tests are widened for it"
        : user_jig ? "none: the tolerance given is taken as each position's own"
        : !cf.grid.layered ? "none: the positions are not on a plate measured at fixture heights"
                           : "none significant (3 standard errors over the plate's rows and columns): every position's "
                             "error is taken as its own";
    out["chi2_per_dof"] = vcur.chi2 / vcur.dof;
    out["dof"] = vcur.dof;
    out["chi2_p_value"] = vcur.chi2_p;
    out["chi2_test"] = {{"scale", vcur.chi2_scale},
                        {"widened", vcur.chi2_widened()},
                        {"method", "chi2 / scale against chi-square(dof / scale) (Satterthwaite; scale 1: chi-square(dof)); "
                                   "the scale is tr(R^2)/tr(R), R the residuals' correlation from the plate's holes"}};
    out["structure"] = {{"statistic", vcur.moran_z},
                        {"p_value", vcur.moran_p},
                        {"variance_scale", vcur.moran_scale},
                        {"method", "Moran's I of the standardised position residuals over the plate's neighbour "
                                   "graph, per axis, per-height means removed; z-score (over the square root of "
                                   "variance_scale, the variance the plate's holes add by repeating at every height), "
                                   "max over axes, Bonferroni p"}};
    out["explained"] = jm.explained;
    out["negligible_only"] = jm.negligible_only;
    out["fits_with_stand_ins"] = jm.with_stand_ins;
    out["stand_ins"] = stand_ins_json(bey.user);
    out["discovered"] = bey.discovery.json;
    out["significant_left"] = jm.significant;
    out["verdict"] = verdict;
    out["recommended"] = recommended;
    out["search"] = search ? "forward-backward stepwise by BIC (see recommended.criterion)"
                           : opt.candidates ? "off (--no-search)" : "off (--no-candidates)";
    out["failing_positions"] = vcur.n_failing;
    out["candidates"] = candidates_json(cands);
    out["candidates_tried"] = opt.candidates;
    out["inseparable"] = inseparable_json(search ? sr.cands : cands);
    out["model_review"] = review;
    out["unexplained_structure"] = {{"summary", unexplained_summary},
                                    {"residual_of", search ? "the recommended model (" + join(sr.effects, " + ", "nominal") + ")"
                                                   : use_top ? "the model plus " + cands[0].name : modelname},
                                    {"findings", findings}};
    out["validation"] = validation;
    jig_report["fixture_fitted_x_mm"] = search ? sr.rep.fixture_mm : rep.fixture_mm;
    jig_report["residual_of"] = out["unexplained_structure"]["residual_of"];
    jig_report["attribution"] = bey.attribution.report;
    out["jig"] = jig_report;
    if (opt.per_position) {
        json pj;
        json point = json::array(), ref = json::array(), height = json::array(), n = json::array(), res = json::array(),
             nres = json::array(), eres = json::array(), sig = json::array(), fail = json::array(),
             lm = json::array(), lr = json::array(), ang = json::array();
        for (size_t j = 0; j < P; ++j) {
            point.push_back(data.pos[j].point);
            ref.push_back(vec3(pos[j].ref));
            height.push_back(pos[j].ref(0));
            n.push_back(pos[j].n);
            res.push_back(vec3(cur.res[j]));
            nres.push_back(vec3(nom.res[j]));
            eres.push_back(vec3(ellE.res[j]));
            V3 s;
            for (int a = 0; a < 3; ++a) s(a) = std::sqrt(cur.var_mean[j](a) + jig(a) * jig(a));
            sig.push_back(vec3(s));
            fail.push_back(bool(vcur.failing[j]));
            lm.push_back(lv.lmean[j]);
            lr.push_back(lv.lres[j]);
            ang.push_back(lv.angle[j]);
        }
        pj["point"] = point;
        pj["ref"] = ref;
        pj["height"] = height;
        pj["n"] = n;
        pj["residual_mm"] = res;
        pj["nominal_residual_mm"] = nres;
        pj["ellipsoid_residual_mm"] = eres;
        pj["sigma_mm"] = sig;
        pj["failing"] = fail;
        pj["lengths_mm"] = lm;
        pj["length_residual_mm"] = lr;
        pj["cable_angle_deg"] = ang;
        pj["trends"] = panel_trends(pos, cur, lv);
        out["positions"] = pj;
        // Fingerprints of what is missing: only candidates that are
        // significant on top of the recommended model (or the user's,
        // without the search), at most four.
        json fps = json::object();
        const auto &fc = search ? sr.cands : cands;
        for (size_t a = 0, shown = 0; a < fc.size() && shown < 4; ++a) {
            if (!fc[a].significant()) continue;
            json f = json::array();
            for (auto &v : fc[a].fp) f.push_back(vec3(v));
            fps[fc[a].name] = f;
            ++shown;
        }
        out["fingerprints"] = fps;
    }
    out["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    fitted = model;
    ctx.report("done", 1.0);
    return true;
}

// Outliers (fit_outliers.h): the diagnosis is run again without the
// positions it set aside, and says which they were.
bool diagnose(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, json &out, Model &fitted,
              std::string &err) {
    json outliers;
    // Each round once more, with the readings' own error from the
    // recommended model's misclosure, when it disagrees with the one used
    // (diagnose_data): at most once.
    auto round = [&](const Dataset &d, size_t already, size_t read, std::vector<Outlier> &found, Declined &declined,
                     std::string &e) {
        std::optional<ReadingNoise> retry;
        if (!diagnose_data(d, g, opt, out, fitted, e, already, read, found, declined, retry)) return false;
        if (!retry || opt.reading_noise) return true;
        DiagnoseOptions o2 = opt;
        o2.reading_noise = retry;
        found.clear();
        declined = {};
        return diagnose_data(d, g, o2, out, fitted, e, already, read, found, declined, retry);
    };
    if (!run_setting_aside_outliers(data, opt.outliers, round, outliers, err)) return false;
    out["data"]["outliers"] = outliers;
    if (outliers["count"].get<size_t>() > 0)
        out["verdict"] = out["verdict"].get<std::string>() + " " + outliers_words(outliers["set_aside"], data.pos.size());
    return true;
}

} // namespace cdm
