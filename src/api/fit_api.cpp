// extern "C" cdm_fit: the calibration fit without the diagnosis (no
// candidates, no review, no validation). Thin: the logic is fit_calibration().
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include "api/errors.h"
#include "calib/fit_calibration.h"
#include "cdm/cdm.h"
#include "model/effect.h"

namespace {

using nlohmann::json;

// Options: {"effects": [...] (required, non-empty), "jig_tolerance_mm",
// "calibration_out"}. CDM_OK or the error, set as the thread's error text.
int parse_options(const char *options_json, cdm::FitCalibrationOptions &opt, std::string &calib_out) {
    if (!options_json || !*options_json)
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: options with a non-empty \"effects\" list are required");
    json o;
    try {
        o = json::parse(options_json);
    } catch (const json::parse_error &e) {
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_fit: options are not JSON: ") + e.what());
    }
    if (!o.is_object()) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: options must be a JSON object");
    for (auto it = o.begin(); it != o.end(); ++it) {
        const std::string k = it.key();
        if (k == "effects") {
            if (!it->is_array()) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: \"effects\" must be a list");
            for (auto &e : *it) opt.effects.push_back(e.get<std::string>());
        } else if (k == "jig_tolerance_mm") {
            if (!it->is_null()) opt.jig_tolerance_mm = it->get<double>();
            if (!std::isfinite(opt.jig_tolerance_mm))
                return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: \"jig_tolerance_mm\" must be a finite number");
        } else if (k == "calibration_out") {
            if (!it->is_null()) calib_out = it->get<std::string>();
        } else {
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: unknown option \"" + k +
                                                      "\" (known: effects, jig_tolerance_mm, calibration_out)");
        }
    }
    if (opt.effects.empty())
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: \"effects\" is required and must not be empty");
    return CDM_OK;
}

json result_json(const cdm::CalibrationFit &cf) {
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
    const int dof = std::max(1, cf.report.n_obs - cf.report.n_free);
    return {{"effects", eff},
            {"fit",
             {{"converged", cf.report.converged}, {"chi2", cf.report.chi2}, {"dof", dof},
              {"n_free", cf.report.n_free}, {"evaluations", cf.report.evals}, {"seconds", cf.report.seconds},
              {"algorithm", cf.report.algorithm}, {"message", cf.report.message}}},
            {"jig_tolerance_mm", {cf.jig(0), cf.jig(1), cf.jig(2)}},
            {"nominal_error_mm", cdm::diag::stats3(cf.nominal.err)},
            {"error_mm", cdm::diag::stats3(cf.fitted.err)}};
}

} // namespace

extern "C" int cdm_fit(const char *data_csv_path, const char *device_json_path, const char *options_json,
                       cdm_progress_fn progress, void *user, char **result_json_out) {
    cdm::clear_thread_error();
    if (!result_json_out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: result_json is NULL");
    *result_json_out = nullptr;
    if (!data_csv_path || !device_json_path)
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_fit: data and device paths are required");
    try {
        cdm::FitCalibrationOptions opt;
        std::string calib_out;
        if (int rc = parse_options(options_json, opt, calib_out); rc != CDM_OK) return rc;
        if (progress)
            opt.progress = [&](const std::string &s, double f) { return progress(user, s.c_str(), f) == 0; };
        cdm::Dataset data;
        std::string err;
        if (!cdm::load_dataset(data_csv_path, data, err)) return cdm::fail(CDM_ERR_PARSE, err);
        // TODO(merge): the io branch's one read-file and atomic write replace
        // the two stream uses below (calibration_api.cpp's are file-local).
        std::ifstream df(device_json_path);
        if (!df) return cdm::fail(CDM_ERR_IO, std::string(device_json_path) + ": cannot open the device description");
        std::stringstream ds;
        ds << df.rdbuf();
        cdm::DeviceGeometry g;
        if (!cdm::parse_device_json(ds.str(), device_json_path, g, err)) return cdm::fail(CDM_ERR_PARSE, err);
        cdm::CalibrationFit cf(g);
        if (!cdm::fit_calibration(data, g, opt, cf, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        json out = result_json(cf);
        if (!calib_out.empty()) {
            auto cj = cf.model.to_json();
            cj["fit"] = {{"data", data_csv_path}, {"error_mm", out["error_mm"]}};
            const std::string tmp = calib_out + ".tmp";
            {
                std::ofstream f(tmp);
                f << cj.dump(2) << "\n";
                if (!f) return cdm::fail(CDM_ERR_IO, calib_out + ": cannot write the calibration");
            }
            if (std::rename(tmp.c_str(), calib_out.c_str()) != 0)
                return cdm::fail(CDM_ERR_IO, calib_out + ": cannot write the calibration");
        }
        const std::string s = out.dump();
        char *r = static_cast<char *>(std::malloc(s.size() + 1));
        if (!r) return cdm::fail(CDM_ERR_NO_MEM, "out of memory");
        std::memcpy(r, s.c_str(), s.size() + 1);
        *result_json_out = r;
        return CDM_OK;
    } catch (const json::exception &e) {
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_fit: bad option value: ") + e.what());
    } catch (const std::bad_alloc &) {
        return cdm::fail(CDM_ERR_NO_MEM, "out of memory");
    } catch (const std::exception &e) {
        return cdm::fail(CDM_ERR_INTERNAL, e.what());
    }
}
