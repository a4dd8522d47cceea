// extern "C" cdm_check: a calibration applied as it is to another jig
// session, the jig placed anew. Thin: the logic is fit_calibration() with
// FitCalibrationOptions::check, and the diagnosis's judge().
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "api/errors.h"
#include "api/jobs.h"
#include "calib/calibration/fit_calibration.h"
#include "calib/evaluation/accuracy.h"
#include "calib/evaluation/stats.h"
#include "cdm/cdm.h"
#include "io/calibration_json.h"
#include "io/file.h"
#include "io/json.h"
#include "model/effect.h"

namespace {

using nlohmann::json;
using cdm::diag::Acc;

// What the calibration's own fit says of itself (the "fit" block `cdm calib
// fit` wrote: its data, its RMS per axis; null when the file has none):
// shown beside the check, so checked as everything shown is. The RMS of
// every axis or of none; each a number of mm in [0, 1000], else refused at
// its line and column.
bool fitted_on(const cdm::io::JsonValue &cal, const std::string &source, json &out, std::string &err) {
    out = nullptr;
    const auto *fit = cal.find("fit");
    if (!fit || fit->type != cdm::io::JsonValue::Object) return true;
    out = json::object();
    if (const auto *d = fit->find("data"); d && d->type == cdm::io::JsonValue::String) out["data"] = d->str;
    const auto *e = fit->find("error_mm");
    if (!e || e->type != cdm::io::JsonValue::Object) return true;
    for (const char *axis : {"x", "y", "z"}) {
        const auto *a = e->find(axis);
        const auto *r = a ? a->find("rms") : nullptr;
        if (!r) {
            err = cdm::io::where(source, a ? *a : *e) + "fit.error_mm." + axis +
                  ".rms is missing (the fit block gives the RMS of x, y and z, or no error_mm)";
            return false;
        }
        if (r->type != cdm::io::JsonValue::Number || !(r->number >= 0 && r->number <= 1000)) {
            char got[32] = "";
            if (r->type == cdm::io::JsonValue::Number) std::snprintf(got, sizeof got, "%g", r->number);
            err = cdm::io::where(source, *r) + "fit.error_mm." + axis + ".rms must be an RMS in mm (0 to 1000), got " +
                  (r->type == cdm::io::JsonValue::Number ? std::string(got) : std::string(r->type_name()));
            return false;
        }
        out["error_mm"][axis]["rms"] = r->number;
    }
    return true;
}

// The jig's placement as fitted here: the Jig-stage effects' values and
// standard errors, the fixture heights' offsets, the tolerance estimated.
json jig_json(const cdm::CalibrationFit &cf) {
    json eff = json::array();
    for (size_t k = 0; k < cf.model.effect_count(); ++k) {
        const auto &d = cf.model.effect_desc(k);
        if (d.stage != cdm::Stage::Jig) continue;
        json pj = json::object();
        for (size_t q = 0; q < d.params.size(); ++q) {
            const auto &sd = cf.report.std;
            const double s = (k < sd.size() && q < sd[k].size()) ? sd[k][q] : 0.0;
            pj[d.params[q].name] = {{"value", cf.model.effect_params(k)[q]}, {"std", s}, {"unit", d.params[q].unit}};
        }
        eff.push_back({{"name", d.name}, {"params", pj}});
    }
    return {{"re_estimated", true},
            {"text", "the jig's placement was fitted on this session (a jig is placed anew at every session); "
                     "every other parameter is the calibration's"},
            {"effects", eff},
            {"added", cf.jig_added},
            {"fixture_mm", cf.report.fixture_mm},
            {"tolerance_mm", {cf.jig(0), cf.jig(1), cf.jig(2)}},
            {"plate_holes_mm", {cf.fit_options.hole_sigma(0), cf.fit_options.hole_sigma(1), cf.fit_options.hole_sigma(2)}}};
}

// The calibration's systematic error: each position's mean error (the
// samples' noise averaged out), summarised over the positions.
json position_error(const cdm::diag::Eval &E) {
    Acc a[3];
    for (size_t j = 0; j < E.res.size(); ++j)
        if (E.ok[j])
            for (int k = 0; k < 3; ++k) a[k].add(E.res[j](k));
    json out = json::object();
    const char *axes[] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
        const json s = a[k].to_json();
        out[axes[k]] = {{"mean", s["mean"]}, {"rms", s["rms"]}, {"max", s["max"]}};
    }
    return out;
}

// One position's entry in a list of positions.
json position_entry(const cdm::CalibrationFit &cf, const cdm::Dataset &data, size_t j) {
    const auto &h = data.pos[j];
    const auto &r = cf.fitted.res[j];
    return {{"point", h.point}, {"ref", {h.ref[0], h.ref[1], h.ref[2]}}, {"error_mm", {r(0), r(1), r(2)}}};
}

// Positions the calibration fails: the diagnosis's per-position test, and
// beyond the user's tolerance when one is given.
json failing_json(const cdm::CalibrationFit &cf, const cdm::Dataset &data, const cdm::diag::Verdict &v,
                  double max_error_mm) {
    json stat = json::array(), tol = json::array();
    for (size_t j = 0; j < cf.fitted.res.size() && j < data.pos.size(); ++j) {
        if (!cf.fitted.ok[j]) continue;
        if (v.failing[j]) stat.push_back(position_entry(cf, data, j));
        if (max_error_mm >= 0 && cf.fitted.res[j].norm() > max_error_mm) tol.push_back(position_entry(cf, data, j));
    }
    json out = {{"count", stat.size()},
                {"test", "each position's mean error against its noise and the jig's tolerance: a chi-square of 3 "
                         "degrees of freedom beyond its 1 % family-wise quantile over the positions (the "
                         "diagnosis's test)"},
                {"positions", stat}};
    if (max_error_mm >= 0)
        out["beyond_max_error"] = {{"max_error_mm", max_error_mm}, {"count", tol.size()}, {"positions", tol}};
    return out;
}

// Whether the calibration's error on this session is what its own
// covariance predicted (the accuracy map's, at each position): each
// position's mean error against its noise, the jig's tolerance and the
// predicted calibration error together, a chi-square over the positions.
// The jig's placement, fitted here, takes up the part of the calibration's
// error that moves every position alike, so the test leans towards
// "as predicted" (it sees no more than the rest).
json predicted_json(const cdm::CalibrationFit &cf, const cdm::Model &calibration, const Eigen::MatrixXd &cov,
                    const cdm::diag::Verdict &v) {
    if (cov.size() == 0) return {{"available", false}, {"text", "the calibration carries no covariance"}};
    std::vector<cdm::diag::V3> at;
    std::vector<size_t> idx;
    for (size_t j = 0; j < cf.fitted.res.size(); ++j)
        if (cf.fitted.ok[j]) at.push_back(cf.fitted.est[j]), idx.push_back(j);
    std::vector<Eigen::Matrix3d> S;
    std::vector<char> ok;
    std::string err;
    if (!cdm::diag::position_covariances(calibration, cov, at, 0.0, S, ok, err))
        return {{"available", false}, {"text", err}};
    // The fixture heights' offsets out, as the judge takes them out (at
    // their degrees of freedom): they are the jig's.
    const cdm::diag::FixtureOffsets fixture = cdm::diag::fixture_offsets(cf.fitted, cf.grid, cf.jig);
    double chi2 = 0, pred[3] = {0, 0, 0}, noise[3] = {0, 0, 0};
    long n = 0;
    json refs = json::array(), errs = json::array(), sig_cal = json::array(), sig_all = json::array(),
         chi2s = json::array();
    for (size_t i = 0; i < idx.size(); ++i) {
        if (!ok[i]) continue;
        const size_t j = idx[i];
        Eigen::Matrix3d C = S[i];
        for (int k = 0; k < 3; ++k) {
            // the judge's weights: the mean's noise and the jig's white
            // scatter (its holes' part in it, CalibrationFit::jig)
            const double w = cf.fitted.var_mean[j](k) + cf.jig(k) * cf.jig(k);
            C(k, k) += w;
            pred[k] += S[i](k, k);
            noise[k] += w;
        }
        cdm::diag::V3 e = cf.fitted.res[j];
        for (int k = 0; k < 3; ++k) {
            const auto it = fixture.find({cf.grid.height_index[j], k});
            if (it != fixture.end()) e(k) -= it->second;
        }
        const double c2 = e.dot(C.ldlt().solve(e));
        chi2 += c2;
        ++n;
        const auto &r = cf.pos[j].ref;
        refs.push_back({r(0), r(1), r(2)});
        errs.push_back({e(0), e(1), e(2)});
        sig_cal.push_back({std::sqrt(S[i](0, 0)), std::sqrt(S[i](1, 1)), std::sqrt(S[i](2, 2))});
        sig_all.push_back({std::sqrt(C(0, 0)), std::sqrt(C(1, 1)), std::sqrt(C(2, 2))});
        chi2s.push_back(c2);
    }
    if (n == 0) return {{"available", false}, {"text", "no position placed"}};
    if (!(chi2 >= 0) || !std::isfinite(chi2))
        return {{"available", false}, {"text", "the calibration's covariance gives no finite test here"}};
    const int dof = std::max(1, int(3 * n) - cf.report.n_free - int(fixture.size()));
    // The plate's holes correlate their positions' errors: the judge's
    // Satterthwaite scale widens this test as it widens the judge's.
    const double scale = std::max(1.0, v.chi2_scale);
    const double p = cdm::diag::chi2_sf(chi2 / scale, dof / scale);
    auto rms = [n](const double *v) {
        return json{{"x", std::sqrt(v[0] / double(n))}, {"y", std::sqrt(v[1] / double(n))}, {"z", std::sqrt(v[2] / double(n))}};
    };
    const bool as_predicted = p >= 1e-3;
    return {{"available", true},
            {"calibration_rms_mm", rms(pred)},
            {"noise_and_jig_rms_mm", rms(noise)},
            {"chi2_per_dof", chi2 / dof},
            {"p_value", p},
            {"chi2_scale", scale},
            {"as_predicted", as_predicted},
            {"test", "each position's mean error against its noise, the jig's tolerance and the "
                     "calibration's predicted error there (its covariance propagated), a chi-square over the "
                     "positions (widened as the judge's for the holes' correlation) at p >= 1e-3; the jig's "
                     "placement, fitted here, takes up any error common to every position"},
            {"per_position",
             {{"ref_mm", refs},
              {"error_mm", errs},
              {"calibration_sigma_mm", sig_cal},
              {"expected_sigma_mm", sig_all},
              {"chi2", chi2s},
              {"about", "each placed position's mean error (the fixture heights' offsets out), the calibration's "
                        "predicted 1-sigma there, the 1-sigma expected with the noise and the jig's tolerance, and "
                        "its chi-square (3 degrees of freedom) against them"}}},
            {"text", std::string(as_predicted ? "as the calibration's accuracy map predicted"
                                              : "larger than the calibration's accuracy map predicted") +
                         " (chi2/dof " + cdm::diag::fmt_num(chi2 / dof, 2) + ", " + cdm::diag::fmt_p(p) + ")"}};
}

std::string check_words(const cdm::diag::Verdict &v, size_t failing) {
    using cdm::diag::fmt_num;
    using cdm::diag::fmt_p;
    const std::string chi = "position chi2/dof " + fmt_num(v.chi2 / v.dof, 2) + " (" + fmt_p(v.chi2_p) +
                            (v.chi2_widened() ? ", widened x" + fmt_num(v.chi2_scale, 2) + " for the plate's holes" : "") +
                            "), spatial structure z = " + fmt_num(v.moran_z, 1) + " (" + fmt_p(v.moran_p) + ")";
    if (v.explained)
        return "the calibration holds on this session: its error is the noise and the jig's tolerance (" + chi + ")";
    return "the calibration does not hold on this session: " + chi + ", " + std::to_string(failing) +
           " positions failing; the device or its jig has changed since it was fitted, or the calibration misses "
           "an effect this session shows (`cdm calib diagnose` on this data says which)";
}

// The jig placement's parameters this session leaves undetermined: a
// standard error past the parameter's typical size (the catalogue's), so
// the data know it no better than one knows a jig before measuring; an
// error of the calibration along it would be taken for the jig's.
std::vector<std::string> undetermined_jig(const cdm::CalibrationFit &cf) {
    std::vector<std::string> out;
    for (size_t k = 0; k < cf.model.effect_count(); ++k) {
        const auto &d = cf.model.effect_desc(k);
        if (d.stage != cdm::Stage::Jig) continue;
        for (size_t q = 0; q < d.params.size(); ++q) {
            const auto &sd = cf.report.std;
            const double s = (k < sd.size() && q < sd[k].size()) ? sd[k][q] : 0.0;
            if (!(s <= d.params[q].scale))
                out.push_back(d.params[q].name + " +-" + cdm::diag::fmt_num(s, 3) + " " + d.params[q].unit +
                              " (typical " + cdm::diag::fmt_num(d.params[q].scale, 3) + ")");
        }
    }
    return out;
}

std::string inconclusive_words(const std::vector<std::string> &undetermined) {
    std::string list;
    for (const auto &u : undetermined) list += (list.empty() ? "" : ", ") + u;
    return "the check is inconclusive: this session does not determine the jig's placement (" + list +
           "): an error of the calibration along it would be taken for the jig's; measure positions spread over "
           "the plate, at two heights or more";
}

json result_json(const cdm::CalibrationFit &cf, const cdm::Dataset &data, const json &fitted,
                 const cdm::Model &calibration, const Eigen::MatrixXd &cov, double max_error_mm) {
    // n_free: the jig's placement fitted here (the judge takes the fixture
    // heights' offsets out itself, at their degrees of freedom)
    const cdm::diag::Verdict v =
        cdm::diag::judge(cf.fitted, cf.grid, cf.jig, cf.report.n_free, cf.fit_options.hole_sigma);
    json names = json::array();
    for (size_t k = 0; k < cf.model.effect_count(); ++k)
        if (cf.model.effect_desc(k).stage != cdm::Stage::Jig) names.push_back(cf.model.effect_name(k));
    size_t used = 0;
    for (char ok : cf.fitted.ok) used += ok != 0;
    const std::vector<std::string> undetermined = undetermined_jig(cf);
    return {{"tool", "cdm calib check"},
            {"effects", names},
            {"data", {{"path", data.path}, {"rows", data.rows}, {"ignored_columns", data.ignored_columns}}},
            {"positions", used},
            {"jig", jig_json(cf)},
            {"error_mm", cdm::diag::stats3(cf.fitted.err)},
            {"position_error_mm", position_error(cf.fitted)},
            {"nominal_error_mm", cdm::diag::stats3(cf.nominal.err)},
            {"calibration_fit", fitted},
            {"failing", failing_json(cf, data, v, max_error_mm)},
            {"predicted", predicted_json(cf, calibration, cov, v)},
            {"model_check",
             {{"holds", v.explained && undetermined.empty()},
              {"conclusive", undetermined.empty()},
              {"jig_undetermined", undetermined},
              {"chi2_per_dof", v.chi2 / v.dof},
              {"chi2_p_value", v.chi2_p},
              {"chi2_scale", v.chi2_scale},
              {"structure", {{"statistic", v.moran_z}, {"p_value", v.moran_p}, {"variance_scale", v.moran_scale}}},
              {"test", "the diagnosis's: position chi-square against noise + jig tolerance and Moran's I of the "
                       "residual over the plate, each at p >= 1e-3"},
              {"text", undetermined.empty() ? check_words(v, size_t(v.n_failing))
                                            : inconclusive_words(undetermined) + " (position chi2/dof " +
                                                  cdm::diag::fmt_num(v.chi2 / v.dof, 2) + ", " +
                                                  cdm::diag::fmt_p(v.chi2_p) + ")"}}},
            {"reading_noise_mm", cdm::diag::reading_noise_json(cf.reading)},
            {"glitches", cdm::glitches_json(data)}};
}

} // namespace

extern "C" int cdm_check(const char *data_csv_path, const char *calibration_json_path, const char *options_json,
                         cdm_progress_fn progress, void *user, char **result_json_out) {
    return cdm::guarded("cdm_check", [&]() -> int {
        if (!result_json_out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_check: result_json is NULL");
        *result_json_out = nullptr;
        if (!data_csv_path || !calibration_json_path)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_check: data and calibration paths are required");
        cdm::api::JobArgs a;
        if (int rc = cdm::api::parse_job_options(options_json, "cdm_check", cdm::api::JobKind::Check, a)) return rc;
        std::string err;
        std::string text;
        if (!cdm::io::read_file(calibration_json_path, cdm::io::kJsonMaxBytes, text, err, "calibration"))
            return cdm::fail(CDM_ERR_IO, err);
        cdm::io::JsonValue cal;
        if (!cdm::io::parse_json(text, calibration_json_path, cal, err)) return cdm::fail(CDM_ERR_PARSE, err);
        cdm::Model calibration{cdm::DeviceGeometry{}};
        if (!cdm::io::model_from_json(cal, calibration_json_path, calibration, err))
            return cdm::fail(CDM_ERR_PARSE, err);
        // The covariance of its fit, when it has one (checked as on load).
        Eigen::MatrixXd cov;
        const nlohmann::json whole = nlohmann::json::parse(text, nullptr, false);
        if (whole.is_object() && whole.contains("fit") && whole["fit"].is_object() &&
            whole["fit"].contains("covariance") && !whole["fit"]["covariance"].is_null() &&
            !cdm::diag::covariance_from_json(whole["fit"]["covariance"], calibration, cov, err))
            return cdm::fail(CDM_ERR_PARSE, std::string(calibration_json_path) + ": " + err);
        json fitted;
        if (!fitted_on(cal, calibration_json_path, fitted, err)) return cdm::fail(CDM_ERR_PARSE, err);
        cdm::api::JobInputs in;
        if (int rc = cdm::api::open_job_data(data_csv_path, calibration.geometry(), in)) return rc;
        cdm::FitCalibrationOptions opt;
        opt.check = &calibration;
        opt.jig_tolerance_mm = a.jig_tolerance_mm;
        if (progress)
            opt.progress = [&](const std::string &s, double f) { return progress(user, s.c_str(), f) == 0; };
        cdm::CalibrationFit cf(calibration.geometry());
        if (!cdm::fit_calibration(in.data, calibration.geometry(), opt, cf, err))
            return cdm::fail(CDM_ERR_INVALID_ARG, err);
        return cdm::api::return_json(result_json(cf, in.data, fitted, calibration, cov, a.max_error_mm), "cdm_check", result_json_out);
    });
}
