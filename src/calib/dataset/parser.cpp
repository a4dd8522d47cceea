// See parser.h: the parser of one jig CSV line at a time.
#include "calib/dataset/parser.h"

#include <algorithm>

#include "calib/dataset/heights.h"
#include "io/decimal.h"
#include "io/json.h"

namespace cdm {
namespace dataset_detail {

namespace {
std::string at(const std::string &src, size_t line, size_t col) {
    return src + ":" + std::to_string(line) + ":" + std::to_string(col) + ": ";
}

// Splits one CSV line (no quoting in this format; fields are numbers). A
// plain loop: fields are a few characters, shorter than memchr's call.
void split(const char *b, const char *e, std::vector<std::pair<const char *, const char *>> &f) {
    f.clear();
    const char *s = b;
    for (const char *p = b; p < e; ++p)
        if (*p == ',') {
            f.emplace_back(s, p);
            s = p + 1;
        }
    f.emplace_back(s, e);
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
    return io::parse_decimal(b, e, v);
}
} // namespace

bool Parser::header(std::string &err) {
    const std::string &src = src_;
    header_ = true;
    ncols_ = f_.size();
    std::vector<std::string> names;
    for (auto &x : f_) {
        std::string n = trim(x.first, x.second);
        // A UTF-8 byte order mark, as spreadsheet programs write before the
        // first field of a CSV saved "as UTF-8", belongs to no column name.
        if (names.empty() && n.rfind("\xEF\xBB\xBF", 0) == 0) n = trim(n.data() + 3, n.data() + n.size());
        auto dup = std::find(names.begin(), names.end(), n);
        if (dup != names.end()) {
            err = at(src, line_, names.size() + 1) + "duplicate column \"" + io::quote_field(n) + "\" (also column " +
                  std::to_string(dup - names.begin() + 1) + ")";
            return false;
        }
        names.push_back(std::move(n));
    }
    for (int k = 0; k < 8; ++k) {
        auto it = std::find(names.begin(), names.end(), kDatasetColumns[k]);
        if (it == names.end()) {
            err = at(src, line_, 1) + "header lacks column \"" + kDatasetColumns[k] +
                  "\" (expected point,x_ref,y_ref,z_ref,l1,l2,l3,l4)";
            return false;
        }
        colidx_[k] = int(it - names.begin());
    }
    for (size_t k = 0; k < names.size(); ++k)
        if (names[k] == "t_s") tcol_ = int(k);
        else if (std::find(kDatasetColumns, kDatasetColumns + kDatasetValues, names[k]) ==
                 kDatasetColumns + kDatasetValues)
            d_.ignored_columns.push_back(names[k]);
    return true;
}

// A known position's row: its reference must be the one its first line gave.
bool Parser::same_ref(size_t g, const double *v, size_t line, const char *b, const char *le, std::string &err) {
    for (int k = 0; k < 3; ++k)
        if (d_.pos[g].ref[k] != v[1 + k]) {
            split(b, le, f_); // (row() is not given the fields)
            const auto &x = f_[size_t(colidx_[1 + k])];
            err = at(src_, line, size_t(colidx_[1 + k]) + 1) + "point " + std::to_string(d_.pos[g].point) + " has " +
                  kDatasetColumns[1 + k] + " " + shown(x.first, x.second) + " but line " +
                  std::to_string(first_line_[g]) + " gave " + std::to_string(d_.pos[g].ref[k]);
            return false;
        }
    return true;
}

bool Parser::line(const char *b, const char *le, std::string &err) {
    const std::string &src = src_;
    const char *const *required = kDatasetColumns;
    auto &f = f_;
    const auto &colidx = colidx_;
    const size_t line = ++line_;
    if (le > b && le[-1] == '\r') --le;
    if (le == b || *b == '#') return true; // blank lines and comments
    split(b, le, f);
    if (!header_) return header(err);
    if (f.size() != ncols_) {
        err = at(src, line, std::min(f.size(), ncols_) + 1) + "expected " + std::to_string(ncols_) +
              " fields as in the header, found " + std::to_string(f.size());
        return false;
    }
    // Every field a number first, then each value by the rule the writer
    // shares (dataset_value_fault), column by column.
    double v[kDatasetValues];
    for (int k = 0; k < kDatasetValues; ++k) {
        auto &x = f[size_t(colidx[k])];
        if (!to_double(x.first, x.second, v[k]) || !std::isfinite(v[k])) {
            err = at(src, line, size_t(colidx[k]) + 1) +
                  dataset_fault_text(DatasetFault::NotFinite, k, required[k], shown(x.first, x.second));
            return false;
        }
    }
    for (int k = 0; k < kDatasetValues; ++k)
        if (const DatasetFault fault = dataset_value_fault(k, v[k]); fault != DatasetFault::None) {
            auto &x = f[size_t(colidx[k])];
            err = at(src, line, size_t(colidx[k]) + 1) +
                  dataset_fault_text(fault, k, required[k], shown(x.first, x.second));
            return false;
        }
    // The time is refused in row(), where a row left out whole is not.
    double t = 0;
    bool t_ok = true;
    if (tcol_ >= 0) {
        auto &x = f[size_t(tcol_)];
        t_ok = to_double(x.first, x.second, t) && std::isfinite(t);
    }
    return row(line, v, t, t_ok, b, le, err);
}

int Parser::values(const char *b, const char *le, double *v, double &t, bool &t_ok,
                   std::vector<std::pair<const char *, const char *>> &f) const {
    if (le > b && le[-1] == '\r') --le;
    if (le == b || *b == '#') return 0;
    split(b, le, f);
    if (f.size() != ncols_) return -1;
    for (int k = 0; k < kDatasetValues; ++k) {
        auto &x = f[size_t(colidx_[k])];
        if (!to_double(x.first, x.second, v[k]) || dataset_value_fault(k, v[k]) != DatasetFault::None) return -1;
    }
    t = 0;
    t_ok = true;
    if (tcol_ >= 0) {
        auto &x = f[size_t(tcol_)];
        t_ok = to_double(x.first, x.second, t) && std::isfinite(t);
    }
    return 1;
}

bool Parser::row(size_t line, const double *v, double t, bool t_ok, const char *b, const char *le,
                 std::string &err) {
    const std::string &src = src_;
    const auto &colidx = colidx_;
    if (le > b && le[-1] == '\r') --le;
    long id = long(v[0]);
    if (skip_ && std::binary_search(skip_->begin(), skip_->end(), id)) {
        // A point left out whole: counted in rows (the row indices stay the
        // file's), nothing else.
        if (exclude_ && next_excluded_ < exclude_->size() && (*exclude_)[next_excluded_] == d_.rows) ++next_excluded_;
        ++d_.rows;
        return true;
    }
    // A position's rows are usually consecutive: the last one's index is
    // tried before the map.
    const bool again = last_g_ != SIZE_MAX && id == last_id_;
    const auto it = again ? index_.end() : index_.find(id);
    size_t g;
    if (again) {
        g = last_g_;
        if (!same_ref(g, v, line, b, le, err)) return false;
    } else if (it == index_.end()) {
        g = d_.pos.size();
        if (expect_ && (g >= expect_->pos.size() || expect_->pos[g].point != id ||
                        !std::equal(v + 1, v + 4, expect_->pos[g].ref))) {
            err = at(src, line, size_t(colidx[0]) + 1) + "the dataset changed since it was loaded (point " +
                  std::to_string(id) + " is new here or moved)";
            return false;
        }
        index_.emplace(id, g);
        first_line_.push_back(line);
        JigHole jp;
        jp.point = id;
        for (int k = 0; k < 3; ++k) jp.ref[k] = v[1 + k];
        d_.pos.push_back(jp);
        if (!expect_) range_.push_back({INFINITY, INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY, -INFINITY});
    } else {
        g = it->second;
        if (!same_ref(g, v, line, b, le, err)) return false;
    }
    last_id_ = id;
    last_g_ = g;
    JigHole &h = d_.pos[g];
    if (!t_ok) {
        split(b, le, f_);
        auto &x = f_[size_t(tcol_)];
        err = at(src, line, size_t(tcol_) + 1) + "t_s is not a finite number: '" + shown(x.first, x.second) + "'";
        return false;
    }
    const size_t row = d_.rows;
    if (exclude_ && next_excluded_ < exclude_->size() && (*exclude_)[next_excluded_] == row) {
        ++next_excluded_; // a glitch: checked above, counted in rows, left out of the statistics
        ++d_.rows;
        return true;
    }
    h.t_s += t; // summed here, divided by n in finish()
    // Welford: the mean and the co-moment sum (l - mean_old)(l - mean_new)',
    // upper triangle; finish() mirrors it and divides by n - 1.
    const double *l = v + 4;
    const double n = double(++h.n);
    double dx[4];
    for (int c = 0; c < 4; ++c) {
        dx[c] = l[c] - h.mean[c];
        h.mean[c] += dx[c] / n;
    }
    for (int a = 0; a < 4; ++a)
        for (int c = a; c < 4; ++c) h.cov[a][c] += dx[a] * (l[c] - h.mean[c]);
    h.mean_row += double(row); // summed here (exact: integers), divided by n in finish()
    ++d_.rows;
    if (tap_) (*tap_)(g, row, line, l);
    if (!expect_) {
        ReadingRange &r = range_[g];
        for (int c = 0; c < 4; ++c) {
            distinct_[c].add(l[c]);
            r[size_t(c)] = std::min(r[size_t(c)], l[c]);
            r[4 + size_t(c)] = std::max(r[4 + size_t(c)], l[c]);
        }
    }
    return true;
}

bool Parser::finish(std::string &err) {
    const std::string &src = src_;
    if (!header_) {
        err = src + ":1:1: empty file (expected the header point,x_ref,y_ref,z_ref,l1,l2,l3,l4)";
        return false;
    }
    if (d_.rows == 0) {
        err = src + ":" + std::to_string(line_) + ":1: no data rows after the header";
        return false;
    }
    for (auto &jp : d_.pos) {
        jp.mean_row /= jp.n;
        jp.t_s = tcol_ >= 0 ? jp.t_s / jp.n : jp.mean_row * kDatasetNominalRowPeriodS;
        for (int a = 0; a < 4; ++a)
            for (int b = a; b < 4; ++b) {
                const double c = jp.n > 1 ? jp.cov[a][b] / (jp.n - 1) : 0.0;
                jp.cov[a][b] = jp.cov[b][a] = c;
            }
    }
    find_heights(d_);
    if (!expect_)
        for (int c = 0; c < 4; ++c) d_.resolution[c] = distinct_[c].min_step();
    else
        std::copy(std::begin(expect_->resolution), std::end(expect_->resolution), d_.resolution);
    if (expect_) {
        bool same = d_.rows == expect_->rows && d_.pos.size() == expect_->pos.size();
        for (size_t g = 0; same && g < d_.pos.size(); ++g) {
            same = d_.pos[g].n == expect_->pos[g].n;
            for (int c = 0; c < 4; ++c) same = same && d_.pos[g].mean[c] == expect_->pos[g].mean[c];
        }
        if (!same) {
            err = src + ": the dataset changed since it was loaded (" + std::to_string(d_.rows) + " rows now, " +
                  std::to_string(expect_->rows) + " then, or other readings)";
            return false;
        }
    }
    return true;
}

} // namespace dataset_detail
} // namespace cdm
