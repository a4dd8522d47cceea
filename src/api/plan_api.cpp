// extern "C" cdm_plan: a jig session planned before any data. Thin: the
// logic is calib/plan's plan_session().
#include <array>
#include <cmath>
#include <sstream>

#include <nlohmann/json.hpp>

#include "api/errors.h"
#include "api/jobs.h"
#include "calib/plan/plan.h"
#include "cdm/cdm.h"
#include "io/device_json.h"
#include "io/file.h"

namespace {

using nlohmann::json;

// A number option within [lo, hi] (whole when `whole`), else false + err.
bool number(const json &v, const std::string &k, double lo, double hi, bool whole, double &out, std::string &err) {
    if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < lo || v.get<double>() > hi ||
        (whole && v.get<double>() != std::floor(v.get<double>()))) {
        std::ostringstream m;
        m << "cdm_plan options: \"" << k << "\" must be " << (whole ? "a whole number" : "a number") << " in [" << lo
          << ", " << hi << "], not " << v.dump().substr(0, 60);
        err = m.str();
        return false;
    }
    out = v.get<double>();
    return true;
}

// A list of positions: [x, y, z] or [x, y, z, samples] (a plan's rows, whose
// samples are not read) in mm, the jig frame.
bool positions(const json &v, const std::string &k, std::vector<std::array<double, 3>> &out, std::string &err) {
    if (k == "allowed" && v.empty()) // not "no restriction": leave the option out for that
        return err = "cdm_plan options: \"allowed\" is empty: no position could be chosen", false;
    for (size_t i = 0; i < v.size(); ++i) {
        const json &r = v[i];
        bool ok = r.is_array() && (r.size() == 3 || r.size() == 4);
        for (size_t c = 0; ok && c < 3; ++c) ok = r[c].is_number() && std::isfinite(r[c].get<double>());
        if (!ok) {
            err = "cdm_plan options: \"" + k + "\"[" + std::to_string(i) +
                  "] must be [x, y, z] or [x, y, z, samples] in mm, not " + r.dump().substr(0, 60);
            return false;
        }
        out.push_back({r[0].get<double>(), r[1].get<double>(), r[2].get<double>()});
    }
    return true;
}

bool parse(const char *text, cdm::PlanOptions &o, std::string &device, std::string &err) {
    const json j = json::parse(text ? text : "", nullptr, false);
    if (!j.is_object()) return err = "cdm_plan options must be a JSON object with \"positions\"", false;
    if (!j.contains("positions")) return err = "cdm_plan options: \"positions\" is required", false;
    o.jig.samples = 100; // the seed's, per position
    for (auto it = j.begin(); it != j.end(); ++it) {
        const std::string &k = it.key();
        const json &v = it.value();
        double d = 0;
        bool ok = true;
        if (k == "positions") ok = number(v, k, 1, 1e6, true, d, err), o.positions = int(d);
        else if (k == "samples") ok = number(v, k, 1, 1e6, true, d, err), o.jig.samples = int(d);
        else if (k == "holes") ok = number(v, k, 1, 1000, true, d, err), o.jig.n = int(d);
        else if (k == "pitch_mm") ok = number(v, k, 1e-3, 1000, false, o.jig.pitch_mm, err);
        else if (k == "noise_mm") ok = number(v, k, 1e-6, 100, false, o.noise_mm, err);
        else if (k == "jig_tolerance_mm") ok = number(v, k, 0, 100, false, o.jig_tolerance_mm, err);
        else if (k == "alpha") ok = number(v, k, 1e-12, 0.5, false, o.alpha, err);
        else if (k == "power") ok = number(v, k, 0.01, 0.999999, false, o.power, err);
        else if (k == "heights_mm" && v.is_array() && !v.empty()) {
            o.jig.heights_mm.clear();
            for (const auto &h : v)
                ok = ok && number(h, k, 1e-3, 1e4, false, d, err) && (o.jig.heights_mm.push_back(d), true);
        } else if (k == "effects" && v.is_array()) {
            for (const auto &e : v) {
                if (!e.is_string()) return err = "cdm_plan options: \"effects\" must be a list of effect names", false;
                o.effects.push_back(e.get<std::string>());
            }
        } else if ((k == "measured" || k == "allowed") && v.is_array()) {
            ok = positions(v, k, k == "measured" ? o.measured : o.allowed, err);
        } else if (k == "device" && v.is_string()) {
            device = v.get<std::string>();
        } else {
            return err = "cdm_plan options: unknown option or wrong type: \"" + k +
                         "\" (known: positions, samples, holes, pitch_mm, heights_mm, effects, noise_mm, "
                         "jig_tolerance_mm, alpha, power, measured, allowed, device)",
                   false;
        }
        if (!ok) return false;
    }
    return true;
}

json plan_json(const cdm::PlanOptions &o, const cdm::PlanResult &r) {
    json rows = json::array(), points = json::array();
    for (const auto &p : r.chosen) {
        rows.push_back({p.ref[0], p.ref[1], p.ref[2], r.samples});
        points.push_back(p.point);
    }
    json power = json::array();
    for (const auto &e : r.power)
        power.push_back({{"effect", e.name}, {"dof", e.dof}, {"lambda", e.lambda}, {"power", e.power},
                         {"lambda_whole_plate", e.lambda_all}, {"power_whole_plate", e.power_all},
                         {"detectable", e.power >= o.power},
                         {"reachable", e.power_all >= o.power}});
    json excluded = json::array();
    for (const auto &[n, why] : r.excluded) excluded.push_back({{"effect", n}, {"why", why}});
    const size_t plate = o.jig.heights_mm.size() * size_t(o.jig.n) * size_t(o.jig.n);
    return {{"positions", rows},
            {"points", points},
            {"samples", r.samples},
            {"plate_positions", plate},
            {"measured", o.measured.size()},
            {"design", {{"effects", r.effects}, {"excluded", excluded}, {"detectability_picks", r.detect_picks}}},
            {"predicted_sigma_mm", {{"plan", r.sigma_mm}, {"whole_plate", r.sigma_all_mm}}},
            {"detectability", power},
            {"test", "each effect's likelihood-ratio test against the jig's placement and the fixture heights' "
                     "offsets alone at level alpha, its power at the effect's typical size from the non-central "
                     "chi-square (non-centrality: the information the positions give on the effect beyond them)"},
            {"alpha", o.alpha},
            {"target_power", o.power},
            {"order", "height by height (lowest first), rows along y, each row's holes along z back and forth"}};
}

} // namespace

extern "C" int cdm_plan(const char *options_json, cdm_progress_fn progress, void *user, char **result_json) {
    return cdm::guarded("cdm_plan", [&]() -> int {
        if (!result_json) return cdm::fail(CDM_ERR_INVALID_ARG, "cdm_plan: result_json is NULL");
        *result_json = nullptr;
        cdm::PlanOptions o;
        std::string device, err;
        if (!parse(options_json, o, device, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        cdm::DeviceGeometry g;
        if (!device.empty()) {
            std::string text;
            if (!cdm::io::read_file(device, cdm::io::kJsonMaxBytes, text, err, "device description"))
                return cdm::fail(CDM_ERR_IO, err);
            if (!cdm::io::parse_device_json(text, device, g, err)) return cdm::fail(CDM_ERR_PARSE, err);
        }
        if (progress) o.progress = [&](double f) { return progress(user, "planning", f) == 0; };
        cdm::PlanResult r;
        if (!cdm::plan_session(g, o, r, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
        return cdm::api::return_json(plan_json(o, r), "cdm_plan", result_json);
    });
}
