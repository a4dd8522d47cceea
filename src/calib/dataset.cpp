#include "calib/dataset.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <unordered_map>

#include "io/json.h"

namespace cdm {

namespace {
std::string at(const std::string &src, size_t line, size_t col) {
    return src + ":" + std::to_string(line) + ":" + std::to_string(col) + ": ";
}

// Splits one CSV line (no quoting in this format; fields are numbers).
void split(const char *b, const char *e, std::vector<std::pair<const char *, const char *>> &f) {
    f.clear();
    const char *s = b;
    for (const char *p = b;; ++p) {
        if (p == e || *p == ',') {
            f.emplace_back(s, p);
            if (p == e) break;
            s = p + 1;
        }
    }
}

std::string trim(const char *b, const char *e) {
    while (b < e && (*b == ' ' || *b == '\t' || *b == '"')) ++b;
    while (e > b && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r' || e[-1] == '"')) --e;
    return std::string(b, e);
}

// A field quoted in a message, cut to ~40 characters.
std::string shown(const char *b, const char *e) { return io::quote_field(trim(b, e)); }

bool to_double(const char *b, const char *e, double &v) {
    while (b < e && (*b == ' ' || *b == '\t')) ++b;
    while (e > b && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r')) --e;
    if (b < e && *b == '+') ++b;
    auto r = std::from_chars(b, e, v);
    return r.ec == std::errc() && r.ptr == e && b != e;
}
} // namespace

bool parse_dataset(const std::string &text, const std::string &src, Dataset &out, std::string &err) {
    static const char *required[] = {"point", "x_ref", "y_ref", "z_ref", "l1", "l2", "l3", "l4"};
    Dataset d;
    d.path = src;
    const char *p = text.data(), *end = p + text.size();
    size_t line = 0;
    std::vector<std::pair<const char *, const char *>> f;
    int colidx[8];
    int tcol = -1; // optional acquisition time column t_s (s)
    size_t ncols = 0;
    bool header = false;
    std::unordered_map<long, size_t> index;
    std::vector<std::vector<std::array<double, 4>>> groups;
    std::vector<size_t> first_line;
    while (p < end) {
        const char *nl = static_cast<const char *>(memchr(p, '\n', size_t(end - p)));
        const char *le = nl ? nl : end;
        ++line;
        const char *b = p;
        p = nl ? nl + 1 : end;
        if (le > b && le[-1] == '\r') --le;
        if (le == b || *b == '#') continue; // blank lines and comments
        split(b, le, f);
        if (!header) {
            header = true;
            ncols = f.size();
            std::vector<std::string> names;
            for (auto &x : f) {
                std::string n = trim(x.first, x.second);
                auto dup = std::find(names.begin(), names.end(), n);
                if (dup != names.end()) {
                    err = at(src, line, names.size() + 1) + "duplicate column \"" + io::quote_field(n) +
                          "\" (also column " + std::to_string(dup - names.begin() + 1) + ")";
                    return false;
                }
                names.push_back(std::move(n));
            }
            for (int k = 0; k < 8; ++k) {
                auto it = std::find(names.begin(), names.end(), required[k]);
                if (it == names.end()) {
                    err = at(src, line, 1) + "header lacks column \"" + required[k] +
                          "\" (expected point,x_ref,y_ref,z_ref,l1,l2,l3,l4)";
                    return false;
                }
                colidx[k] = int(it - names.begin());
            }
            for (size_t k = 0; k < names.size(); ++k)
                if (names[k] == "t_s") tcol = int(k);
                else if (std::find(std::begin(required), std::end(required), names[k]) == std::end(required))
                    d.ignored_columns.push_back(names[k]);
            continue;
        }
        if (f.size() != ncols) {
            err = at(src, line, std::min(f.size(), ncols) + 1) + "expected " + std::to_string(ncols) +
                  " fields as in the header, found " + std::to_string(f.size());
            return false;
        }
        double v[8];
        for (int k = 0; k < 8; ++k) {
            auto &x = f[size_t(colidx[k])];
            if (!to_double(x.first, x.second, v[k]) || !std::isfinite(v[k])) {
                err = at(src, line, size_t(colidx[k]) + 1) + required[k] + " is not a finite number: '" +
                      shown(x.first, x.second) + "'";
                return false;
            }
        }
        if (v[0] != std::floor(v[0]) || std::fabs(v[0]) > 9e15) {
            err = at(src, line, size_t(colidx[0]) + 1) + "point must be an integer id, got " +
                  shown(f[size_t(colidx[0])].first, f[size_t(colidx[0])].second);
            return false;
        }
        for (int k = 1; k < 4; ++k)
            if (std::fabs(v[k]) > kDatasetMaxRefMm) {
                err = at(src, line, size_t(colidx[k]) + 1) + required[k] + " = " + shown(f[size_t(colidx[k])].first, f[size_t(colidx[k])].second) +
                      " mm is beyond the sane range of +-5000 mm (wrong unit?)";
                return false;
            }
        for (int k = 4; k < 8; ++k)
            if (!(v[k] > 0) || v[k] > kDatasetMaxLengthMm) {
                err = at(src, line, size_t(colidx[k]) + 1) + required[k] + " must be a positive length in mm, at most 10000 (got " +
                      shown(f[size_t(colidx[k])].first, f[size_t(colidx[k])].second) + ")";
                return false;
            }
        long id = long(v[0]);
        auto it = index.find(id);
        size_t g;
        if (it == index.end()) {
            g = groups.size();
            index.emplace(id, g);
            groups.emplace_back();
            first_line.push_back(line);
            JigHole jp;
            jp.point = id;
            for (int k = 0; k < 3; ++k) jp.ref[k] = v[1 + k];
            d.pos.push_back(jp);
        } else {
            g = it->second;
            for (int k = 0; k < 3; ++k)
                if (d.pos[g].ref[k] != v[1 + k]) {
                    err = at(src, line, size_t(colidx[1 + k]) + 1) + "point " + std::to_string(id) + " has " +
                          required[1 + k] + " " + shown(f[size_t(colidx[1 + k])].first, f[size_t(colidx[1 + k])].second) +
                          " but line " + std::to_string(first_line[g]) + " gave " + std::to_string(d.pos[g].ref[k]);
                    return false;
                }
        }
        if (tcol >= 0) {
            auto &x = f[size_t(tcol)];
            double t;
            if (!to_double(x.first, x.second, t) || !std::isfinite(t)) {
                err = at(src, line, size_t(tcol) + 1) + "t_s is not a finite number: '" + shown(x.first, x.second) + "'";
                return false;
            }
            d.pos[g].t_s += t; // summed here, divided by n below
        }
        groups[g].push_back({v[4], v[5], v[6], v[7]});
        d.pos[g].mean_row += double(d.rows); // summed here, divided by n below
        ++d.rows;
    }
    if (!header) {
        err = src + ":1:1: empty file (expected the header point,x_ref,y_ref,z_ref,l1,l2,l3,l4)";
        return false;
    }
    if (d.rows == 0) {
        err = src + ":" + std::to_string(line) + ":1: no data rows after the header";
        return false;
    }
    d.samples.reserve(d.rows);
    for (size_t g = 0; g < groups.size(); ++g) {
        auto &jp = d.pos[g];
        jp.first = d.samples.size();
        jp.n = int(groups[g].size());
        for (auto &s : groups[g]) {
            d.samples.push_back(s);
            for (int c = 0; c < 4; ++c) jp.mean[c] += s[c];
        }
        for (int c = 0; c < 4; ++c) jp.mean[c] /= jp.n;
        jp.mean_row /= jp.n;
        jp.t_s = tcol >= 0 ? jp.t_s / jp.n : jp.mean_row * kDatasetNominalRowPeriodS;
        if (jp.n > 1) {
            for (auto &s : groups[g])
                for (int a = 0; a < 4; ++a)
                    for (int b = 0; b < 4; ++b) jp.cov[a][b] += (s[a] - jp.mean[a]) * (s[b] - jp.mean[b]);
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b) jp.cov[a][b] /= (jp.n - 1);
        }
        d.heights.push_back(jp.ref[0]);
    }
    std::sort(d.heights.begin(), d.heights.end());
    d.heights.erase(std::unique(d.heights.begin(), d.heights.end(),
                                [](double a, double b) { return std::fabs(a - b) < 1e-6; }),
                    d.heights.end());
    out = std::move(d);
    return true;
}

bool load_dataset(const std::string &path, Dataset &out, std::string &err, bool *io_failure) {
    std::string text;
    if (io_failure) *io_failure = false;
    if (!io::read_file(path, io::kDatasetMaxBytes, text, err, "dataset")) {
        if (io_failure) *io_failure = true;
        return false;
    }
    return parse_dataset(text, path, out, err);
}

bool DatasetWriter::open(const std::string &path, const std::vector<std::string> &protect, std::string &err) {
    buf_ = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
    return f_.open(path, protect, err);
}

bool DatasetWriter::add_row(long point, const double ref[3], const double len[4], std::string &err) {
    char line[256];
    const int n = std::snprintf(line, sizeof line, "%ld,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", point, ref[0], ref[1],
                                ref[2], len[0], len[1], len[2], len[3]);
    if (n < 0 || size_t(n) >= sizeof line) {
        err = "dataset row for point " + std::to_string(point) + " does not fit a CSV line (non-sane values)";
        f_.abandon();
        return false;
    }
    buf_.append(line, size_t(n));
    // Flush in 64 kB pieces: bounded memory for long recordings.
    if (buf_.size() >= 65536) {
        if (!f_.write(buf_, err)) return false;
        buf_.clear();
    }
    return true;
}

bool DatasetWriter::commit(std::string &err) {
    if (!buf_.empty() && !f_.write(buf_, err)) return false;
    buf_.clear();
    return f_.commit(err);
}


} // namespace cdm
