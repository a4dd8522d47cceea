// extern "C" cdm_fit: the calibration fit without the diagnosis (no
// candidates, no review, no validation). Thin: the logic is fit_calibration().
#include <algorithm>

#include "api/errors.h"
#include "api/jobs.h"
#include "calib/evaluation/accuracy.h"
#include "calib/evaluation/stats.h"
#include "calib/diagnosis/diagnose.h"
#include "calib/calibration/fit_calibration.h"
#include "calib/calibration/fit_outliers.h"
#include "cdm/cdm.h"
#include "model/effect.h"

namespace {

using nlohmann::json;

json result_json(const cdm::CalibrationFit &cf, const cdm::Dataset &data, const json &outliers) {
    json eff = json::array();
    for (size_t k = 0; k < cf.model.effect_count(); ++k) {
        const auto &d = cf.model.effect_desc(k);
        const auto &pv = cf.model.effect_params(k);
        json pj = json::object();
        for (size_t q = 0; q < pv.size(); ++q) {
            const auto &sd = cf.report.std;
            const double s = (k < sd.size() && q < sd[k].size()) ? sd[k][q] : 0.0;
            pj[d.params[q].name] = {{"value", pv[q]}, {"std", s}, {"unit", d.params[q].unit}};
        }
        eff.push_back({{"name", d.name}, {"params", pj}});
    }
    // the reading-space fit's: its own parameters and the fixture heights' offsets
    const int dof = std::max(1, cf.report.n_obs - cf.report.n_free - cf.report.n_fixture);
    // Whether the fitted effects explain the data, by the diagnosis's own
    // two tests (judge: the position chi-square against the noise and the
    // jig, and the spatial structure), so that a fit of the wrong effects is
    // not reported only as "converged". Candidates are not tried here.
    const cdm::diag::Verdict v =
        cdm::diag::judge(cf.fitted, cf.grid, cf.jig, cf.report.n_free, cf.fit_options.hole_sigma);
    const std::string text = cdm::diag::fit_check_words(v);
    json check = {{"explained", v.explained},
                  {"chi2_per_dof", v.chi2 / v.dof},
                  {"chi2_p_value", v.chi2_p},
                  {"chi2_scale", v.chi2_scale},
                  {"structure", {{"statistic", v.moran_z}, {"p_value", v.moran_p}, {"variance_scale", v.moran_scale}}},
                  {"test", "the diagnosis's: position chi-square against noise + jig tolerance and Moran's I of the "
                           "residual over the plate, each at p >= 1e-3"},
                  {"text", text}};
    return {{"effects", eff},
            {"model_check", check},
            {"fit",
             {{"converged", cf.report.converged}, {"chi2", cf.report.chi2}, {"dof", dof},
              {"n_free", cf.report.n_free}, {"evaluations", cf.report.evals}, {"seconds", cf.report.seconds},
              {"algorithm", cf.report.algorithm}, {"message", cf.report.message}}},
            {"jig_tolerance_mm", {cf.jig(0), cf.jig(1), cf.jig(2)}},
            // The part of it each plate hole shares at every height (since 1.1).
            {"plate_holes_mm", {cf.fit_options.hole_sigma(0), cf.fit_options.hole_sigma(1), cf.fit_options.hole_sigma(2)}},
            // Each reading's own white error beyond the pots' noise (since 1.1).
            {"reading_noise_mm", cdm::diag::reading_noise_json(cf.reading)},
            {"nominal_error_mm", cdm::diag::stats3(cf.nominal.err)},
            {"error_mm", cdm::diag::stats3(cf.fitted.err)},
            // The predicted error over the workspace and what it comes from (since 1.2).
            {"accuracy_map", cdm::diag::accuracy_map_json(cf.model, cf.report, cf.pos, cf.grid)},
            {"covariance", cdm::diag::covariance_json(cf.model, cf.report.cov_by_hole)},
            // The samples the dataset's screen set aside (the diagnosis' data.glitches).
            {"glitches", cdm::glitches_json(data)},
            // The positions set aside (the diagnosis' data.outliers, the same test).
            {"outliers", outliers}};
}

} // namespace

extern "C" int cdm_fit(const char *data_csv_path, const char *device_json_path, const char *options_json,
                       cdm_progress_fn progress, void *user, char **result_json_out) {
    return cdm::guarded("cdm_fit", [&]() -> int {
        if (!result_json_out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: result_json is NULL");
        *result_json_out = nullptr;
        if (!data_csv_path || !device_json_path)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: data and device paths are required");
        cdm::api::JobArgs a;
        if (int rc = cdm::api::parse_job_options(options_json, "cdm_fit", cdm::api::JobKind::Fit, a)) return rc;
        cdm::FitCalibrationOptions opt;
        opt.effects = a.effects;
        opt.jig_tolerance_mm = a.jig_tolerance_mm;
        if (progress)
            opt.progress = [&](const std::string &s, double f) { return progress(user, s.c_str(), f) == 0; };
        cdm::api::JobInputs in;
        if (int rc = cdm::api::open_job(data_csv_path, device_json_path, a, in)) return rc;
        cdm::CalibrationFit cf(in.geometry);
        std::string err;
        auto round = [&](const cdm::Dataset &d, size_t already, size_t read, std::vector<cdm::diag::Outlier> &found,
                         cdm::diag::Declined &declined, std::string &e) {
            cf = cdm::CalibrationFit(in.geometry);
            if (!cdm::fit_calibration(d, in.geometry, opt, cf, e)) return false;
            if (a.outliers) found = cdm::calibration_outliers(cf, already, read, declined);
            return true;
        };
        json outliers;
        if (!cdm::run_setting_aside_outliers(in.data, a.outliers, round, outliers, err))
            return cdm::fail(CDM_ERR_INVALID_ARG, err);
        const json out = result_json(cf, in.data, outliers);
        if (int rc = cdm::api::commit_calibration(in, cf.model, data_csv_path, out["error_mm"], out["outliers"],
                                                  out["glitches"], out["covariance"]))
            return rc;
        return cdm::api::return_json(out, "cdm_fit", result_json_out);
    });
}
