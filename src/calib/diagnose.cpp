// See diagnose.h. diagnose() orchestrates; the statistics are in diag_*.h and
// docs/calibration.md explains each.
#include "calib/diagnose.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>

#include <Eigen/Dense>

#include "calib/fit.h"
#include "cdm/cdm.h"
#include "io/device_json.h"
#include "model/effect.h"

#include "calib/diag_eval.h"
#include "calib/diag_findings.h"
#include "calib/diag_residual.h"
#include "calib/diag_spatial.h"
#include "calib/diag_stats.h"
#include "calib/fit_calibration.h"

namespace cdm {

namespace {

using nlohmann::json;
using namespace diag;
const char *kAxis[3] = {"x", "y", "z"};

json vec3(const V3 &v) { return json::array({v(0), v(1), v(2)}); }

} // namespace

// ============================================================== diagnose

bool diagnose(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, json &out, Model &fitted,
              std::string &err) {
    auto t0 = std::chrono::steady_clock::now();
    auto progress = [&](const std::string &s, double f) { return !opt.progress || opt.progress(s, f); };
    FitCalibrationOptions fopt;
    fopt.effects = opt.effects;
    fopt.jig_tolerance_mm = opt.jig_tolerance_mm;
    fopt.progress = opt.progress;
    fopt.fitted_maxima = false; // one pass over the rows at the end serves every evaluation
    CalibrationFit cf(g);
    if (!fit_calibration(data, g, fopt, cf, err)) return false;
    const auto &pos = cf.pos;
    const size_t P = pos.size();
    const Grid &G = cf.grid;
    Model &model = cf.model;
    FitReport &rep = cf.report;
    FitOptions &fo = cf.fit_options;
    V3 jig = cf.jig;
    const Eval &nom = cf.nominal;
    Ellipsoid ell = ellipsoid_on(nom, pos);
    Eval ellE; // the seed's procedure with its ellipsoid: in the pass over the rows below
    Eval cur = cf.fitted;
    const bool user_jig = opt.jig_tolerance_mm >= 0;
    // Candidates' own jig tolerance is capped as in fit_calibration().
    const bool repeats = std::any_of(pos.begin(), pos.end(), [](const PreparedPos &p) { return p.n > 1; });
    const double jig_cap = repeats ? 0.05 : INFINITY;
    const bool model_has_ellipsoid =
        std::find(opt.effects.begin(), opt.effects.end(), "ellipsoid") != opt.effects.end();
    auto fit_with_progress = [&](Model &m, FitOptions f, const std::string &stage, FitReport &r) {
        f.progress = [&](double fr) { return progress(stage, fr); };
        return fit_model(m, pos, f, r);
    };
    Verdict vcur = judge(cur, G, jig, rep.n_free);
    const double n_obs = 4.0 * double(P);
    // The fitted model's reading-space chi-square, the reference every
    // candidate and every review refit is compared with.
    const double chi2_cur = model_chi2(model, pos, fo);

    // --- candidates
    struct Cand {
        std::string name;
        double dchi2 = 0, bic = 0, score = 0, corr = 0;
        int k = 0;
        Eval E;
        Verdict v;
        Model m;
        std::vector<V3> fp;
        std::vector<std::string> in_model; // model effects that reproduce it
    };
    std::vector<Cand> cands;
    if (opt.candidates) {
        auto list = candidate_effects();
        size_t done = 0;
        for (auto &d : list) {
            ++done;
            if (model.has_effect(d->name)) continue;
            Cand c{d->name, 0, 0, 0, 0, 0, {}, {}, model, {}, {}};
            std::string e2;
            if (!c.m.add_effect(d->name, {}, e2)) continue;
            FitReport r2;
            if (!fit_with_progress(c.m, fo, "scoring " + d->name, r2)) {
                err = "fit cancelled";
                return false;
            }
            c.k = r2.n_free - (rep.n_free - (model_has_ellipsoid ? 3 : 0));
            // What the model already does that this effect would: an effect
            // the model's own effects reproduce cannot be told from them.
            if (model.effect_count() > (model_has_ellipsoid ? 1u : 0u)) {
                Overlap ov = effect_overlap(c.m, pos, fo, d->name);
                for (auto &pe : ov.per_effect)
                    if (pe.second > 0.99) c.in_model.push_back(pe.first);
                if (c.in_model.empty() && ov.all > 0.99)
                    for (auto &pe : ov.per_effect) c.in_model.push_back(pe.first);
            }
            if (c.k <= 0) continue; // nothing left to fit after the gauge: indistinguishable from the model
            c.dchi2 = chi2_cur - r2.chi2;
            c.bic = -c.dchi2 + c.k * std::log(n_obs);
            c.score = -c.bic;
            c.E = evaluate(c.m, pos);
            // Each explanation is judged with the white scatter its own
            // residual shows: a large smooth residual biases the nugget.
            V3 jc = jig;
            if (!user_jig) {
                V3 est = estimate_nugget(c.E, G);
                for (int a = 0; a < 3; ++a) jc(a) = std::min(est(a), jig_cap);
            }
            c.v = judge(c.E, G, jc, r2.n_free);
            c.fp.resize(P);
            double sxy = 0, sxx = 0, syy = 0;
            for (size_t j = 0; j < P; ++j) {
                c.fp[j] = cur.res[j] - c.E.res[j];
                for (int a = 0; a < 3; ++a) {
                    const double s2 = cur.var_mean[j](a) + jig(a) * jig(a);
                    sxy += c.fp[j](a) * cur.res[j](a) / s2;
                    sxx += c.fp[j](a) * c.fp[j](a) / s2;
                    syy += cur.res[j](a) * cur.res[j](a) / s2;
                }
            }
            c.corr = (sxx > 0 && syy > 0) ? sxy / std::sqrt(sxx * syy) : 0;
            cands.push_back(std::move(c));
            progress("candidates", double(done) / double(list.size()));
        }
        std::sort(cands.begin(), cands.end(), [](const Cand &a, const Cand &b) { return a.bic < b.bic; });
    }
    // Confusion: two candidates that explain the same residual about as well.
    auto fp_corr = [&](const Cand &a, const Cand &b) {
        double sab = 0, saa = 0, sbb = 0;
        for (size_t j = 0; j < P; ++j)
            for (int k = 0; k < 3; ++k) {
                const double s2 = cur.var_mean[j](k) + jig(k) * jig(k);
                sab += a.fp[j](k) * b.fp[j](k) / s2;
                saa += a.fp[j](k) * a.fp[j](k) / s2;
                sbb += b.fp[j](k) * b.fp[j](k) / s2;
            }
        return (saa > 0 && sbb > 0) ? sab / std::sqrt(saa * sbb) : 0.0;
    };
    std::vector<std::vector<std::string>> confused(cands.size());
    for (size_t a = 0; a < cands.size(); ++a) confused[a] = cands[a].in_model;
    for (size_t a = 0; a < cands.size(); ++a)
        for (size_t b = 0; b < cands.size(); ++b) {
            if (a == b || cands[a].bic >= 0 || cands[b].bic >= 0) continue;
            // Equally good (BIC within 10: "very strong" evidence on
            // Kass-Raftery's scale is needed to prefer one) and explaining
            // the same pattern.
            if (std::fabs(cands[a].bic - cands[b].bic) < 10 && fp_corr(cands[a], cands[b]) > 0.9)
                confused[a].push_back(cands[b].name);
        }

    // --- model review: is each effect in the model still earning its
    // parameters, and would a candidate do its job better? Greedy forward
    // selection can pick a many-parameter effect that mimics two small ones
    // (anchors for a jig tilt plus a gain error); this catches it.
    json review = json::array();
    {
        const double bic_cur = chi2_cur + rep.n_free * std::log(n_obs);
        auto rebuild = [&](const std::string &skip, const std::string &add, Model &m2) {
            std::string e2;
            for (size_t k = 0; k < model.effect_count(); ++k) {
                const EffectDesc &d = model.effect_desc(k);
                if (d.name == skip || d.stage == Stage::Position) continue;
                ParamValues pv;
                for (size_t q = 0; q < d.params.size(); ++q) pv.push_back({d.params[q].name, model.effect_params(k)[q]});
                m2.add_effect(d.name, pv, e2);
            }
            if (!add.empty()) m2.add_effect(add, {}, e2);
        };
        for (size_t k = 0; k < model.effect_count(); ++k) {
            if (model.effect_desc(k).stage == Stage::Position) continue;
            const std::string name = model.effect_desc(k).name;
            Model without{g};
            rebuild(name, "", without);
            FitReport rw;
            fit_with_progress(without, fo, "reviewing " + name, rw);
            const double bic_without = rw.chi2 + rw.n_free * std::log(n_obs);
            json item = {{"effect", name}, {"bic_change_if_removed", bic_without - bic_cur},
                         {"redundant", bic_without - bic_cur < 10}};
            double best = 0;
            std::string best_name;
            // Every catalogued effect not in the model (not only the ranked
            // candidates: one that adds no free parameter to the model, like
            // the jig transform beside the anchors, can still replace one).
            for (auto &cd : candidate_effects()) {
                if (model.has_effect(cd->name)) continue;
                Model swapped{g};
                rebuild(name, cd->name, swapped);
                FitReport rs;
                fit_with_progress(swapped, fo, "reviewing " + name, rs);
                const double d = rs.chi2 + rs.n_free * std::log(n_obs) - bic_cur;
                if (d < best) {
                    best = d;
                    best_name = cd->name;
                }
            }
            if (best < -10) item["better_swap"] = {{"effect", best_name}, {"bic_change", best}};
            review.push_back(item);
        }
    }

    // --- leave-one-height-out validation
    json validation = nullptr;
    if (opt.validation && rep.n_free > 0 && G.layered && data.heights.size() > 1 && data.heights.size() <= 20) {
        Acc held[3];
        json folds = json::array();
        for (size_t h = 0; h < data.heights.size(); ++h) {
            Model mv = model;
            FitOptions fv = fo;
            fv.use.assign(P, 0);
            for (size_t j = 0; j < P; ++j) fv.use[j] = G.height_index[j] != int(h);
            FitReport rv;
            if (!fit_with_progress(mv, fv, "validation", rv)) {
                err = "fit cancelled";
                return false;
            }
            Eval ev = evaluate(mv, pos);
            Acc f[3];
            for (size_t j = 0; j < P; ++j)
                if (!fv.use[j] && ev.ok[j])
                    for (int a = 0; a < 3; ++a) {
                        f[a].add(ev.res[j](a));
                        held[a].add(ev.res[j](a));
                    }
            folds.push_back({{"height", data.heights[h]},
                             {"rms_mm", {{"x", f[0].to_json()["rms"]}, {"y", f[1].to_json()["rms"]}, {"z", f[2].to_json()["rms"]}}}});
        }
        Acc ins[3];
        for (size_t j = 0; j < P; ++j)
            if (cur.ok[j])
                for (int a = 0; a < 3; ++a) ins[a].add(cur.res[j](a));
        validation = {{"method", "leave-one-height-out"},
                      {"folds", folds},
                      {"rms_mm", {{"x", held[0].to_json()["rms"]}, {"y", held[1].to_json()["rms"]}, {"z", held[2].to_json()["rms"]}}},
                      {"in_sample_rms_mm", {{"x", ins[0].to_json()["rms"]}, {"y", ins[1].to_json()["rms"]}, {"z", ins[2].to_json()["rms"]}}}};
    }

    // --- beyond the catalogue: what is left after the best catalogued
    // explanation (the current model, or the top candidate on top of it when
    // neither explains the data), against physical variables
    progress("residual analysis", 0.0);
    const bool use_top = !vcur.explained && !cands.empty() && cands[0].bic < 0 && !cands[0].v.explained;
    const Model &basis = use_top ? cands[0].m : model;
    const Eval &bE = use_top ? cands[0].E : cur;
    std::vector<std::array<double, 4>> lres(P), lmean(P), angle(P);
    for (size_t j = 0; j < P; ++j) {
        double t[3], y[4];
        basis.jig_to_device(pos[j].ref.data(), t);
        basis.readings(t, y);
        const auto A = g;
        for (int c = 0; c < 4; ++c) {
            lres[j][size_t(c)] = pos[j].mean(c) - y[c];
            lmean[j][size_t(c)] = pos[j].mean(c);
            auto an = A.anchor(c);
            auto ho = A.holder(c);
            double d[3] = {t[0] + ho[0] - an[0], t[1] + ho[1] - an[1], t[2] + ho[2] - an[2]};
            angle[j][size_t(c)] = std::atan2(d[0], std::hypot(d[1], d[2])) * 180 / M_PI;
        }
    }
    const json findings = residual_findings(pos, lmean, lres, angle, bE, jig);

    // --- verdict
    const Cand *top = cands.empty() ? nullptr : &cands[0];
    std::string verdict, unexplained_summary;
    auto errx = [](const Eval &E) { return E.err[0].to_json()["rms"].get<double>(); };
    auto fmt = [](double v, int prec = 3) {
        char b[64];
        std::snprintf(b, sizeof b, "%.*f", prec, v);
        return std::string(b);
    };
    std::string modelname = "the nominal model";
    if (model.effect_count()) {
        modelname = "the model with ";
        for (size_t k = 0; k < model.effect_count(); ++k) modelname += (k ? ", " : "") + model.effect_name(k);
    }
    if (vcur.explained) {
        verdict = modelname + " explains the data: the residual is consistent with the pots' repeatability and the jig's "
                  "tolerance (chi2/dof " + fmt(vcur.chi2 / vcur.dof, 2) + ", spatial structure p = " + fmt(vcur.moran_p, 3) +
                  ").";
        unexplained_summary = "nothing left to explain";
    } else if (top && top->bic < 0 && top->v.explained) {
        verdict = modelname + " leaves structured error (x RMS " + fmt(errx(cur)) + " mm, structure z = " +
                  fmt(vcur.moran_z, 1) + "). Missing effect: " + top->name + " (delta chi2 " + fmt(top->dchi2, 0) +
                  "); with it the x RMS falls to " + fmt(errx(top->E)) + " mm and the residual is consistent with noise.";
        if (!confused[0].empty()) {
            verdict += " The data cannot tell it from: ";
            for (size_t k = 0; k < confused[0].size(); ++k) verdict += (k ? ", " : "") + confused[0][k];
            verdict += " (see inseparable).";
        }
        verdict += " Add it with --effects.";
        unexplained_summary = "explained by a catalogued effect (" + top->name + ")";
    } else if (top && top->bic < 0 && vcur.chi2 - top->v.chi2 >= 0.5 * (vcur.chi2 - vcur.dof)) {
        verdict = modelname + " leaves structured error; the best catalogued effect, " + top->name +
                  ", explains part of it (x RMS " + fmt(errx(cur)) + " -> " + fmt(errx(top->E)) +
                  " mm) but structure remains after it (z = " + fmt(top->v.moran_z, 1) +
                  "). Either several effects are missing (add " + top->name +
                  " and diagnose again) or an effect outside the catalogue is at work: see unexplained_structure.";
        unexplained_summary = "not fully explained by any single catalogued effect";
    } else {
        verdict = modelname + " leaves structured error (x RMS " + fmt(errx(cur)) + " mm, structure z = " +
                  fmt(vcur.moran_z, 1) + ") and no effect in the catalogue explains it";
        if (top && top->bic < 0)
            verdict += " (the best, " + top->name + ", removes only " +
                       fmt(std::max(0.0, 100 * (vcur.chi2 - top->v.chi2) / std::max(1.0, vcur.chi2 - vcur.dof)), 0) +
                       " % of the excess chi-square)";
        verdict += ". See unexplained_structure for the residual against the physical variables; a user-defined "
                   "effect (docs/calibration.md) can then be fitted like a catalogued one.";
        unexplained_summary = "no catalogued effect explains the residual";
    }
    for (auto &r : review) {
        if (r.contains("better_swap"))
            verdict += " Review: replacing " + r["effect"].get<std::string>() + " with " +
                       r["better_swap"]["effect"].get<std::string>() + " explains the data as well with fewer "
                       "parameters (BIC " + fmt(r["better_swap"]["bic_change"].get<double>(), 0) + ").";
        else if (r["redundant"].get<bool>())
            verdict += " Review: " + r["effect"].get<std::string>() +
                       " no longer earns its parameters (removing it changes BIC by " +
                       fmt(r["bic_change_if_removed"].get<double>(), 0) + ").";
    }
    if (!vcur.explained && !(top && top->v.explained) && !findings.empty()) {
        unexplained_summary += "; found: ";
        for (size_t k = 0; k < std::min<size_t>(3, findings.size()); ++k)
            unexplained_summary += (k ? "; " : "") + findings[k]["text"].get<std::string>();
    }

    // --- what needs every sample: the maxima of the reported evaluations and
    // the seed's ellipsoid applied to each sample, in one pass over the rows
    {
        std::vector<Eval *> linear{&cur};
        for (auto &c : cands) linear.push_back(&c.E);
        progress("per-sample statistics", 0.0);
        if (!sample_pass(data, pos, linear, {{&g, &ell, &ellE}}, err)) return false;
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
                   {"ignored_columns", data.ignored_columns},
                   {"out_of_workspace_samples", nom.bad_samples}};
    out["device"] = io::device_to_json(g);
    json mlist = json::array(), params = json::object();
    for (size_t k = 0; k < model.effect_count(); ++k) {
        mlist.push_back(model.effect_name(k));
        const EffectDesc &d = model.effect_desc(k);
        const auto &pv = model.effect_params(k);
        json pj = json::object();
        for (size_t q = 0; q < pv.size(); ++q) {
            double sd = (k < rep.std.size() && q < rep.std[k].size()) ? rep.std[k][q] : 0.0;
            pj[d.params[q].name] = {{"value", pv[q]}, {"std", sd}, {"unit", d.params[q].unit}};
        }
        params[model.effect_name(k)] = pj;
    }
    out["model"] = mlist;
    out["params"] = params;
    out["fit"] = {{"algorithm", rep.algorithm}, {"evaluations", rep.evals}, {"seconds", rep.seconds},
                  {"converged", rep.converged}, {"free_parameters", rep.n_free}, {"message", rep.message}};
    out["error_mm"] = stats3(cur.err);
    out["nominal_error_mm"] = stats3(nom.err);
    out["ellipsoid_error_mm"] = stats3(ellE.err);
    out["ellipsoid"] = {{"L", ell.L}, {"M", ell.M}, {"N", ell.N}};
    {
        json nf;
        for (int a = 0; a < 3; ++a) {
            const double w = cur.within[a].n > 1 ? cur.within[a].ss / cur.within[a].n : 0;
            const double s = std::sqrt(w + jig(a) * jig(a));
            nf[kAxis[a]] = {{"mean", 0.0}, {"std", s}, {"rms", s}, {"max", cur.within[a].mx}};
        }
        out["noise_floor_mm"] = nf;
    }
    out["jig_tolerance_mm"] = {{"value", std::sqrt(0.5 * (jig(1) * jig(1) + jig(2) * jig(2)))},
                               {"per_axis", vec3(jig)},
                               {"source", user_jig ? "user" : "estimated"},
                               {"note", repeats ? "white position-to-position scatter beyond the pots' repeatability, "
                                                  "from second differences along the plate; capped at 0.05 mm"
                                                : "no repeated samples: the pots' noise and the jig's scatter cannot be "
                                                  "told apart, both are in this estimate"}};
    out["chi2_per_dof"] = vcur.chi2 / vcur.dof;
    out["dof"] = vcur.dof;
    out["chi2_p_value"] = vcur.chi2_p;
    out["structure"] = {{"statistic", vcur.moran_z},
                        {"p_value", vcur.moran_p},
                        {"method", "Moran's I of the standardised position residuals over the plate's neighbour "
                                   "graph, per axis, per-height means removed; z-score, max over axes, Bonferroni p"}};
    out["explained"] = vcur.explained;
    out["verdict"] = verdict;
    out["failing_positions"] = vcur.n_failing;
    json cj = json::array();
    for (size_t a = 0; a < cands.size(); ++a) {
        auto &c = cands[a];
        cj.push_back({{"effect", c.name},
                      {"score", c.score},
                      {"delta_chi2", c.dchi2},
                      {"bic_change", c.bic},
                      {"n_params", c.k},
                      {"error_mm_after", stats3(c.E.err)},
                      {"explained_after", c.v.explained},
                      {"chi2_per_dof_after", c.v.chi2 / c.v.dof},
                      {"structure_after", c.v.moran_z},
                      {"confused_with", confused[a]},
                      {"residual_correlation", c.corr}});
    }
    out["candidates"] = cj;
    // Inseparable groups, with where their predictions part.
    json insep = json::array();
    std::vector<char> seen(cands.size(), 0);
    for (size_t a = 0; a < cands.size(); ++a) {
        if (seen[a] || confused[a].empty()) continue;
        json grp = json::array({cands[a].name});
        seen[a] = 1;
        std::string sep;
        for (auto &nm : confused[a]) {
            grp.push_back(nm);
            for (size_t b = 0; b < cands.size(); ++b)
                if (cands[b].name == nm) {
                    seen[b] = 1;
                    // probe heights and radii beyond the measured ones
                    double best = -1, bh = 0, by = 0, bz = 0;
                    for (double hx = 10; hx <= 110; hx += 10)
                        for (double yy = -90; yy <= 90; yy += 15)
                            for (double zz = -90; zz <= 90; zz += 15) {
                                double pa[3] = {hx, yy, zz}, ra[4], rb[4], ta[3], tb[3];
                                cands[a].m.jig_to_device(pa, ta);
                                cands[b].m.jig_to_device(pa, tb);
                                cands[a].m.readings(ta, ra);
                                cands[b].m.readings(tb, rb);
                                double dmax = 0;
                                for (int c = 0; c < 4; ++c) dmax = std::max(dmax, std::fabs(ra[c] - rb[c]));
                                if (dmax > best) {
                                    best = dmax;
                                    bh = hx;
                                    by = yy;
                                    bz = zz;
                                }
                            }
                    sep += (sep.empty() ? "" : "; ") + cands[a].name + " vs " + nm;
                    // 0.01 mm: a position mean of 100 samples at 0.05 mm noise.
                    if (best < 0.01)
                        sep += ": they predict the same readings everywhere (at most " + fmt(best, 4) +
                               " mm apart out to x = 10..110, y, z = +-90 mm): no jig measurement separates them; "
                               "they are one effect as far as the cable lengths can tell, keep either";
                    else
                        sep += ": their readings differ most (" + fmt(best) + " mm) at x = " + fmt(bh, 0) + ", y = " +
                               fmt(by, 0) + ", z = " + fmt(bz, 0) +
                               " mm; measure positions toward there (other heights, further out) to separate them";
                }
            bool is_cand = false;
            for (auto &c : cands) is_cand = is_cand || c.name == nm;
            if (!is_cand)
                sep += (sep.empty() ? "" : "; ") + nm + " (already in the model) reproduces what " + cands[a].name +
                       " would do: adding it changes nothing the data can see";
        }
        insep.push_back({{"effects", grp}, {"separate_by", sep}});
    }
    out["inseparable"] = insep;
    out["model_review"] = review;
    out["unexplained_structure"] = {{"summary", unexplained_summary},
                                    {"residual_of", use_top ? "the model plus " + cands[0].name : modelname},
                                    {"findings", findings}};
    out["validation"] = validation;
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
            lm.push_back(lmean[j]);
            lr.push_back(lres[j]);
            ang.push_back(angle[j]);
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
        out["positions"] = pj;
        json fps = json::object();
        for (size_t a = 0; a < std::min<size_t>(4, cands.size()); ++a) {
            json f = json::array();
            for (auto &v : cands[a].fp) f.push_back(vec3(v));
            fps[cands[a].name] = f;
        }
        out["fingerprints"] = fps;
    }
    out["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    fitted = model;
    progress("done", 1.0);
    return true;
}

} // namespace cdm
