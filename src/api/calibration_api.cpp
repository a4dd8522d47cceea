// extern "C": calibrations, user effects, the diagnosis. Thin: the logic is
// in model/ and calib/.
#include <dlfcn.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

#include "api/calibration_handle.h"
#include "api/errors.h"
#include "calib/diagnose.h"
#include "model/effect.h"

namespace {

int parse_calibration(const std::string &text, const std::string &source, cdm_calibration **out) {
    nlohmann::json j;
    std::string err;
    if (!cdm::parse_json_text(text, source, j, err)) return cdm::fail(CDM_ERR_PARSE, err);
    cdm::Model m{cdm::DeviceGeometry{}};
    if (!cdm::Model::from_json(j, source, m, err)) return cdm::fail(CDM_ERR_PARSE, err);
    *out = new cdm_calibration{std::make_shared<const cdm::Model>(m)};
    return CDM_OK;
}

bool read_file(const char *path, std::string &text) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return false;
    std::ostringstream ss;
    ss << in.rdbuf();
    text = ss.str();
    return true;
}

} // namespace

extern "C" {

int cdm_calibration_load(const char *path, cdm_calibration **out) {
    cdm::clear_thread_error();
    if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_load: out is NULL");
    *out = nullptr;
    if (!path) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_load: path is NULL");
    try {
        std::string text;
        if (!read_file(path, text)) return cdm::fail(CDM_ERR_IO, std::string(path) + ": cannot open the calibration");
        return parse_calibration(text, path, out);
    } catch (const std::bad_alloc &) {
        return cdm::fail(CDM_ERR_NO_MEM, "out of memory");
    } catch (const std::exception &e) {
        return cdm::fail(CDM_ERR_INTERNAL, e.what());
    }
}

int cdm_calibration_parse(const char *json, size_t len, cdm_calibration **out) {
    cdm::clear_thread_error();
    if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_parse: out is NULL");
    *out = nullptr;
    if (!json) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_calibration_parse: json is NULL");
    try {
        return parse_calibration(std::string(json, len), "(calibration text)", out);
    } catch (const std::exception &e) {
        return cdm::fail(CDM_ERR_INTERNAL, e.what());
    }
}

void cdm_calibration_free(cdm_calibration *cal) { delete cal; }

int cdm_calibration_position(const cdm_calibration *cal, const double lengths_mm[4], double position_mm[3]) {
    if (!cal || !lengths_mm || !position_mm) return CDM_ERR_INVALID_ARG;
    double p[3];
    if (cal->model->position(lengths_mm, p) != 0) return CDM_ERR_NUMERIC;
    for (int k = 0; k < 3; ++k) position_mm[k] = p[k];
    return CDM_OK;
}

int cdm_calibration_lengths(const cdm_calibration *cal, const double position_mm[3], double lengths_mm[4]) {
    if (!cal || !lengths_mm || !position_mm) return CDM_ERR_INVALID_ARG;
    double l[4];
    cal->model->readings(position_mm, l);
    for (int k = 0; k < 4; ++k)
        if (!std::isfinite(l[k])) return CDM_ERR_NUMERIC;
    for (int k = 0; k < 4; ++k) lengths_mm[k] = l[k];
    return CDM_OK;
}

size_t cdm_calibration_effect_count(const cdm_calibration *cal) { return cal ? cal->model->effect_count() : 0; }

const char *cdm_calibration_effect_name(const cdm_calibration *cal, size_t i) {
    if (!cal || i >= cal->model->effect_count()) return nullptr;
    return cal->model->effect_name(i).c_str();
}

int cdm_effect_register(const cdm_effect_def *def) {
    cdm::clear_thread_error();
    try {
        std::string err;
        int rc = cdm::register_user_effect(def, err);
        return rc == CDM_OK ? rc : cdm::fail(rc, err);
    } catch (const std::exception &e) {
        return cdm::fail(CDM_ERR_INTERNAL, e.what());
    }
}

int cdm_effect_unregister(const char *name) {
    cdm::clear_thread_error();
    if (!name) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_unregister: name is NULL");
    std::string err;
    int rc = cdm::unregister_user_effect(name, err);
    return rc == CDM_OK ? rc : cdm::fail(rc, err);
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
    const int rc = init(cdm_effect_register);
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

size_t cdm_effect_count(void) { return cdm::all_effects().size(); }

const char *cdm_effect_name(size_t i) {
    auto v = cdm::all_effects();
    if (i >= v.size()) return nullptr;
    // Descriptors are immutable and kept alive by the registry (built-ins
    // forever; a user effect until it is unregistered).
    return v[i]->name.c_str();
}

int cdm_diagnose(const char *data_csv_path, const char *device_json_path, const char *options_json,
                 cdm_progress_fn progress, void *user, char **result_json) {
    cdm::clear_thread_error();
    if (!result_json) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_diagnose: result_json is NULL");
    *result_json = nullptr;
    if (!data_csv_path || !device_json_path)
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_diagnose: data and device paths are required");
    try {
        cdm::DiagnoseOptions opt;
        std::string calib_out;
        if (options_json && *options_json) {
            nlohmann::json o;
            try {
                o = nlohmann::json::parse(options_json);
            } catch (const nlohmann::json::parse_error &e) {
                return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_diagnose: options are not JSON: ") + e.what());
            }
            for (auto it = o.begin(); it != o.end(); ++it) {
                const std::string k = it.key();
                if (k == "effects") {
                    if (!it->is_array()) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_diagnose: \"effects\" must be a list");
                    for (auto &e : *it) opt.effects.push_back(e.get<std::string>());
                } else if (k == "jig_tolerance_mm") {
                    if (!it->is_null()) opt.jig_tolerance_mm = it->get<double>();
                } else if (k == "candidates") {
                    opt.candidates = it->get<bool>();
                } else if (k == "validation") {
                    opt.validation = it->get<bool>();
                } else if (k == "per_position") {
                    opt.per_position = it->get<bool>();
                } else if (k == "calibration_out") {
                    if (!it->is_null()) calib_out = it->get<std::string>();
                } else {
                    return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_diagnose: unknown option \"" + k +
                                                              "\" (known: effects, jig_tolerance_mm, candidates, "
                                                              "validation, per_position, calibration_out)");
                }
            }
        }
        if (progress)
            opt.progress = [&](const std::string &s, double f) { return progress(user, s.c_str(), f) == 0; };
        cdm::Dataset data;
        std::string err;
        if (!cdm::load_dataset(data_csv_path, data, err)) return cdm::fail(CDM_ERR_PARSE, err);
        std::string dtext;
        if (!read_file(device_json_path, dtext))
            return cdm::fail(CDM_ERR_IO, std::string(device_json_path) + ": cannot open the device description");
        cdm::DeviceGeometry g;
        if (!cdm::parse_device_json(dtext, device_json_path, g, err)) return cdm::fail(CDM_ERR_PARSE, err);
        nlohmann::json out;
        cdm::Model fitted(g);
        if (!cdm::diagnose(data, g, opt, out, fitted, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        if (!calib_out.empty()) {
            auto cj = fitted.to_json();
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
        std::string s = out.dump();
        char *r = static_cast<char *>(std::malloc(s.size() + 1));
        if (!r) return cdm::fail(CDM_ERR_NO_MEM, "out of memory");
        std::memcpy(r, s.c_str(), s.size() + 1);
        *result_json = r;
        return CDM_OK;
    } catch (const nlohmann::json::exception &e) {
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_diagnose: bad option value: ") + e.what());
    } catch (const std::bad_alloc &) {
        return cdm::fail(CDM_ERR_NO_MEM, "out of memory");
    } catch (const std::exception &e) {
        return cdm::fail(CDM_ERR_INTERNAL, e.what());
    }
}

void cdm_free_string(char *s) { std::free(s); }

} // extern "C"
