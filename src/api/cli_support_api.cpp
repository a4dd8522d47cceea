// extern "C" experimental entry points the `cdm` command needs beyond the
// stable API (cdm.h, "experimental: tools"): the device's raw info report,
// the simulator's truth, recordings, the jig plan, the effect catalogue and
// jig-dataset simulation. Thin fences around the modules: no logic of their
// own beyond argument checks.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "api/errors.h"
#include "calib/jig_plan.h"
#include "calib/simulate.h"
#include "cdm/cdm.h"
#include "device/device.h"
#include "device/replay_format.h"
#include "device/sim/sim_truth.h"
#include "device/transport.h"
#include "model/effect.h"
#include "model/model.h"

struct cdm_recorder {
    cdm::replay::Writer writer;
};

struct cdm_jig_plan {
    cdm::JigPlanOptions options;
    std::vector<cdm::JigPosition> positions;
};

namespace {

template <class F>
int fenced(const char *fn, F &&f) {
    cdm::clear_thread_error();
    try {
        return f();
    } catch (const std::bad_alloc &) {
        return cdm::fail(CDM_ERR_NO_MEM, std::string(fn) + ": out of memory");
    } catch (const std::exception &e) {
        return cdm::fail(CDM_ERR_INTERNAL, std::string(fn) + ": internal error: " + e.what());
    } catch (...) {
        return cdm::fail(CDM_ERR_INTERNAL, std::string(fn) + ": internal error");
    }
}

int null_arg(const char *fn, const char *arg) {
    return cdm::fail(CDM_ERR_INVALID_ARG, std::string(fn) + ": " + arg + " is NULL");
}

// The jig_* options of a sim: URI, with the simulator's own ranges (the
// same helpers the sim transport validates them with).
int jig_options_from_uri(const std::string &text, cdm::JigPlanOptions &o, bool &is_sim, std::string &err) {
    cdm::Uri u;
    is_sim = false;
    if (int rc = cdm::parse_uri(text, u, err); rc != CDM_OK) return rc;
    if (u.scheme != "sim") return CDM_OK;
    is_sim = true;
    for (const auto &kv : u.options) {
        uint64_t n = 0;
        bool ok = true;
        if (kv.first == "jig_n") {
            ok = cdm::option_u64(u, kv.first, kv.second, 1, 1000, n, err);
            o.n = int(n);
        } else if (kv.first == "jig_pitch") {
            ok = cdm::option_double(u, kv.first, kv.second, 1e-3, 1000.0, o.pitch_mm, err);
        } else if (kv.first == "jig_samples") {
            ok = cdm::option_u64(u, kv.first, kv.second, 1, 1000000, n, err);
            o.samples = int(n);
        } else if (kv.first == "jig_heights") {
            std::string herr;
            ok = cdm::parse_heights(kv.second, o.heights_mm, herr);
            if (!ok) err = "URI \"" + u.text + "\": option " + herr;
        }
        if (!ok) return CDM_ERR_INVALID_ARG;
    }
    return CDM_OK;
}

// "line L, column C" of a 1-based byte offset (the parser's own text carries
// its internal error code, which means nothing to a user).
std::string json_position(const std::string &text, size_t byte) {
    size_t line = 1, col = 1;
    for (size_t i = 0; i + 1 < byte && i < text.size(); ++i, ++col)
        if (text[i] == '\n') {
            ++line;
            col = 0;
        }
    return "line " + std::to_string(line) + ", column " + std::to_string(col);
}

std::vector<std::string> split_list(const char *s) {
    std::vector<std::string> v;
    if (!s) return v;
    std::stringstream ss(s);
    std::string x;
    while (std::getline(ss, x, ','))
        if (!x.empty()) v.push_back(x);
    return v;
}

} // namespace

extern "C" {

int cdm_device_info_report(cdm_device *dev, uint8_t *buf, size_t cap, size_t *len) {
    return fenced("cdm_device_info_report", [&] {
        if (!dev) return null_arg("cdm_device_info_report", "dev");
        if (!len) return null_arg("cdm_device_info_report", "len");
        uint8_t tmp[1024] = {0x02};
        std::string err;
        const int n = dev->transport().get_feature(tmp, sizeof tmp, err);
        if (n <= 0) return cdm::fail(n < 0 ? n : CDM_ERR_IO, err.empty() ? "no device-info report" : err);
        *len = size_t(n);
        if (!buf || cap < size_t(n))
            return cdm::fail(CDM_ERR_NO_MEM, "cdm_device_info_report: the report is " + std::to_string(n) +
                                                 " bytes, the buffer " + std::to_string(cap));
        std::memcpy(buf, tmp, size_t(n));
        return int(CDM_OK);
    });
}

int cdm_sim_truth(cdm_device *dev, uint32_t sequence, double position_mm[3]) {
    return fenced("cdm_sim_truth", [&] {
        if (!dev) return null_arg("cdm_sim_truth", "dev");
        if (!position_mm) return null_arg("cdm_sim_truth", "position_mm");
        cdm::SimTruth t;
        if (!cdm::sim_truth(dev, sequence, t))
            return cdm::fail(CDM_ERR_UNSUPPORTED, "cdm_sim_truth: not a sim: device, or report " +
                                                      std::to_string(sequence) + " is no longer remembered");
        std::memcpy(position_mm, t.position, sizeof t.position);
        return int(CDM_OK);
    });
}

int cdm_recorder_open(const char *path, const uint8_t *info_report, size_t len, cdm_recorder **out) {
    return fenced("cdm_recorder_open", [&] {
        if (!out) return null_arg("cdm_recorder_open", "out");
        *out = nullptr;
        if (!path) return null_arg("cdm_recorder_open", "path");
        if (!info_report || len == 0) return null_arg("cdm_recorder_open", "info_report");
        auto rec = std::make_unique<cdm_recorder>();
        std::string err;
        if (int rc = rec->writer.open(path, info_report, len, err); rc != CDM_OK) return cdm::fail(rc, err);
        *out = rec.release();
        return int(CDM_OK);
    });
}

int cdm_recorder_write(cdm_recorder *rec, uint64_t host_time_ns, const uint8_t *report, size_t len) {
    return fenced("cdm_recorder_write", [&] {
        if (!rec) return null_arg("cdm_recorder_write", "rec");
        if (!report) return null_arg("cdm_recorder_write", "report");
        std::string err;
        if (int rc = rec->writer.write(host_time_ns, report, len, err); rc != CDM_OK) return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_recorder_close(cdm_recorder *rec) {
    if (!rec) return CDM_OK;
    std::unique_ptr<cdm_recorder> owned(rec);
    return fenced("cdm_recorder_close", [&] {
        std::string err;
        if (int rc = owned->writer.close(err); rc != CDM_OK) return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_jig_plan_create(const char *uri, const cdm_jig_plan_options *options, cdm_jig_plan **out) {
    return fenced("cdm_jig_plan_create", [&] {
        if (!out) return null_arg("cdm_jig_plan_create", "out");
        *out = nullptr;
        if (options && options->struct_size < sizeof(cdm_jig_plan_options))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_create: options->struct_size is too small");
        auto plan = std::make_unique<cdm_jig_plan>();
        cdm::JigPlanOptions &o = plan->options;
        std::string err;
        bool is_sim = false;
        if (uri) {
            if (int rc = jig_options_from_uri(uri, o, is_sim, err); rc != CDM_OK) return cdm::fail(rc, err);
        }
        const cdm::JigPlanOptions from_uri = o;
        if (options) {
            if (options->holes) o.n = options->holes;
            if (options->pitch_mm != 0) o.pitch_mm = options->pitch_mm;
            if (options->samples) o.samples = options->samples;
            if (options->n_heights) {
                if (!options->heights_mm) return null_arg("cdm_jig_plan_create", "options->heights_mm");
                o.heights_mm.assign(options->heights_mm, options->heights_mm + options->n_heights);
            }
        }
        if (is_sim && (o.n != from_uri.n || o.pitch_mm != from_uri.pitch_mm || o.samples != from_uri.samples ||
                       o.heights_mm != from_uri.heights_mm))
            return cdm::fail(CDM_ERR_INVALID_ARG,
                             "the jig options disagree with the simulator's jig_* options in the URI: the labels "
                             "would not match the positions");
        if (!cdm::check_jig_options(o, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        plan->positions = cdm::make_jig_plan(o);
        *out = plan.release();
        return int(CDM_OK);
    });
}

size_t cdm_jig_plan_count(const cdm_jig_plan *plan) { return plan ? plan->positions.size() : 0; }

int cdm_jig_plan_samples(const cdm_jig_plan *plan) { return plan ? plan->options.samples : 0; }

int cdm_jig_plan_get(const cdm_jig_plan *plan, size_t i, cdm_jig_position *out) {
    if (!plan || !out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_get: plan or out is NULL");
    if (i >= plan->positions.size())
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_get: position " + std::to_string(i) + " of " +
                                                  std::to_string(plan->positions.size()));
    const cdm::JigPosition &p = plan->positions[i];
    out->point = p.point;
    out->height_index = p.height_index;
    out->row = p.row;
    out->col = p.col;
    std::memcpy(out->ref_mm, p.ref, sizeof p.ref);
    return CDM_OK;
}

void cdm_jig_plan_free(cdm_jig_plan *plan) { delete plan; }

const char *cdm_effect_doc(size_t i) {
    auto v = cdm::all_effects();
    // Kept alive by the registry, as cdm_effect_name's.
    return i < v.size() ? v[i]->doc.c_str() : nullptr;
}

size_t cdm_effect_param_count(size_t i) {
    auto v = cdm::all_effects();
    return i < v.size() ? v[i]->params.size() : 0;
}

int cdm_effect_param(size_t i, size_t k, cdm_effect_param_info *out) {
    if (!out) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_param: out is NULL");
    auto v = cdm::all_effects();
    if (i >= v.size() || k >= v[i]->params.size())
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_param: no parameter " + std::to_string(k) + " of effect " +
                                                  std::to_string(i));
    const cdm::ParamDesc &p = v[i]->params[k];
    out->name = p.name.c_str();
    out->unit = p.unit.c_str();
    out->scale = p.scale;
    out->lower = p.lower;
    out->upper = p.upper;
    return CDM_OK;
}

int cdm_nominal_device_json(char **json) {
    return fenced("cdm_nominal_device_json", [&] {
        if (!json) return null_arg("cdm_nominal_device_json", "json");
        const std::string text = cdm::device_to_json(cdm::DeviceGeometry{}).dump(2) + "\n";
        *json = static_cast<char *>(std::malloc(text.size() + 1));
        if (!*json) return cdm::fail(CDM_ERR_NO_MEM, "cdm_nominal_device_json: out of memory");
        std::memcpy(*json, text.c_str(), text.size() + 1);
        return int(CDM_OK);
    });
}

void cdm_jig_sim_defaults(cdm_jig_sim_options *o) {
    if (!o) return;
    const cdm::JigSimOptions d;
    std::memset(o, 0, sizeof *o);
    o->struct_size = sizeof *o;
    o->holes = d.n;
    o->pitch_mm = d.pitch_mm;
    o->samples = d.samples;
    o->noise_mm = d.noise_mm;
    o->quant_mm = d.quant_mm;
    o->jig_tolerance_mm = d.jig_tolerance_mm;
    o->seed = d.seed;
    o->effect_seed = 1;
}

int cdm_simulate_jig_dataset(const char *out_csv, const cdm_jig_sim_options *o) {
    return fenced("cdm_simulate_jig_dataset", [&] {
        if (!out_csv) return null_arg("cdm_simulate_jig_dataset", "out_csv");
        if (!o) return null_arg("cdm_simulate_jig_dataset", "options");
        if (o->struct_size < sizeof(cdm_jig_sim_options))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_simulate_jig_dataset: options->struct_size is too small");
        std::string err;
        cdm::DeviceGeometry g;
        if (o->device_json_path) {
            std::ifstream f(o->device_json_path);
            std::stringstream ss;
            ss << f.rdbuf();
            if (!f) return cdm::fail(CDM_ERR_IO, std::string(o->device_json_path) + ": cannot open: " + std::strerror(errno));
            if (!cdm::parse_device_json(ss.str(), o->device_json_path, g, err)) return cdm::fail(CDM_ERR_PARSE, err);
        }
        cdm::Model truth(g);
        if (o->truth_json_path) {
            std::ifstream f(o->truth_json_path);
            std::stringstream ss;
            ss << f.rdbuf();
            if (!f) return cdm::fail(CDM_ERR_IO, std::string(o->truth_json_path) + ": cannot open: " + std::strerror(errno));
            nlohmann::json j;
            try {
                j = nlohmann::json::parse(ss.str());
            } catch (const nlohmann::json::parse_error &e) {
                return cdm::fail(CDM_ERR_PARSE, std::string(o->truth_json_path) + ": " + json_position(ss.str(), e.byte) +
                                                    ": not valid JSON");
            }
            if (!cdm::Model::from_json(j, o->truth_json_path, truth, err)) return cdm::fail(CDM_ERR_PARSE, err);
        }
        uint64_t k = 0;
        for (const auto &e : split_list(o->effects))
            if (!truth.add_effect_random(e, o->effect_seed + k++, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        cdm::JigSimOptions so;
        so.n = o->holes;
        so.pitch_mm = o->pitch_mm;
        if (o->n_heights) {
            if (!o->heights_mm) return null_arg("cdm_simulate_jig_dataset", "options->heights_mm");
            so.heights.assign(o->heights_mm, o->heights_mm + o->n_heights);
        }
        so.samples = o->samples;
        so.noise_mm = o->noise_mm;
        so.quant_mm = o->quant_mm;
        so.jig_tolerance_mm = o->jig_tolerance_mm;
        so.seed = o->seed;
        if (!cdm::simulate_jig_csv(truth, so, out_csv, err)) return cdm::fail(CDM_ERR_IO, err);
        if (o->truth_out_path) {
            const std::string tmp = std::string(o->truth_out_path) + ".tmp";
            std::ofstream f(tmp);
            f << truth.to_json().dump(2) << "\n";
            f.close();
            if (!f || std::rename(tmp.c_str(), o->truth_out_path) != 0)
                return cdm::fail(CDM_ERR_IO, std::string(o->truth_out_path) + ": cannot write: " + std::strerror(errno));
        }
        return int(CDM_OK);
    });
}

} // extern "C"
