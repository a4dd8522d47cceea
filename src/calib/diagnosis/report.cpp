// See stages.h: the diagnosis's JSON (docs/calibration.md) written from the
// stages' results; nothing is computed here that a stage could get wrong.
#include <chrono>
#include <cmath>
#include <string>

#include "calib/diagnosis/diagnose_json.h"
#include "calib/evaluation/accuracy.h"
#include "calib/diagnosis/panels.h"
#include "calib/diagnosis/stages.h"
#include "cdm/cdm.h"
#include "io/device_json.h"

namespace cdm {
namespace diag {

namespace {

using nlohmann::json;
const char *kAxis[3] = {"x", "y", "z"};

json data_json(const Diagnosis &d) {
    const Dataset &data = d.data;
    return {{"path", data.path},
            {"rows", data.rows},
            {"positions", d.u.cf.pos.size()},
            {"heights", data.heights},
            // points whose x_ref no other position shares, grouped with the nearest height
            {"off_height_points", data.off_height_points},
            {"ignored_columns", data.ignored_columns},
            {"out_of_workspace_samples", d.u.cf.nominal.bad_samples},
            {"samples_used", [&] {
                 size_t n = 0;
                 for (auto &p : data.pos) n += size_t(p.n);
                 return n;
             }()},
            {"glitches", glitches_json(data)}};
}

json recommended_json(const Diagnosis &d) {
    const SearchResult &sr = d.s.sr;
    const DiagContext &sctx = d.s.sctx;
    const Verdict &vr = d.w.vr;
    const Judgement &jr = d.w.jr;
    json path = json::array(), alternatives = json::array();
    for (auto &st : sr.path) {
        json s = {{"step", st.step}, {"bic_change", st.bic_change}, {"x_rms_mm", st.x_rms_mm}};
        if (!st.added.empty()) s["added"] = st.added;
        if (!st.removed.empty()) s["removed"] = st.removed;
        path.push_back(s);
    }
    for (auto &a : d.s.alts) alternatives.push_back(a.first);
    json alt_bic = json::array();
    for (auto &a : d.s.alts) alt_bic.push_back(a.second);
    return {{"effects", sr.effects},
            {"bic", sr.bic},
            {"error_mm", stats3(sr.E.err)},
            {"explained", jr.explained},
            {"negligible_only", jr.negligible_only},
            {"fits_with_stand_ins", jr.with_stand_ins},
            {"stand_ins", stand_ins_json(d.r.bey.recommended)},
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
}

// The jig tolerance and the plate's holes, the readings' own error.
void noise_json(const Diagnosis &d, json &out) {
    const CalibrationFit &cf = d.u.cf;
    const V3 &jig = cf.jig;
    out["jig_tolerance_mm"] = {{"value", std::sqrt(0.5 * (jig(1) * jig(1) + jig(2) * jig(2)))},
                               {"per_axis", vec3(jig)},
                               {"source", d.u.user_jig ? "user" : "estimated"},
                               {"note", d.u.repeats ? "white position-to-position scatter beyond the pots' repeatability, "
                                                      "from second differences along the plate; capped at 0.05 mm"
                                                    : "no repeated samples: the pots' noise is not measured apart; it is in "
                                                      "the readings' own error (reading_noise_mm) where that is kept, and in "
                                                      "this estimate where it is not"}};
    out["jig_tolerance_mm"]["plate_holes"] = vec3(cf.fit_options.hole_sigma);
    out["reading_noise_mm"] = reading_noise_json(cf.reading);
    if (!d.u.repeats && cf.reading.sigma > 0)
        out["reading_noise_mm"]["note"] = "no repeated samples: the pots' noise is not measured apart, and this "
                                          "holds it with whatever each reading adds of its own";
    if (d.reading.on)
        out["reading_noise_mm"]["recommended_model"] = {{"value", d.reading.r.sigma},
                                                         {"variance_mm2", d.reading.r.variance},
                                                         {"beyond_used_mm2", d.reading.again.variance},
                                                         {"se_mm2", d.reading.again.se}};
    out["jig_tolerance_mm"]["plate_holes_note"] =
        (cf.fit_options.hole_sigma.array() > 0).any()
            ? "the part of the tolerance each hole shares at every height, from the covariance across heights of "
              "the same second differences: the fit weighs each hole's readings as one block (generalised least "
              "squares) and the chi-square and structure tests are widened for it"
        : d.u.user_jig ? "none: the tolerance given is taken as each position's own"
        : !cf.grid.layered ? "none: the positions are not on a plate measured at fixture heights"
                           : "none significant (3 standard errors over the plate's rows and columns): every position's "
                             "error is taken as its own";
}

// The user's model's tests and verdict, the candidates, the search, the
// review, what is left, the validation, the jig.
void tests_json(const Diagnosis &d, json &out) {
    const Verdict &vcur = d.u.v;
    const Judgement &jm = d.w.jm;
    const bool search = d.s.on;
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
    out["stand_ins"] = stand_ins_json(d.r.bey.user);
    out["discovered"] = d.r.bey.discovery.json;
    out["significant_left"] = jm.significant;
    out["verdict"] = d.w.verdict;
    out["recommended"] = search ? recommended_json(d) : json(nullptr);
    out["search"] = search ? "forward-backward stepwise by BIC (see recommended.criterion)"
                           : d.opt.candidates ? "off (--no-search)" : "off (--no-candidates)";
    out["failing_positions"] = vcur.n_failing;
    out["candidates"] = candidates_json(d.cands);
    out["candidates_tried"] = d.opt.candidates;
    out["inseparable"] = inseparable_json(search ? d.s.sr.cands : d.cands);
    out["model_review"] = d.review;
    out["unexplained_structure"] = {
        {"summary", d.w.unexplained_summary},
        {"residual_of", search ? "the recommended model (" + join(d.s.sr.effects, " + ", "nominal") + ")"
                        : d.r.use_top ? "the model plus " + d.cands[0].name
                                      : d.w.modelname},
        {"findings", d.r.findings}};
    out["validation"] = d.validation;
    json jig_report = d.r.ja.report;
    jig_report["fixture_fitted_x_mm"] = search ? d.s.sr.rep.fixture_mm : d.u.cf.report.fixture_mm;
    jig_report["residual_of"] = out["unexplained_structure"]["residual_of"];
    jig_report["attribution"] = d.r.bey.attribution.report;
    out["jig"] = jig_report;
}

// Per position: its residuals under the user's model, the nominal and the
// seed's, its sigma, whether it fails, its cables.
json positions_json(const Diagnosis &d) {
    const CalibrationFit &cf = d.u.cf;
    const auto &pos = cf.pos;
    const Eval &cur = cf.fitted, &nom = cf.nominal, &ellE = d.seed.E;
    const LengthView &lv = d.r.lv;
    json pj;
    json point = json::array(), ref = json::array(), height = json::array(), n = json::array(), res = json::array(),
         nres = json::array(), eres = json::array(), sig = json::array(), fail = json::array(),
         lm = json::array(), lr = json::array(), ang = json::array();
    for (size_t j = 0; j < pos.size(); ++j) {
        point.push_back(d.data.pos[j].point);
        ref.push_back(vec3(pos[j].ref));
        height.push_back(pos[j].ref(0));
        n.push_back(pos[j].n);
        res.push_back(vec3(cur.res[j]));
        nres.push_back(vec3(nom.res[j]));
        eres.push_back(vec3(ellE.res[j]));
        V3 s;
        for (int a = 0; a < 3; ++a) s(a) = std::sqrt(cur.var_mean[j](a) + cf.jig(a) * cf.jig(a));
        sig.push_back(vec3(s));
        fail.push_back(bool(d.u.v.failing[j]));
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
    return pj;
}

// Fingerprints of what is missing: only candidates that are significant on
// top of the recommended model (or the user's, without the search), at
// most four.
json fingerprints_json(const Diagnosis &d) {
    json fps = json::object();
    const auto &fc = d.s.on ? d.s.sr.cands : d.cands;
    for (size_t a = 0, shown = 0; a < fc.size() && shown < 4; ++a) {
        if (!fc[a].significant()) continue;
        json f = json::array();
        for (auto &v : fc[a].fp) f.push_back(vec3(v));
        fps[fc[a].name] = f;
        ++shown;
    }
    return fps;
}

} // namespace

json to_json(const Diagnosis &d) {
    const CalibrationFit &cf = d.u.cf;
    const Model &model = cf.model;
    const FitReport &rep = cf.report;
    json out = json::object();
    out["tool"] = "cdm calib diagnose";
    // The header's version, not cdm_version(): calib sits below the API layer.
    out["version"] = std::to_string(CDM_VERSION_MAJOR) + "." + std::to_string(CDM_VERSION_MINOR) + "." +
                     std::to_string(CDM_VERSION_PATCH);
    out["data"] = data_json(d);
    out["device"] = io::device_to_json(d.g);
    json mlist = json::array();
    for (size_t k = 0; k < model.effect_count(); ++k) mlist.push_back(model.effect_name(k));
    out["model"] = mlist;
    out["params"] = params_json(model, rep);
    out["fit"] = {{"algorithm", rep.algorithm}, {"evaluations", rep.evals}, {"seconds", rep.seconds},
                  {"converged", rep.converged}, {"free_parameters", rep.n_free}, {"message", rep.message},
                  {"fixture_x_mm", rep.fixture_mm}, {"restarted_from", cf.restarted_from}};
    out["error_mm"] = stats3(cf.fitted.err);
    out["accuracy_map"] = accuracy_map_json(model, rep, cf.pos, cf.grid);
    out["covariance"] = covariance_json(model, rep.cov_by_hole);
    out["nominal_error_mm"] = stats3(cf.nominal.err);
    out["ellipsoid_error_mm"] = stats3(d.seed.E.err);
    out["ellipsoid"] = {{"L", d.seed.ell.L}, {"M", d.seed.ell.M}, {"N", d.seed.ell.N}};
    {
        json nf;
        for (int a = 0; a < 3; ++a)
            nf[kAxis[a]] = {{"mean", 0.0}, {"std", d.u.noise(a)}, {"rms", d.u.noise(a)}, {"max", cf.fitted.within[a].mx}};
        out["noise_floor_mm"] = nf;
    }
    noise_json(d, out);
    tests_json(d, out);
    if (d.opt.per_position) {
        out["positions"] = positions_json(d);
        out["fingerprints"] = fingerprints_json(d);
    }
    out["seconds"] = d.seconds;
    return out;
}

} // namespace diag
} // namespace cdm
