// extern "C" experimental entry points the `cdm` command needs beyond the
// stable API (cdm.h, "experimental: tools"): the device's raw info report,
// the simulator's truth, recordings, the jig plan, the effect catalogue and
// jig-dataset simulation. Thin fences around the modules: no logic of their
// own beyond argument checks.
#include <array>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <unistd.h>

#include "api/errors.h"
#include "io/calibration_json.h"
#include "io/device_json.h"
#include "io/file.h"
#include "jig/plan.h"
#include "jig/planned.h"
#include "calib/dataset/simulate.h"
#include "cdm/cdm.h"
#include "device/device.h"
#include "device/recording/recording.h"
#include "device/recording/replay_format.h"
#include "device/sim/sim_truth.h"
#include "device/transport.h"
#include "model/effect.h"
#include "model/model.h"

struct cdm_recorder {
    std::unique_ptr<cdm::recording::Writer> writer;
};

struct cdm_jig_plan {
    cdm::JigPlanOptions options;
    std::vector<cdm::JigPosition> positions; // the whole plate
    // A planned session's visits (cdm_jig_plan_use_file); empty: every
    // position of the plate, options.samples each.
    std::vector<cdm::PlannedVisit> visits;
    std::vector<cdm::PlanRow> uri_plan; // a sim: URI's jig_plan rows, if any
    bool sim = false;                   // made for a sim: URI (which walks its own plan)
};

namespace {

int null_arg(const char *fn, const char *arg) {
    return cdm::fail(CDM_ERR_INVALID_ARG, std::string(fn) + ": " + arg + " is NULL");
}

// The jig_* options of a sim: URI, with the simulator's own ranges (the
// same helpers the sim transport validates them with).
int jig_options_from_uri(const std::string &text, cdm::JigPlanOptions &o, bool &is_sim,
                         std::vector<cdm::PlanRow> &plan_rows, std::string &err) {
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
        } else if (kv.first == "jig_plan") {
            std::string perr;
            ok = cdm::read_plan_csv(kv.second, plan_rows, perr);
            if (!ok) err = "URI \"" + u.text + "\": option jig_plan: " + perr;
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

int to_c_string(const std::string &text, char **out) {
    *out = static_cast<char *>(std::malloc(text.size() + 1));
    if (!*out) return cdm::fail(CDM_ERR_NO_MEM, "out of memory");
    std::memcpy(*out, text.c_str(), text.size() + 1);
    return CDM_OK;
}

struct SimRequest {
    cdm::JigSimOptions o;
    uint64_t effect_seed = 1;
    std::string device, truth, truth_out;
    std::string plan_file; // where "plan" was read from: an input, never written over
    std::vector<std::string> effects;
};

nlohmann::json sim_options_json(const cdm::JigSimOptions &o, uint64_t effect_seed) {
    return {{"holes", o.n},         {"pitch_mm", o.pitch_mm},
            {"heights_mm", o.heights}, {"samples", o.samples},
            {"noise_mm", o.noise_mm}, {"quant_mm", o.quant_mm},
            {"jig_tolerance_mm", o.jig_tolerance_mm}, {"jig_hole_mm", o.jig_hole_mm},
            {"jig_fixture_mm", o.jig_fixture_mm}, {"seed", o.seed},
            {"effect_seed", effect_seed}};
}

// A number option: finite and within [lo, hi], else false + err naming it.
bool number(const nlohmann::json &v, const std::string &key, double lo, double hi, double &out, std::string &err) {
    if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < lo || v.get<double>() > hi) {
        std::ostringstream m;
        m << "option \"" << key << "\" must be a number in [" << lo << ", " << hi << "], not " << v.dump();
        err = m.str();
        return false;
    }
    out = v.get<double>();
    return true;
}

bool parse_sim_options(const char *text, SimRequest &r, std::string &err) {
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(text);
    } catch (const nlohmann::json::parse_error &e) {
        err = "options: " + json_position(text, e.byte) + ": not valid JSON";
        return false;
    }
    if (!j.is_object()) return err = "options must be a JSON object", false;
    for (auto it = j.begin(); it != j.end(); ++it) {
        const std::string &k = it.key();
        const auto &v = it.value();
        double d = 0;
        bool ok = true;
        if (k == "holes") ok = number(v, k, 1, 1000, d, err), r.o.n = int(d);
        else if (k == "pitch_mm") ok = number(v, k, 1e-3, 1000, r.o.pitch_mm, err);
        else if (k == "samples") ok = number(v, k, 1, 1e6, d, err), r.o.samples = int(d);
        else if (k == "noise_mm") ok = number(v, k, 0, 100, r.o.noise_mm, err);
        else if (k == "quant_mm") ok = number(v, k, 0, 100, r.o.quant_mm, err);
        else if (k == "jig_tolerance_mm") ok = number(v, k, 0, 100, r.o.jig_tolerance_mm, err);
        else if (k == "jig_hole_mm") ok = number(v, k, 0, 100, r.o.jig_hole_mm, err);
        else if (k == "jig_fixture_mm") ok = number(v, k, 0, 100, r.o.jig_fixture_mm, err);
        else if (k == "seed") ok = number(v, k, 0, 9007199254740992.0, d, err), r.o.seed = uint64_t(d);
        else if (k == "effect_seed") ok = number(v, k, 0, 9007199254740992.0, d, err), r.effect_seed = uint64_t(d);
        else if (k == "heights_mm" && v.is_array() && !v.empty()) {
            r.o.heights.clear();
            for (const auto &h : v) ok = ok && number(h, "heights_mm", 1e-3, 1e4, d, err) && (r.o.heights.push_back(d), true);
        } else if (k == "plan" && v.is_array()) {
            // [[x_ref, y_ref, z_ref, samples], ...]: a planned session (cdm_plan)
            for (const auto &row : v) {
                std::array<double, 4> q{};
                if (!row.is_array() || row.size() != 4)
                    return err = "option \"plan\": each position is [x_ref, y_ref, z_ref, samples], not " +
                                 row.dump().substr(0, 80), false;
                for (size_t c = 0; c < 4 && ok; ++c)
                    ok = number(row[c], "plan", c == 3 ? 1 : -5000, c == 3 ? 1e6 : 5000, q[c], err);
                r.o.plan.push_back(q);
            }
        } else if (k == "effects" && v.is_array()) {
            for (const auto &e : v) {
                if (!e.is_string()) return err = "option \"effects\" must be a list of effect names", false;
                r.effects.push_back(e.get<std::string>());
            }
        } else if ((k == "device" || k == "truth" || k == "truth_out" || k == "plan_file") && v.is_string()) {
            (k == "device" ? r.device : k == "truth" ? r.truth : k == "truth_out" ? r.truth_out : r.plan_file) =
                v.get<std::string>();
        } else if (k == "heights_mm" || k == "effects" || k == "device" || k == "truth" || k == "truth_out" ||
                   k == "plan" || k == "plan_file") {
            return err = "option \"" + k + "\" has the wrong type: " + v.dump(), false;
        } else {
            return err = "unknown option \"" + k + "\" (known: holes, pitch_mm, heights_mm, samples, noise_mm, "
                         "quant_mm, jig_tolerance_mm, jig_hole_mm, jig_fixture_mm, seed, effect_seed, device, truth, effects, truth_out, "
                         "plan, plan_file)", false;
        }
        if (!ok) return false;
    }
    return true;
}

} // namespace

extern "C" {

int cdm_device_info_report(cdm_device *dev, uint8_t *buf, size_t cap, size_t *len) {
    return cdm::guarded("cdm_device_info_report", [&] {
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
    return cdm::guarded("cdm_sim_truth", [&] {
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
    return cdm_recorder_open_ex(path, nullptr, info_report, len, out);
}

int cdm_recorder_open_ex(const char *path, const char *format, const uint8_t *info_report, size_t len,
                         cdm_recorder **out) {
    return cdm::guarded("cdm_recorder_open", [&] {
        if (!out) return null_arg("cdm_recorder_open", "out");
        *out = nullptr;
        if (!path) return null_arg("cdm_recorder_open", "path");
        if (!info_report) return null_arg("cdm_recorder_open", "info_report");
        if (len == 0)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_recorder_open: info_report is empty (len 0; the device-info "
                                                  "report of cdm_device_info_report, 128 bytes in protocol 1)");
        cdm::recording::Format f = cdm::recording::format_for_path(path);
        std::string compression;
        if (format && !cdm::recording::parse_format(format, f, &compression))
            return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_recorder_open: format \"") + format +
                                                      "\" is not one of cdmrec, mcap (mcap:zstd, mcap:lz4, "
                                                      "mcap:none), csv");
        auto rec = std::make_unique<cdm_recorder>();
        std::string err;
        if (int rc = cdm::recording::open_writer(path, f, info_report, len, rec->writer, err, compression);
            rc != CDM_OK)
            return cdm::fail(rc, err);
        *out = rec.release();
        return int(CDM_OK);
    });
}

int cdm_recorder_write(cdm_recorder *rec, uint64_t host_time_ns, const uint8_t *report, size_t len) {
    return cdm::guarded("cdm_recorder_write", [&] {
        if (!rec) return null_arg("cdm_recorder_write", "rec");
        if (!report) return null_arg("cdm_recorder_write", "report");
        std::string err;
        if (int rc = rec->writer->write(host_time_ns, report, len, nullptr, err); rc != CDM_OK)
            return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_recorder_write_sample(cdm_recorder *rec, const cdm_sample *sample) {
    return cdm::guarded("cdm_recorder_write_sample", [&] {
        if (!rec) return null_arg("cdm_recorder_write_sample", "rec");
        if (!sample || !sample->report || !sample->raw)
            return null_arg("cdm_recorder_write_sample", "sample (or its report, raw)");
        // A sample from a 1.0 library has no source time: its receipt time is the best there is.
        const uint64_t t = sample->struct_size >= offsetof(cdm_sample, source_time_ns) + sizeof(uint64_t)
                               ? sample->source_time_ns
                               : sample->raw->host_time_ns;
        std::string err;
        if (int rc = rec->writer->write(t, sample->report, sample->report_len, sample->pose, err); rc != CDM_OK)
            return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_recorder_write_rejected(cdm_recorder *rec, const cdm_rejected *rejected) {
    return cdm::guarded("cdm_recorder_write_rejected", [&] {
        if (!rec) return null_arg("cdm_recorder_write_rejected", "rec");
        if (!rejected || !rejected->report || !rejected->reason)
            return null_arg("cdm_recorder_write_rejected", "rejected (or its report, reason)");
        if (rejected->struct_size < sizeof(cdm_rejected))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_recorder_write_rejected: cdm_rejected.struct_size is " +
                                                      std::to_string(rejected->struct_size) + ", expected at least " +
                                                      std::to_string(sizeof(cdm_rejected)));
        const char *kind = rejected->kind == CDM_REJECTED_MALFORMED      ? "malformed"
                           : rejected->kind == CDM_REJECTED_OUT_OF_ORDER ? "out_of_order"
                                                                         : nullptr;
        if (!kind)
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_recorder_write_rejected: kind " +
                                                      std::to_string(rejected->kind) + " is not a cdm_rejected_kind");
        std::string err;
        if (int rc = rec->writer->write_rejected(rejected->source_time_ns, rejected->report, rejected->report_len, kind,
                                                 rejected->reason, err);
            rc != CDM_OK)
            return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_recorder_close(cdm_recorder *rec) {
    if (!rec) return CDM_OK;
    std::unique_ptr<cdm_recorder> owned(rec);
    return cdm::guarded("cdm_recorder_close", [&] {
        std::string err;
        if (int rc = owned->writer->close(err); rc != CDM_OK) return cdm::fail(rc, err);
        return int(CDM_OK);
    });
}

int cdm_jig_plan_create(const char *uri, int holes, double pitch_mm, const double *heights_mm, size_t n_heights,
                        int samples, cdm_jig_plan **out) {
    return cdm::guarded("cdm_jig_plan_create", [&] {
        if (!out) return null_arg("cdm_jig_plan_create", "out");
        *out = nullptr;
        auto plan = std::make_unique<cdm_jig_plan>();
        cdm::JigPlanOptions &o = plan->options;
        std::string err;
        bool is_sim = false;
        if (uri) {
            if (int rc = jig_options_from_uri(uri, o, is_sim, plan->uri_plan, err); rc != CDM_OK)
                return cdm::fail(rc, err);
        }
        plan->sim = is_sim;
        const cdm::JigPlanOptions from_uri = o;
        if (holes) o.n = holes;
        if (pitch_mm != 0) o.pitch_mm = pitch_mm;
        if (samples) o.samples = samples;
        if (n_heights) {
            if (!heights_mm) return null_arg("cdm_jig_plan_create", "heights_mm");
            o.heights_mm.assign(heights_mm, heights_mm + n_heights);
        }
        if (is_sim && (o.n != from_uri.n || o.pitch_mm != from_uri.pitch_mm || o.samples != from_uri.samples ||
                       o.heights_mm != from_uri.heights_mm))
            return cdm::fail(CDM_ERR_INVALID_ARG,
                             "the jig options disagree with the simulator's jig_* options in the URI: the labels "
                             "would not match the positions");
        if (!cdm::check_jig_options(o, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        plan->positions = cdm::make_jig_plan(o);
        if (!plan->uri_plan.empty() && !cdm::match_plan(plan->positions, plan->uri_plan, plan->visits, err))
            return cdm::fail(CDM_ERR_INVALID_ARG, "the URI's jig_plan: " + err);
        *out = plan.release();
        return int(CDM_OK);
    });
}

int cdm_plan_file_read(const char *plan_csv, char **rows_json) {
    return cdm::guarded("cdm_plan_file_read", [&] {
        if (!rows_json) return null_arg("cdm_plan_file_read", "rows_json");
        *rows_json = nullptr;
        if (!plan_csv) return null_arg("cdm_plan_file_read", "plan_csv");
        std::vector<cdm::PlanRow> rows;
        std::string err;
        if (!cdm::read_plan_csv(plan_csv, rows, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        nlohmann::json j = nlohmann::json::array();
        for (const cdm::PlanRow &r : rows) j.push_back({r[0], r[1], r[2], r[3]});
        return to_c_string(j.dump(), rows_json);
    });
}

int cdm_jig_plan_use_file(cdm_jig_plan *plan, const char *plan_csv) {
    return cdm::guarded("cdm_jig_plan_use_file", [&] {
        if (!plan) return null_arg("cdm_jig_plan_use_file", "plan");
        if (!plan_csv) return null_arg("cdm_jig_plan_use_file", "plan_csv");
        std::vector<cdm::PlanRow> rows;
        std::vector<cdm::PlannedVisit> visits;
        std::string err;
        if (!cdm::read_plan_csv(plan_csv, rows, err) || !cdm::match_plan(plan->positions, rows, visits, err))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_use_file: " + err);
        if (plan->sim && plan->uri_plan.empty())
            return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_jig_plan_use_file: the sim: URI walks the whole "
                                                              "plate: give it the plan too (jig_plan=") +
                                                      plan_csv + "), or the labels would not match the positions");
        if (!plan->uri_plan.empty() && rows != plan->uri_plan)
            return cdm::fail(CDM_ERR_INVALID_ARG, std::string("cdm_jig_plan_use_file: ") + plan_csv +
                                                      " is not the simulator's jig_plan in the URI: the labels "
                                                      "would not match the positions");
        plan->visits = std::move(visits);
        return int(CDM_OK);
    });
}

size_t cdm_jig_plan_count(const cdm_jig_plan *plan) {
    if (!plan) return 0;
    return plan->visits.empty() ? plan->positions.size() : plan->visits.size();
}

int cdm_jig_plan_samples(const cdm_jig_plan *plan) { return plan ? plan->options.samples : 0; }

int cdm_jig_plan_samples_at(const cdm_jig_plan *plan, size_t i) {
    if (!plan || i >= cdm_jig_plan_count(plan)) return 0;
    return plan->visits.empty() ? plan->options.samples : plan->visits[i].samples;
}

int cdm_jig_plan_plate(const cdm_jig_plan *plan, int *holes, double *pitch_mm, double *heights_mm, size_t cap,
                       size_t *n_heights) {
    if (!plan) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_plate: plan is NULL");
    const cdm::JigPlanOptions &o = plan->options;
    if (holes) *holes = o.n;
    if (pitch_mm) *pitch_mm = o.pitch_mm;
    if (heights_mm)
        for (size_t i = 0; i < cap && i < o.heights_mm.size(); ++i) heights_mm[i] = o.heights_mm[i];
    if (n_heights) *n_heights = o.heights_mm.size();
    return CDM_OK;
}

int cdm_jig_plan_get(const cdm_jig_plan *plan, size_t i, int *point, double ref_mm[3]) {
    if (!plan || !point || !ref_mm)
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_get: plan, point or ref_mm is NULL");
    const size_t n = cdm_jig_plan_count(plan);
    if (i >= n)
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_jig_plan_get: position " + std::to_string(i) + " of " +
                                                  std::to_string(n));
    const cdm::JigPosition &p = plan->positions[plan->visits.empty() ? i : plan->visits[i].index];
    *point = p.point;
    std::memcpy(ref_mm, p.ref, sizeof p.ref);
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

int cdm_effect_param(size_t i, size_t k, const char **name, const char **unit, double *scale, double *lower,
                     double *upper) {
    auto v = cdm::all_effects();
    if (i >= v.size() || k >= v[i]->params.size())
        return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_effect_param: no parameter " + std::to_string(k) + " of effect " +
                                                  std::to_string(i));
    const cdm::ParamDesc &p = v[i]->params[k];
    if (name) *name = p.name.c_str();
    if (unit) *unit = p.unit.c_str();
    if (scale) *scale = p.scale;
    if (lower) *lower = p.lower;
    if (upper) *upper = p.upper;
    return CDM_OK;
}

int cdm_nominal_device_json(char **json) {
    return cdm::guarded("cdm_nominal_device_json", [&] {
        if (!json) return null_arg("cdm_nominal_device_json", "json");
        return to_c_string(cdm::io::device_to_json(cdm::DeviceGeometry{}).dump(2) + "\n", json);
    });
}

int cdm_device_file_read(const char *device_json_path, char **json) {
    return cdm::guarded("cdm_device_file_read", [&] {
        if (!json) return null_arg("cdm_device_file_read", "json");
        *json = nullptr;
        if (!device_json_path) return null_arg("cdm_device_file_read", "device_json_path");
        cdm::DeviceGeometry g;
        std::string err;
        if (!cdm::io::load_device_json(device_json_path, g, err))
            // What could not be read is I/O; what was read and is wrong, the argument.
            return cdm::fail(access(device_json_path, R_OK) != 0 ? CDM_ERR_IO : CDM_ERR_INVALID_ARG, err);
        return to_c_string(cdm::io::device_to_json(g).dump(2) + "\n", json);
    });
}

int cdm_simulate_jig_defaults(char **options_json) {
    return cdm::guarded("cdm_simulate_jig_defaults", [&] {
        if (!options_json) return null_arg("cdm_simulate_jig_defaults", "options_json");
        return to_c_string(sim_options_json(cdm::JigSimOptions{}, 1).dump(), options_json);
    });
}

int cdm_simulate_jig_dataset(const char *out_csv, const char *options_json) {
    return cdm::guarded("cdm_simulate_jig_dataset", [&] {
        if (!out_csv) return null_arg("cdm_simulate_jig_dataset", "out_csv");
        SimRequest req;
        std::string err;
        if (options_json && *options_json && !parse_sim_options(options_json, req, err))
            return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_simulate_jig_dataset: " + err);
        if (!cdm::check_jig_sim(req.o, err)) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_simulate_jig_dataset: " + err);
        cdm::DeviceGeometry g;
        std::string text;
        if (!req.device.empty()) {
            if (!cdm::io::read_file(req.device, cdm::io::kJsonMaxBytes, text, err, "device description"))
                return cdm::fail(CDM_ERR_IO, err);
            if (!cdm::io::parse_device_json(text, req.device, g, err)) return cdm::fail(CDM_ERR_PARSE, err);
        }
        cdm::Model truth(g);
        if (!req.truth.empty()) {
            if (!cdm::io::read_file(req.truth, cdm::io::kJsonMaxBytes, text, err, "calibration"))
                return cdm::fail(CDM_ERR_IO, err);
            if (!cdm::io::parse_calibration_json(text, req.truth, truth, err)) return cdm::fail(CDM_ERR_PARSE, err);
        }
        uint64_t k = 0;
        for (const auto &e : req.effects)
            if (!truth.add_effect_random(e, req.effect_seed + k++, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        std::vector<std::string> inputs;
        if (!req.device.empty()) inputs.push_back(req.device);
        if (!req.truth.empty()) inputs.push_back(req.truth);
        if (!req.plan_file.empty()) inputs.push_back(req.plan_file);
        if (!req.truth_out.empty() &&
            !cdm::io::write_file_atomic(req.truth_out, cdm::io::model_to_json(truth).dump(2) + "\n", inputs, err))
            return cdm::fail(CDM_ERR_IO, err);
        if (!req.truth_out.empty()) inputs.push_back(req.truth_out);
        if (!cdm::simulate_jig_csv(truth, req.o, out_csv, inputs, err)) return cdm::fail(CDM_ERR_IO, err);
        return int(CDM_OK);
    });
}

int cdm_write_file_atomic(const char *path, const void *data, size_t len, const char *const *protect_paths,
                          size_t n_protect) {
    return cdm::guarded("cdm_write_file_atomic", [&] {
        if (!path) return null_arg("cdm_write_file_atomic", "path");
        if (!data && len) return null_arg("cdm_write_file_atomic", "data");
        if (!protect_paths && n_protect) return null_arg("cdm_write_file_atomic", "protect_paths");
        std::vector<std::string> protect;
        for (size_t i = 0; i < n_protect; ++i)
            if (protect_paths[i]) protect.emplace_back(protect_paths[i]);
        std::string err;
        const std::string bytes(static_cast<const char *>(data), len);
        if (!cdm::io::write_file_atomic(path, bytes, protect, err)) return cdm::fail(CDM_ERR_IO, err);
        return int(CDM_OK);
    });
}

} // extern "C"
