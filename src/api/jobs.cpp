// The steps cdm_diagnose and cdm_fit share (jobs.h).
#include "api/jobs.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "api/errors.h"
#include "io/calibration_json.h"
#include "io/device_json.h"
#include "io/json.h"

namespace cdm::api {

namespace {

// More than this fraction of positions whose mean readings the nominal
// triangulation cannot place means the data does not describe this device
// (wrong unit, wrong device file, overflowing means): no diagnosis of it is
// meaningful. Below it, a few edge positions that effects push past the
// nominal spheres are normal and the model's own solver handles them.
constexpr double kMaxUnsolvableFraction = 0.5;

int check_solvable(const cdm::Dataset &d, const cdm::DeviceGeometry &g) {
    size_t bad = 0, nonfinite = 0;
    for (const auto &h : d.pos) {
        double p[3];
        bool fin = true;
        for (double m : h.mean) fin = fin && std::isfinite(m);
        if (!fin) ++nonfinite;
        if (!fin || !cdm::triangulate(g, h.mean, p)) ++bad;
    }
    if (double(bad) <= kMaxUnsolvableFraction * double(d.pos.size())) return CDM_OK;
    return cdm::fail(CDM_ERR_NUMERIC,
                     d.path + ": " + std::to_string(bad) + " of " + std::to_string(d.pos.size()) +
                         " positions (" + std::to_string(d.rows) + " samples) cannot be placed by the nominal "
                         "triangulation (" + std::to_string(nonfinite) + " with non-finite mean readings, the "
                         "rest outside the workspace of this device: the four cable spheres do not meet); more "
                         "than half unsolvable means the data does not match the device description, so no "
                         "diagnosis is given");
}

// Reads and parses an input file, telling a file that cannot be read
// (CDM_ERR_IO: missing, special, too large) from one that is malformed.
int load_device(const char *path, cdm::DeviceGeometry &g) {
    std::string text, err;
    if (!cdm::io::read_file(path, cdm::io::kJsonMaxBytes, text, err, "device description"))
        return cdm::fail(CDM_ERR_IO, err);
    if (!cdm::io::parse_device_json(text, path, g, err)) return cdm::fail(CDM_ERR_PARSE, err);
    return CDM_OK;
}

} // namespace

int parse_job_options(const char *text, const char *fn, JobKind kind, JobArgs &a) {
    const bool diagnosis = kind == JobKind::Diagnosis, check = kind == JobKind::Check;
    const char *known = diagnosis ? "effects, jig_tolerance_mm, candidates, search, validation, per_position, outliers, calibration_out"
                        : check   ? "jig_tolerance_mm, max_error_mm"
                                  : "effects, jig_tolerance_mm, outliers, calibration_out";
    if (!text || !*text) {
        if (kind != JobKind::Fit) return CDM_OK;
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string(fn) + ": options with a non-empty \"effects\" list are required");
    }
    const std::string src = std::string(fn) + " options";
    cdm::io::JsonValue o;
    std::string err;
    if (!cdm::io::parse_json(text, src, o, err)) return cdm::fail(CDM_ERR_INVALID_ARG, err);
    if (o.type != cdm::io::JsonValue::Object)
        return cdm::fail(CDM_ERR_INVALID_ARG, cdm::io::where(src, o) + "options must be a JSON object");
    using J = cdm::io::JsonValue;
    auto bad = [&](const cdm::io::JsonValue &v, const std::string &k, const char *want) {
        // A number out of range is shown as given; anything else by its kind.
        // (shortest form that reads back the same: -0.1, not -0.10000000000000001)
        char num[40];
        char *end = num;
        if (v.type == J::Number) end = std::to_chars(num, num + sizeof num, v.number).ptr;
        return cdm::fail(CDM_ERR_INVALID_ARG, cdm::io::where(src, v) + "option \"" + k + "\" must be " + want +
                                                  ", got " + (v.type == J::Number ? std::string(num, size_t(end - num)) : v.type_name()));
    };
    for (const auto &[k, v] : o.members) {
        if (check && k != "jig_tolerance_mm" && k != "max_error_mm")
            return cdm::fail(CDM_ERR_INVALID_ARG, cdm::io::where(src, v) + "unknown option \"" +
                                                      cdm::io::quote_field(k) + "\" (known: " + known + ")");
        if (check && k == "max_error_mm") {
            if (v.type == J::Null) continue;
            if (v.type != J::Number || !(v.number > 0) || v.number > cdm::kDatasetMaxRefMm)
                return bad(v, k, "a number of mm in (0, 5000]");
            a.max_error_mm = v.number;
        } else if (k == "effects") {
            if (v.type != J::Array) return bad(v, k, "a list of effect names");
            for (const auto &e : v.items) {
                if (e.type != J::String) return bad(e, k, "a list of effect names");
                a.effects.push_back(e.str);
            }
        } else if (k == "jig_tolerance_mm") {
            if (v.type == J::Null) continue;
            if (v.type != J::Number || !(v.number >= 0) || v.number > cdm::kDatasetMaxRefMm)
                return bad(v, k, "a number of mm in 0..5000");
            a.jig_tolerance_mm = v.number;
        } else if (k == "outliers" ||
                   (diagnosis && (k == "candidates" || k == "search" || k == "validation" || k == "per_position"))) {
            if (v.type != J::Bool) return bad(v, k, "true or false");
            (k == "candidates" ? a.candidates
             : k == "search"   ? a.search
             : k == "validation" ? a.validation
             : k == "outliers"   ? a.outliers
                                 : a.per_position) = v.boolean;
        } else if (k == "calibration_out") {
            if (v.type == J::Null) continue;
            if (v.type != J::String) return bad(v, k, "a path");
            // "" would silently write nothing: the caller asked for a file.
            if (v.str.empty()) return bad(v, k, "a path (null or absent for none), not an empty string");
            a.calib_out = v.str;
        } else {
            return cdm::fail(CDM_ERR_INVALID_ARG, cdm::io::where(src, v) + "unknown option \"" +
                                                      cdm::io::quote_field(k) +
                                                      "\" (known: " + known + ")");
        }
    }
    if (kind == JobKind::Fit && a.effects.empty())
        return cdm::fail(CDM_ERR_INVALID_ARG, std::string(fn) + ": \"effects\" is required and must not be empty");
    return CDM_OK;
}


int open_job(const char *data_path, const char *device_path, const JobArgs &a, JobInputs &in) {
    std::string err;
    if (!a.calib_out.empty() && !in.calib_out.open(a.calib_out, {data_path, device_path}, err))
        return cdm::fail(CDM_ERR_IO, err);
    bool io_failure = false;
    if (!cdm::load_dataset(data_path, in.data, err, &io_failure))
        return cdm::fail(io_failure ? CDM_ERR_IO : CDM_ERR_PARSE, err);
    if (int rc = load_device(device_path, in.geometry)) return rc;
    return check_solvable(in.data, in.geometry);
}

int open_job_data(const char *data_path, const DeviceGeometry &g, JobInputs &in) {
    std::string err;
    bool io_failure = false;
    if (!cdm::load_dataset(data_path, in.data, err, &io_failure))
        return cdm::fail(io_failure ? CDM_ERR_IO : CDM_ERR_PARSE, err);
    return check_solvable(in.data, g);
}

int commit_calibration(JobInputs &in, const Model &fitted, const char *data_path, const nlohmann::json &error_mm,
                       const nlohmann::json &outliers, const nlohmann::json &glitches,
                       const nlohmann::json &covariance) {
    if (!in.calib_out.is_open()) return CDM_OK;
    auto cj = cdm::io::model_to_json(fitted);
    nlohmann::json positions = nlohmann::json::array();
    for (const auto &o : outliers.value("set_aside", nlohmann::json::array()))
        positions.push_back({{"point", o.at("point")}, {"ref", o.at("ref")}, {"residual_mm", o.at("residual_mm")}});
    cj["fit"] = {{"data", data_path},
                 {"error_mm", error_mm},
                 {"set_aside",
                  {{"outliers_screened", outliers.value("enabled", false)},
                   {"positions", positions},
                   {"glitch_samples", glitches.value("count", 0)},
                   {"glitch_positions", glitches.value("positions", 0)},
                   {"glitches_listed", glitches.value("samples", nlohmann::json::array())}}},
                 {"covariance", covariance}};
    std::string err;
    // A file name that is not UTF-8 (JSON holds UTF-8 only) is shown with
    // U+FFFD where its bad bytes were: a record of the source, never opened.
    const std::string text = cj.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
    if (!in.calib_out.write(text, err) || !in.calib_out.commit(err)) return cdm::fail(CDM_ERR_IO, err);
    return CDM_OK;
}

int return_json(const nlohmann::json &j, const char *fn, char **out) {
    // The input's name, when it is not UTF-8, with U+FFFD for its bad bytes.
    const std::string s = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    char *r = static_cast<char *>(std::malloc(s.size() + 1));
    if (!r) return cdm::fail(CDM_ERR_NO_MEM, std::string(fn) + ": out of memory");
    std::memcpy(r, s.c_str(), s.size() + 1);
    *out = r;
    return CDM_OK;
}

} // namespace cdm::api
