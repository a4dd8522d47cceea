#include "calib_outputs.h"

#include <dirent.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

#include <cdm/cdm.h>
#include "commands.h"
#include "report.h"

namespace cdm::cli {

// Through libcdm's one atomic writer: the old file survives any failure,
// and the command's inputs (`protect`) are never written over.
bool write_atomic(const std::string &path, const std::string &text, const std::vector<std::string> &protect) {
    std::vector<const char *> p;
    for (const auto &s : protect)
        if (!s.empty()) p.push_back(s.c_str());
    if (cdm_write_file_atomic(path.c_str(), text.data(), text.size(), p.data(), p.size()) == CDM_OK) return true;
    std::fprintf(stderr, "cdm: %s\n", cdm_thread_error());
    return false;
}

// "" when DIR is the report's to write `name` into: empty, or holding a
// report's marker (.cdm-report) and no `name` the marker does not list (a
// file of the user's by that name is never written over); else why not.
std::string report_dir_refusal(const std::string &dir, const std::string &name) {
    const std::string marker = dir + "/.cdm-report";
    struct stat st {};
    if (stat(marker.c_str(), &st) == 0 && S_ISREG(st.st_mode)) {
        const std::string path = dir + "/" + name;
        if (lstat(path.c_str(), &st) != 0) return "";
        std::ifstream f(marker);
        for (std::string line; std::getline(f, line);)
            if (line == name) return "";
        // A result of this toolkit's (its "tool"): what `--report` wrote there
        // before its marker listed the JSON it is drawn from. A regular file
        // only, read within the cap every JSON input has.
        if (S_ISREG(st.st_mode) && st.st_size <= 64 * 1024 * 1024) {
            std::ifstream in(path, std::ios::binary);
            const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
            if (j.is_object() && j.value("tool", std::string()).rfind("cdm calib ", 0) == 0) return "";
        }
        return dir + "/" + name + " is not the report's (.cdm-report does not list it): not writing over it; give "
                                  "--json a path, or --report another directory";
    }
    DIR *d = opendir(dir.c_str());
    if (!d) return dir + " cannot be read";
    bool empty = true;
    while (dirent *e = readdir(d))
        if (std::strcmp(e->d_name, ".") != 0 && std::strcmp(e->d_name, "..") != 0) empty = false;
    closedir(d);
    if (empty) return "";
    return dir + " is not empty and holds no report (.cdm-report is missing): the report writes only into a new "
                 "or empty directory, or one an earlier report wrote; give another directory";
}

// The outputs' checks that need no result, before the work: --json is no
// directory or other non-file, --report DIR is the report's to write
// `name` into (when --json does not give the JSON a path), and that JSON
// is not one of `inputs` (an earlier diagnosis compared with, in DIR).
void check_outputs_first(const std::string &json_out, const std::string &report, const char *name,
                         const std::vector<std::string> &inputs) {
    struct stat st {};
    if (!json_out.empty() && stat(json_out.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
        throw UsageError("--json " + json_out + " exists and is not a regular file: not writing over it");
    if (report.empty() || !json_out.empty() || stat(report.c_str(), &st) != 0) return;
    if (!S_ISDIR(st.st_mode)) throw UsageError("--report " + report + " exists and is not a directory");
    if (const std::string why = report_dir_refusal(report, name); !why.empty()) throw UsageError("--report: " + why);
    const std::string jp = report + "/" + name;
    for (const auto &p : inputs)
        if (same_file(p, jp))
            throw UsageError("--report: " + jp + " is the input " + p +
                             " of this command, which the report would replace: give --json a path, or copy it "
                             "elsewhere first");
}

// The result's JSON (--json) and HTML report (--report DIR, drawn from the
// JSON: --json's file, or `name` written into DIR when there is none).
// Never over one of the command's inputs.
int write_outputs(const std::string &json_out, const std::string &report, const std::vector<std::string> &before,
                  const nlohmann::json &r, const std::vector<std::string> &inputs, const char *name) {
    if (!json_out.empty() && !write_atomic(json_out, r.dump(1) + "\n", inputs)) return kExitFailure;
    if (report.empty()) return kExitOk;
    std::string jp = json_out;
    if (jp.empty()) {
        if (mkdir(report.c_str(), 0755) != 0 && errno != EEXIST) {
            std::fprintf(stderr, "cdm: --report: cannot create %s: %s\n", report.c_str(), std::strerror(errno));
            return kExitFailure;
        }
        if (const std::string why = report_dir_refusal(report, name); !why.empty()) {
            std::fprintf(stderr, "cdm: --report: %s\n", why.c_str());
            return kExitUsage;
        }
        jp = report + "/" + name;
        if (!write_atomic(jp, r.dump() + "\n", inputs)) return kExitFailure;
    }
    if (run_report(jp, before, report, json_out.empty()) != 0) return kExitFailure;
    std::printf("report: %s/index.html\n", report.c_str());
    return kExitOk;
}

} // namespace cdm::cli
