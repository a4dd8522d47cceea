#include "jig/planned.h"

#include <sys/stat.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>

namespace cdm {

const char *const kPlanHeader = "x_ref,y_ref,z_ref,samples";

namespace {

// One data line's four numbers; false + err (without the "PATH:LINE: ").
bool plan_row(const std::string &line, PlanRow &row, std::string &err) {
    std::vector<double> v;
    for (size_t b = 0, e;; b = e + 1) { // every field, an empty last one included
        e = std::min(line.find(',', b), line.size());
        const std::string cell = line.substr(b, e - b);
        char *end = nullptr;
        const double d = std::strtod(cell.c_str(), &end);
        if (cell.empty() || *end != '\0' || !std::isfinite(d) || cell.find_first_of("xXpP") != std::string::npos) {
            err = "\"" + cell.substr(0, 40) + "\" is not a number";
            return false;
        }
        v.push_back(d);
        if (e == line.size()) break;
    }
    if (v.size() != 4) {
        err = std::string("4 values expected (") + kPlanHeader + "), got " + std::to_string(v.size());
        return false;
    }
    for (int c = 0; c < 3; ++c)
        if (std::fabs(v[size_t(c)]) > 5000) {
            err = "a reference beyond +-5000 mm";
            return false;
        }
    if (!(v[3] >= 1 && v[3] <= 1e6) || v[3] != std::floor(v[3])) {
        err = "samples must be a whole number in 1..1000000";
        return false;
    }
    row = {v[0], v[1], v[2], v[3]};
    return true;
}

} // namespace

bool read_plan_csv(const std::string &path, std::vector<PlanRow> &rows, std::string &err) {
    rows.clear();
    struct stat st {};
    if (stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) {
        err = path + " is not a regular file that can be read";
        return false;
    }
    if (size_t(st.st_size) > kPlanMaxBytes) {
        err = path + " is over 16 MiB";
        return false;
    }
    std::ifstream f(path, std::ios::binary);
    if (!f) {
        err = "cannot read " + path;
        return false;
    }
    std::string line;
    // A UTF-8 byte-order mark (a spreadsheet's "CSV UTF-8") is no part of the header.
    const auto header = [&] {
        if (line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);
        line.erase(line.find_last_not_of("\r") + 1);
        return line == kPlanHeader;
    };
    if (!std::getline(f, line) || !header()) {
        err = path + ":1: the header must be " + std::string(kPlanHeader) + " (a file of `cdm calib plan`)";
        return false;
    }
    size_t bytes = line.size();
    // Each position once: a repeat would merge two seatings of the jig into
    // one position of the dataset. References to the micrometre.
    std::map<std::array<long long, 3>, size_t> seen;
    for (size_t no = 2; std::getline(f, line); ++no) {
        bytes += line.size() + 1;
        if (bytes > kPlanMaxBytes) {
            err = path + " is over 16 MiB";
            return false;
        }
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty()) continue;
        PlanRow r;
        if (!plan_row(line, r, err)) {
            err = path + ":" + std::to_string(no) + ": " + err;
            return false;
        }
        const auto at = seen.emplace(std::array<long long, 3>{std::llround(r[0] * 1e3), std::llround(r[1] * 1e3),
                                                              std::llround(r[2] * 1e3)},
                                     no);
        if (!at.second) {
            err = path + ":" + std::to_string(no) + ": the position of line " + std::to_string(at.first->second) +
                  " again (a plan visits each position once)";
            return false;
        }
        rows.push_back(r);
    }
    if (rows.empty()) {
        err = path + " lists no position";
        return false;
    }
    return true;
}

bool match_plan(const std::vector<JigPosition> &plate, const std::vector<PlanRow> &rows,
                std::vector<PlannedVisit> &visits, std::string &err) {
    visits.clear();
    // The plate's positions by their reference in micrometres: a planned
    // reference within 1e-6 mm of one is found among its key's neighbours.
    using Key = std::array<long long, 3>;
    auto key = [](const double *r) {
        return Key{std::llround(r[0] * 1e6), std::llround(r[1] * 1e6), std::llround(r[2] * 1e6)};
    };
    std::map<Key, size_t> at;
    for (size_t k = 0; k < plate.size(); ++k) at.emplace(key(plate[k].ref), k);
    auto find = [&](const double *r) -> size_t {
        const Key c = key(r);
        for (long long dx = -1; dx <= 1; ++dx)
            for (long long dy = -1; dy <= 1; ++dy)
                for (long long dz = -1; dz <= 1; ++dz) {
                    const auto it = at.find({c[0] + dx, c[1] + dy, c[2] + dz});
                    if (it == at.end()) continue;
                    const double *p = plate[it->second].ref;
                    if (std::fabs(p[0] - r[0]) < 1e-6 && std::fabs(p[1] - r[1]) < 1e-6 && std::fabs(p[2] - r[2]) < 1e-6)
                        return it->second;
                }
        return plate.size();
    };
    for (size_t i = 0; i < rows.size(); ++i) {
        const PlanRow &r = rows[i];
        const size_t found = find(r.data());
        if (found == plate.size()) {
            char b[160];
            std::snprintf(b, sizeof b, "plan position %zu (%g, %g, %g mm) is not a hole of the plate at one of its heights",
                          i + 1, r[0], r[1], r[2]);
            err = b;
            return false;
        }
        if (!(r[3] >= 1 && r[3] <= 1e6) || r[3] != std::floor(r[3])) {
            err = "plan position " + std::to_string(i + 1) + ": samples must be a whole number in 1..1000000";
            return false;
        }
        visits.push_back({found, int(r[3])});
    }
    return true;
}

} // namespace cdm
