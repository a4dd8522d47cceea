// What the command groups share: exit codes, the clock, number parsing and
// printing.
#include <sys/stat.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include <cdm/cdm.h>
#include "commands.h"

namespace cdm::cli {

uint64_t now_ns() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1000000000ull + uint64_t(ts.tv_nsec);
}

double now_s() { return double(now_ns()) * 1e-9; }

std::string num(double v) {
    char b[32];
    // Whole numbers in full (1000000, not 1e+06), the rest as %g.
    if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) <= 9007199254740992.0)
        std::snprintf(b, sizeof b, "%.0f", v);
    else
        std::snprintf(b, sizeof b, "%g", v);
    return b;
}

namespace {

// A decimal number, finite, in a double's range: strtod alone also takes
// hexadecimal ("0x10"), "inf", "nan(...)" and leading blanks, which CLI11's
// own conversion of the value may read differently. "" when it is one,
// else why not.
std::string decimal_number(const std::string &s, double &v) {
    if (s.empty() || s.find_first_not_of("0123456789+-.eE") != std::string::npos)
        return "\"" + s + "\" is not a decimal number";
    char *end = nullptr;
    errno = 0;
    v = std::strtod(s.c_str(), &end);
    if (*end != '\0') return "\"" + s + "\" is not a decimal number";
    if (errno == ERANGE || !std::isfinite(v)) return s + " is out of a double's range";
    return std::string();
}

} // namespace

CLI::Validator range(double lo, double hi) {
    const std::string desc = "in [" + num(lo) + ", " + num(hi) + "]";
    return CLI::Validator(
        [lo, hi, desc](std::string &s) -> std::string {
            double v = 0;
            if (std::string why = decimal_number(s, v); !why.empty()) return why;
            if (v < lo || v > hi) return s + " is not " + desc;
            return std::string();
        },
        desc);
}

CLI::Validator tolerance_or_estimate() {
    const std::string desc = "-1 (estimated) or in [0, 5000]";
    return CLI::Validator(
        [desc](std::string &s) -> std::string {
            double v = 0;
            if (std::string why = decimal_number(s, v); !why.empty()) return why;
            if (v != -1 && !(v >= 0 && v <= 5000)) return s + " is not " + desc;
            return std::string();
        },
        desc);
}

std::vector<std::string> split_list(const std::string &s) {
    std::vector<std::string> v;
    std::stringstream ss(s);
    std::string x;
    while (std::getline(ss, x, ','))
        if (!x.empty()) v.push_back(x);
    return v;
}

std::vector<double> parse_number_list(const std::string &text, const std::string &option) {
    std::vector<double> out;
    std::vector<std::string> items;
    for (size_t b = 0, e;; b = e + 1) { // every item, empty ones included ("50,,60" is a typo)
        e = std::min(text.find(',', b), text.size());
        items.push_back(text.substr(b, e - b));
        if (e == text.size()) break;
    }
    for (const auto &item : items) {
        if (item.empty())
            throw UsageError(option + ": an empty item in \"" + text + "\" (expected a comma-separated list such "
                                      "as 30,40,50)");
        char *end = nullptr;
        errno = 0;
        const double v = std::strtod(item.c_str(), &end);
        if (*end || errno == ERANGE || !std::isfinite(v))
            throw UsageError(option + ": \"" + item + "\" is not a number (expected a comma-separated list such as "
                                                      "30,40,50)");
        out.push_back(v);
    }
    if (out.empty()) throw UsageError(option + ": empty list (expected a comma-separated list such as 30,40,50)");
    return out;
}

const std::string &json_path(const std::string &option, const std::string &path) {
    try {
        (void)nlohmann::json(path).dump();
    } catch (const nlohmann::json::type_error &) {
        throw UsageError(option + " " + nlohmann::json(path).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) +
                         ": the name is not UTF-8, and libcdm takes it inside JSON options (UTF-8 only); rename the "
                         "file, or give a link to it with a UTF-8 name");
    }
    return path;
}

bool same_file(const std::string &a, const std::string &b) {
    struct stat sa {}, sb {};
    return !a.empty() && !b.empty() && stat(a.c_str(), &sa) == 0 && stat(b.c_str(), &sb) == 0 &&
           sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

void distinct_outputs(const std::vector<std::pair<std::string, std::string>> &outputs) {
    auto where = [](const std::string &path) {
        const size_t slash = path.find_last_of('/');
        const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
        char *real = realpath(dir.c_str(), nullptr);
        const std::string key = (real ? std::string(real) : dir) + "/" + path.substr(slash + 1);
        std::free(real);
        return key;
    };
    for (size_t i = 0; i < outputs.size(); ++i)
        for (size_t k = 0; k < i; ++k) {
            const auto &a = outputs[k], &b = outputs[i];
            if (a.second.empty() || b.second.empty()) continue;
            if (same_file(a.second, b.second) || where(a.second) == where(b.second))
                throw UsageError(a.first + " and " + b.first + " are the same file " + b.second +
                                 ": the second would replace the first");
        }
}

nlohmann::json stats_json(const cdm_stats &st) {
    return {{"reports", st.reports},           {"dropped", st.dropped},
            {"malformed", st.malformed},       {"out_of_order", st.out_of_order},
            {"sequence_jumps", st.sequence_jumps}, {"restarts", st.restarts},
            {"out_of_workspace", st.out_of_workspace}, {"reconnects", st.reconnects},
            {"replay_truncated_bytes", st.replay_truncated_bytes}};
}

std::string losses_text(const cdm_stats &st) {
    const auto n = [](uint64_t v) { return std::to_string(v); };
    return n(st.dropped) + " dropped, " + n(st.malformed) + " malformed, " + n(st.out_of_order) + " out of order, " +
           n(st.sequence_jumps) + " sequence jumps, " + n(st.restarts) + " restarts";
}

int report_error(const std::string &what, int rc) {
    std::fprintf(stderr, "cdm: %s: %s", what.c_str(), cdm_strerror(rc));
    std::string detail = cdm_thread_error() ? cdm_thread_error() : "";
    // The JSON parser's internal codes ("[json.exception.parse_error.101] ")
    // mean nothing to a user; the library's own text around them says where
    // and what. Until every loader words its errors itself, they stop here.
    for (size_t at; (at = detail.find("[json.exception.")) != std::string::npos;) {
        const size_t end = detail.find(']', at);
        detail.erase(at, end == std::string::npos ? std::string::npos : end + 2 - at);
    }
    if (!detail.empty()) std::fprintf(stderr, ": %s", detail.c_str());
    std::fprintf(stderr, "\n");
    return kExitFailure;
}

void add_plugin_option(CLI::App *app, std::vector<std::string> &plugins) {
    app->add_option("--plugin", plugins,
                    "Load a user-effect plugin (.so) first; repeatable (its effects can then be in a calibration, "
                    "a sim: URI's effects= or truth=, --effects)")
        ->expected(1) // one path per --plugin: `--plugin a.so sim:` keeps sim: the URI
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
}

int load_plugins(const std::vector<std::string> &plugins) {
    for (const auto &p : plugins) {
        if (p.size() >= 3 && p.compare(p.size() - 3, 3, ".py") == 0)
            throw UsageError("--plugin " + p + ": a Python effect is used from Python, not from the cdm command "
                             "(which does not embed Python): register it there (cdm.register_effect) and open the "
                             "device with cdm.open(uri, calibration=...) in that process (docs/effects.md, "
                             "\"User effects\")");
        if (cdm_effect_load_plugin(p.c_str()) != CDM_OK) return report_error("--plugin " + p, CDM_ERR_INVALID_ARG);
    }
    return kExitOk;
}

} // namespace cdm::cli
