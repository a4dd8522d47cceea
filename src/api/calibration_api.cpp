// extern "C": calibrations, user effects, the diagnosis. Thin: the logic is
// in model/, io/ and calib/. Every entry point that can fail runs inside
// cdm::guarded(), so no exception reaches a C caller.
#include <dlfcn.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "api/calibration_handle.h"
#include "api/errors.h"
#include "api/jobs.h"
#include "calib/diagnosis/diagnose.h"
#include "calib/evaluation/accuracy.h"
#include "io/calibration_json.h"
#include "io/device_json.h"
#include "io/file.h"
#include "model/effect.h"

namespace {

int parse_calibration(const std::string &text, const std::string &source, cdm_calibration **out) {
    std::string err;
    cdm::Model m{cdm::DeviceGeometry{}};
    if (!cdm::io::parse_calibration_json(text, source, m, err)) return cdm::fail(CDM_ERR_PARSE, err);
    // The covariance, checked against the model it is for (the text is
    // valid JSON: parse_calibration_json read it).
    Eigen::MatrixXd cov;
    const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
    if (j.is_object() && j.contains("fit") && j["fit"].is_object() && j["fit"].contains("covariance") &&
        !j["fit"]["covariance"].is_null() && !cdm::diag::covariance_from_json(j["fit"]["covariance"], m, cov, err))
        return cdm::fail(CDM_ERR_PARSE, source + ": " + err);
    *out = new cdm_calibration{std::make_shared<const cdm::Model>(m), std::move(cov)};
    return CDM_OK;
}

int diagnose_body(const char *data_csv_path, const char *device_json_path, const char *options_json,
                  cdm_progress_fn progress, void *user, char **result_json) {
    cdm::api::JobArgs a;
    if (int rc = cdm::api::parse_job_options(options_json, "cdm_diagnose", cdm::api::JobKind::Diagnosis, a)) return rc;
    cdm::DiagnoseOptions opt;
    opt.effects = a.effects;
    opt.jig_tolerance_mm = a.jig_tolerance_mm;
    opt.candidates = a.candidates;
    opt.search = a.search;
    opt.validation = a.validation;
    opt.per_position = a.per_position;
    opt.outliers = a.outliers;
    if (progress) opt.progress = [&](const std::string &s, double f) { return progress(user, s.c_str(), f) == 0; };
    cdm::api::JobInputs in;
    if (int rc = cdm::api::open_job(data_csv_path, device_json_path, a, in)) return rc;
    nlohmann::json out;
    cdm::Model fitted(in.geometry);
    std::string err;
    if (!cdm::diagnose(in.data, in.geometry, opt, out, fitted, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
    if (int rc = cdm::api::commit_calibration(in, fitted, data_csv_path, out["error_mm"], out["data"]["outliers"],
                                              out["data"]["glitches"], out["covariance"]))
        return rc;
    return cdm::api::return_json(out, "cdm_diagnose", result_json);
}

} // namespace

struct cdm_dataset_writer {
    cdm::DatasetWriter w;
};

extern "C" {

int cdm_calibration_load(const char *path, cdm_calibration **out) {
    return cdm::guarded("cdm_calibration_load", [&]() -> int {
        if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_load: out is NULL");
        *out = nullptr;
        if (!path) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_load: path is NULL");
        std::string text, err;
        if (!cdm::io::read_file(path, cdm::io::kJsonMaxBytes, text, err, "calibration"))
            return cdm::fail(CDM_ERR_IO, err);
        return parse_calibration(text, path, out);
    });
}

int cdm_calibration_parse(const char *json, size_t len, cdm_calibration **out) {
    return cdm::guarded("cdm_calibration_parse", [&]() -> int {
        if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_parse: out is NULL");
        *out = nullptr;
        if (!json) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_parse: json is NULL");
        if (len > cdm::io::kJsonMaxBytes)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_parse: text of " + std::to_string(len) +
                                                      " bytes is over the 64 MiB limit");
        return parse_calibration(std::string(json, len), "(calibration text)", out);
    });
}

void cdm_calibration_free(cdm_calibration *cal) { delete cal; }

int cdm_calibration_position(const cdm_calibration *cal, const double lengths_mm[4], double position_mm[3]) {
    return cdm::guarded("cdm_calibration_position", [&]() -> int {
        if (!cal || !lengths_mm || !position_mm)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_position: NULL argument");
        double p[3];
        if (cal->model->position(lengths_mm, p) != 0)
            return cdm::fail(CDM_ERR_NUMERIC, "cdm_calibration_position: no position gives these lengths");
        for (int k = 0; k < 3; ++k) position_mm[k] = p[k];
        return CDM_OK;
    });
}

int cdm_calibration_position_covariance(const cdm_calibration *cal, const double position_mm[3],
                                        double cov_mm2[9]) {
    return cdm::guarded("cdm_calibration_position_covariance", [&]() -> int {
        if (!cal || !position_mm || !cov_mm2)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_position_covariance: NULL argument");
        for (int k = 0; k < 3; ++k)
            if (!std::isfinite(position_mm[k]))
                return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_position_covariance: position_mm[" +
                                                          std::to_string(k) + "] is not finite");
        if (cal->cov.size() == 0)
            return cdm::fail(CDM_ERR_UNSUPPORTED, "cdm_calibration_position_covariance: the calibration carries "
                                                  "no covariance (its fit block has none): fit it with `cdm calib "
                                                  "fit` or cdm_fit to get one");
        std::vector<Eigen::Matrix3d> c;
        std::vector<char> ok;
        std::string err;
        if (!cdm::diag::position_covariances(*cal->model, cal->cov, {Eigen::Vector3d(position_mm[0], position_mm[1],
                                                                                    position_mm[2])},
                                             0.0, c, ok, err))
            return cdm::fail(CDM_ERR_NUMERIC, "cdm_calibration_position_covariance: " + err);
        if (!ok[0])
            return cdm::fail(CDM_ERR_NUMERIC, "cdm_calibration_position_covariance: the model cannot place this "
                                              "position (outside its workspace)");
        for (int r = 0; r < 3; ++r)
            for (int k = 0; k < 3; ++k) cov_mm2[3 * r + k] = c[0](r, k);
        return CDM_OK;
    });
}

int cdm_calibration_lengths(const cdm_calibration *cal, const double position_mm[3], double lengths_mm[4]) {
    return cdm::guarded("cdm_calibration_lengths", [&]() -> int {
        if (!cal || !lengths_mm || !position_mm)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_lengths: NULL argument");
        double l[4];
        if (cal->model->readings(position_mm, l) != 0)
            return cdm::fail(CDM_ERR_NUMERIC, "cdm_calibration_lengths: a user effect of the calibration failed at "
                                              "this position");
        for (int k = 0; k < 4; ++k)
            if (!std::isfinite(l[k]))
                return cdm::fail(CDM_ERR_NUMERIC, "cdm_calibration_lengths: non-finite length at this position");
        for (int k = 0; k < 4; ++k) lengths_mm[k] = l[k];
        return CDM_OK;
    });
}

size_t cdm_calibration_effect_count(const cdm_calibration *cal) { return cal ? cal->model->effect_count() : 0; }

const char *cdm_calibration_effect_name(const cdm_calibration *cal, size_t i) {
    if (!cal || i >= cal->model->effect_count()) return nullptr;
    return cal->model->effect_name(i).c_str();
}

int cdm_effect_register(const cdm_effect_def *def) {
    return cdm::guarded("cdm_effect_register", [&]() -> int {
        std::string err;
        int rc = cdm::register_user_effect(def, err);
        return rc == CDM_OK ? rc : cdm::fail(rc, err);
    });
}

int cdm_effect_unregister(const char *name) {
    return cdm::guarded("cdm_effect_unregister", [&]() -> int {
        if (!name) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_unregister: name is NULL");
        std::string err;
        int rc = cdm::unregister_user_effect(name, err);
        return rc == CDM_OK ? rc : cdm::fail(rc, err);
    });
}

int cdm_effect_load_plugin(const char *path) {
    cdm::clear_thread_error();
    if (!path) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_load_plugin: path is NULL");
    // A name without a slash would be looked up along LD_LIBRARY_PATH, the
    // rpath and the system directories: whoever controls those picks the
    // code. Only a path (./x.so, /opt/x.so) names one file.
    if (!std::strchr(path, '/'))
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_effect_load_plugin: \"") + path +
                                                  "\" is a bare name; give a path (e.g. ./" + path +
                                                  "), the dynamic linker's search path is not used");
    void *h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!h) return cdm::fail(CDM_ERR_IO, std::string(path) + ": cannot load plugin: " + dlerror());
    using init_fn = int (*)(int (*)(const cdm_effect_def *));
    auto init = reinterpret_cast<init_fn>(dlsym(h, "cdm_plugin_init"));
    if (!init) {
        dlclose(h);
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string(path) + ": no symbol cdm_plugin_init");
    }
    auto effect_names = [] {
        std::vector<std::string> v;
        for (const auto &e : cdm::all_effects()) v.push_back(e->name);
        return v;
    };
    const std::vector<std::string> before = effect_names();
    // The effects the init registers come from this file: their origin is
    // its absolute path (what a calibration written with them names).
    char *abs = realpath(path, nullptr);
    const std::string origin = abs ? abs : path;
    std::free(abs);
    cdm::set_registering_origin(origin.c_str());
    const int rc = init(cdm_effect_register);
    cdm::set_registering_origin(nullptr);
    if (rc != CDM_OK) {
        const std::string why = cdm_thread_error();
        // Effects a failed init registered point into the library: remove
        // them before it goes.
        for (const std::string &name : effect_names())
            if (std::find(before.begin(), before.end(), name) == before.end()) cdm_effect_unregister(name.c_str());
        dlclose(h);
        return cdm::fail(rc, std::string(path) + ": cdm_plugin_init failed (library unloaded): " + why);
    }
    // A successful plugin stays loaded for the life of the process: its
    // effects' apply functions live in it.
    return CDM_OK;
}

size_t cdm_effect_count(void) {
    try {
        return cdm::all_effects().size();
    } catch (...) {
        return 0; // no memory for the snapshot: report none rather than throw into C
    }
}

const char *cdm_effect_name(size_t i) {
    try {
        auto v = cdm::all_effects();
        if (i >= v.size()) return nullptr;
        // Descriptors are immutable and kept alive by the registry (built-ins
        // forever; a user effect until it is unregistered).
        return v[i]->name.c_str();
    } catch (...) {
        return nullptr;
    }
}

int cdm_effect_fingerprint(size_t i, char *buf, size_t len, const char **origin) {
    return cdm::guarded("cdm_effect_fingerprint", [&]() -> int {
        auto v = cdm::all_effects();
        if (i >= v.size())
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_fingerprint: no effect " + std::to_string(i) + " of " +
                                                      std::to_string(v.size()));
        const std::string fp = v[i]->is_user() ? v[i]->fingerprint : cdm::effect_fingerprint(*v[i]);
        if (buf) {
            if (len < fp.size() + 1)
                return cdm::fail(CDM_ERR_NO_MEM, "cdm_effect_fingerprint: buf needs " + std::to_string(fp.size() + 1) +
                                                     " bytes, got " + std::to_string(len));
            std::memcpy(buf, fp.c_str(), fp.size() + 1);
        }
        // Kept alive by the registry, as cdm_effect_name's.
        if (origin) *origin = v[i]->origin.c_str();
        return CDM_OK;
    });
}

int cdm_diagnose(const char *data_csv_path, const char *device_json_path, const char *options_json,
                 cdm_progress_fn progress, void *user, char **result_json) {
    return cdm::guarded("cdm_diagnose", [&]() -> int {
        if (!result_json) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_diagnose: result_json is NULL");
        *result_json = nullptr;
        if (!data_csv_path || !device_json_path)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_diagnose: data and device paths are required");
        return diagnose_body(data_csv_path, device_json_path, options_json, progress, user, result_json);
    });
}

void cdm_free_string(char *s) { std::free(s); }

int cdm_dataset_writer_open(const char *path, const char *const *protect_paths, size_t n_protect,
                            cdm_dataset_writer **out) {
    return cdm::guarded("cdm_dataset_writer_open", [&]() -> int {
        if (!out || !path || (n_protect && !protect_paths))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_dataset_writer_open: NULL argument");
        *out = nullptr;
        std::vector<std::string> protect;
        for (size_t k = 0; k < n_protect; ++k)
            if (protect_paths[k]) protect.emplace_back(protect_paths[k]);
        auto w = std::make_unique<cdm_dataset_writer>();
        std::string err;
        if (!w->w.open(path, protect, err)) return cdm::fail(CDM_ERR_IO, err);
        *out = w.release();
        return CDM_OK;
    });
}

int cdm_dataset_writer_add(cdm_dataset_writer *w, int point, const double ref_mm[3], const double lengths_mm[4]) {
    return cdm::guarded("cdm_dataset_writer_add", [&]() -> int {
        if (!w || !ref_mm || !lengths_mm) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_dataset_writer_add: NULL argument");
        std::string err;
        bool usage = false;
        if (!w->w.add_row(long(point), ref_mm, lengths_mm, err, NAN, &usage))
            return cdm::fail(usage ? CDM_ERR_INVALID_ARG : CDM_ERR_IO, err);
        return CDM_OK;
    });
}

int cdm_dataset_writer_add_at(cdm_dataset_writer *w, int point, const double ref_mm[3], const double lengths_mm[4],
                              double t_s) {
    return cdm::guarded("cdm_dataset_writer_add_at", [&]() -> int {
        if (!w || !ref_mm || !lengths_mm)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_dataset_writer_add_at: NULL argument");
        if (!std::isfinite(t_s))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_dataset_writer_add_at: t_s must be finite");
        std::string err;
        bool usage = false;
        if (!w->w.add_row(long(point), ref_mm, lengths_mm, err, t_s, &usage))
            return cdm::fail(usage ? CDM_ERR_INVALID_ARG : CDM_ERR_IO, err);
        return CDM_OK;
    });
}

int cdm_dataset_writer_commit(cdm_dataset_writer *w) {
    return cdm::guarded("cdm_dataset_writer_commit", [&]() -> int {
        if (!w) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_dataset_writer_commit: NULL writer");
        std::string err;
        bool usage = false;
        if (!w->w.commit(err, &usage)) return cdm::fail(usage ? CDM_ERR_INVALID_ARG : CDM_ERR_IO, err);
        return CDM_OK;
    });
}

void cdm_dataset_writer_free(cdm_dataset_writer *w) { delete w; }

} // extern "C"
