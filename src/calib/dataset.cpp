#include "calib/dataset.h"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <system_error>
#include <thread>
#include <unordered_map>
#include <utility>

#include "calib/dataset_glitches.h"
#include "calib/dataset_heights.h"
#include "io/decimal.h"
#include "io/json.h"

namespace cdm {

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

const char *const kDatasetColumns[kDatasetValues] = {"point", "x_ref", "y_ref", "z_ref", "l1", "l2", "l3", "l4"};

DatasetFault dataset_value_fault(int column, double v) {
    if (!std::isfinite(v)) return DatasetFault::NotFinite;
    if (column == 0) return v != std::floor(v) || std::fabs(v) > 9e15 ? DatasetFault::NotInteger : DatasetFault::None;
    if (column < 4) return std::fabs(v) > kDatasetMaxRefMm ? DatasetFault::OutOfRange : DatasetFault::None;
    return !(v > 0) || v > kDatasetMaxLengthMm ? DatasetFault::OutOfRange : DatasetFault::None;
}

std::string dataset_fault_text(DatasetFault f, int column, const std::string &name, const std::string &shown) {
    switch (f) {
    case DatasetFault::None: break;
    case DatasetFault::NotFinite: return name + " is not a finite number: '" + shown + "'";
    case DatasetFault::NotInteger: return name + " must be an integer id, got " + shown;
    case DatasetFault::OutOfRange:
        return column < 4 ? name + " = " + shown + " mm is beyond the sane range of +-5000 mm (wrong unit?)"
                          : name + " must be a positive length in mm, at most 10000 (got " + shown + ")";
    }
    return name + " is accepted";
}

struct DatasetSource {
    bool is_file = false;
    io::FileReader file; // the descriptor load_dataset() opened
    std::string text;    // what parse_dataset() was given
};

namespace {

// The distinct values of one cable's readings, as a sorted vector (8 bytes
// a value) fed through a small unsorted buffer; at most `cap` are kept.
class DistinctValues {
public:
    void add(double v) {
        if (v == last_ || full_) return; // quantised data repeats itself
        last_ = v;
        // A position's samples repeat a few values: one seen lately (a
        // small table by the value's bits; it is in sorted_ or pending_
        // already) is not sorted in again. The flushes still come every
        // 4096 values, as when each was kept, so the set kept once full is
        // the same.
        uint64_t bits;
        std::memcpy(&bits, &v, sizeof bits);
        double &seen = recent_[size_t((bits * 0x9E3779B97F4A7C15ull) >> 54)];
        if (seen != v) {
            seen = v;
            pending_.push_back(v);
        }
        if (++counted_ >= 4096) flush();
    }
    // Smallest step between distinct values (> 1e-9), 0 when there is none.
    double min_step() {
        flush();
        double q = INFINITY;
        for (size_t k = 1; k < sorted_.size(); ++k)
            if (sorted_[k] - sorted_[k - 1] > 1e-9) q = std::min(q, sorted_[k] - sorted_[k - 1]);
        return std::isfinite(q) ? q : 0.0;
    }

private:
    void flush() {
        counted_ = 0;
        if (pending_.empty()) return;
        std::sort(pending_.begin(), pending_.end());
        pending_.erase(std::unique(pending_.begin(), pending_.end()), pending_.end());
        const size_t mid = sorted_.size();
        sorted_.insert(sorted_.end(), pending_.begin(), pending_.end());
        std::inplace_merge(sorted_.begin(), sorted_.begin() + std::ptrdiff_t(mid), sorted_.end());
        sorted_.erase(std::unique(sorted_.begin(), sorted_.end()), sorted_.end());
        pending_.clear();
        full_ = sorted_.size() >= kDatasetResolutionValues;
    }
    std::vector<double> sorted_, pending_;
    std::vector<double> recent_ = std::vector<double>(1024, NAN); // (NaN equals nothing)
    size_t counted_ = 0; // values since the last flush, each kept or seen lately
    double last_ = NAN;
    bool full_ = false;
};

using Visit = std::function<void(size_t, const double *)>;
// A row as the parser sees it: position index, 0-based data row, 1-based
// line, the four readings.
using Tap = std::function<void(size_t, size_t, size_t, const double *)>;

// One CSV line at a time, in order: the header, then rows accumulated into
// per-position statistics (Welford's update of the mean and the co-moment
// matrix). With `expect` it reads a dataset again and checks it is the one
// `expect` describes, handing each row to `tap`. Rows listed in `exclude`
// (sorted data-row indices: the glitches) are checked but neither
// accumulated nor handed on.
class Parser {
public:
    Parser(const std::string &src, Dataset &d, const Dataset *expect, const Tap *tap,
           const std::vector<size_t> *exclude = nullptr, const std::vector<long> *skip = nullptr)
        : src_(src), d_(d), expect_(expect), tap_(tap), exclude_(exclude), skip_(skip) {
        d_.path = src;
    }
    bool line(const char *b, const char *le, std::string &err);
    // The values of a plain data row (value stage, any thread, once the
    // header is read): false when the line is anything else (blank, a
    // comment, a field count or a value line() would refuse), which then
    // goes to line(). Reads only the header's layout, fixed once read.
    // 1: a data row (v, t, t_ok); 0: a blank or comment line; -1 otherwise.
    int values(const char *b, const char *le, double *v, double &t, bool &t_ok,
               std::vector<std::pair<const char *, const char *>> &f) const;
    // The rest of line() for a row whose values() are v, t, t_ok, as line
    // number `line` (the file's lines are counted by the caller); b..le is
    // the line, for a message.
    bool row(size_t line, const double *v, double t, bool t_ok, const char *b, const char *le, std::string &err);
    bool finish(std::string &err);
    bool have_header() const { return header_; }
    size_t lines() const { return line_; }
    void set_lines(size_t n) { line_ = n; }
    // Per position, the readings' range (ReadingRange), from a first pass.
    std::vector<ReadingRange> &range() { return range_; }

private:
    bool header(std::string &err);
    bool same_ref(size_t g, const double *v, size_t line, const char *b, const char *le, std::string &err);
    const std::string &src_;
    Dataset &d_;
    const Dataset *expect_;
    const Tap *tap_;
    const std::vector<size_t> *exclude_;
    size_t next_excluded_ = 0; // cursor into *exclude_
    const std::vector<long> *skip_; // points left out whole (sorted)
    std::vector<ReadingRange> range_;
    size_t line_ = 0;
    std::vector<std::pair<const char *, const char *>> f_;
    int colidx_[8] = {};
    int tcol_ = -1; // optional acquisition time column t_s (s)
    size_t ncols_ = 0;
    bool header_ = false;
    std::unordered_map<long, size_t> index_;
    long last_id_ = 0;           // the last row's point
    size_t last_g_ = SIZE_MAX;   // and its position (SIZE_MAX: none yet)
    std::vector<size_t> first_line_;
    DistinctValues distinct_[4];
};

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

// The reader's two stages. A line's values (Parser::values: the fields
// split and converted, the bulk of the work) need nothing but the header,
// so they are found for a block of lines on whichever thread is free; the
// rest (Parser::row: the position, its statistics, the checks against
// what came before) runs on the calling thread, block after block in file
// order, so every statistic is summed in the order of a reading in turn,
// bit for bit. A line the value stage leaves (anything but a plain data
// row or a blank or comment line: a header, a field count or a value
// line() refuses) and every line after it in its block go to
// Parser::line, which says what is wrong as a reading in turn would.
struct Block {
    struct Row {
        double v[kDatasetValues];
        double t;
        uint32_t rel, b, e; // its line within the block (0-based), its bytes in text
        bool t_ok;
    };
    std::vector<char> text; // whole lines (the file's last may lack its '\n')
    std::vector<Row> rows;  // the data rows before `slow`
    size_t slow = SIZE_MAX; // byte offset of the first line left to Parser::line
    size_t slow_rel = 0;    // its line within the block
    size_t lines = 0;       // the block's lines, when none is left to Parser::line
    enum { Read, Claimed, Done } state = Read;
};

// The value stage of a block (any thread).
void block_values(const Parser &p, Block &bk, std::vector<std::pair<const char *, const char *>> &f) {
    bk.rows.clear();
    bk.slow = SIZE_MAX;
    bk.lines = 0;
    if (bk.text.size() > UINT32_MAX) { // (a text beyond a file's bound, parse_dataset's: offsets of 32 bits)
        bk.slow = 0;
        bk.slow_rel = 0;
        return;
    }
    const char *const base = bk.text.data(), *const end = base + bk.text.size();
    for (const char *b = base; b < end; ++bk.lines) {
        const char *nl = static_cast<const char *>(memchr(b, '\n', size_t(end - b)));
        const char *le = nl ? nl : end;
        Block::Row r;
        const int k = p.values(b, le, r.v, r.t, r.t_ok, f);
        if (k < 0) {
            bk.slow = size_t(b - base);
            bk.slow_rel = bk.lines;
            return;
        }
        if (k > 0) {
            r.rel = uint32_t(bk.lines);
            r.b = uint32_t(b - base);
            r.e = uint32_t(le - base);
            bk.rows.push_back(r);
        }
        b = nl ? nl + 1 : end;
    }
}

// The row stage of a block whose values are found, on the parser's thread.
bool block_rows(Parser &p, const Block &bk, std::string &err) {
    const size_t base = p.lines();
    const char *const text = bk.text.data();
    for (const auto &r : bk.rows)
        if (!p.row(base + r.rel + 1, r.v, r.t, r.t_ok, text + r.b, text + r.e, err)) return false;
    if (bk.slow == SIZE_MAX) {
        p.set_lines(base + bk.lines);
        return true;
    }
    p.set_lines(base + bk.slow_rel);
    const char *const end = text + bk.text.size();
    for (const char *b = text + bk.slow; b < end;) {
        const char *nl = static_cast<const char *>(memchr(b, '\n', size_t(end - b)));
        if (!p.line(b, nl ? nl : end, err)) return false;
        b = nl ? nl + 1 : end;
    }
    return true;
}

// Feeds `read(buf, n)` (bytes read, 0 at the end, < 0 on error) to the
// parser line by line, in blocks of whole lines of about kBlock bytes (a
// line longer than that is held whole), with at most kAhead blocks read
// ahead: memory stays bounded by the file's own bound (io::kDatasetMaxBytes;
// five blocks of very long lines may hold most of it) and otherwise by the
// blocks. Once the header is read and two blocks wait, a second thread
// finds the values of blocks ahead while this one takes the rows of the
// block in turn (Block); in turn on this thread alone when the input is
// shorter, the machine has one processor, or no thread can be started.
// read_error (optional): set when the failure returned is read's (a fault
// in the lines read before it is returned first, as in turn).
template <class Read> bool stream_lines(Read read, Parser &p, std::string &err, bool *read_error = nullptr) {
    constexpr size_t kBlock = size_t(1) << 18, kAhead = 4;
    std::vector<char> carry; // bytes read after the last block's last '\n'
    bool eof = false, failed = false;
    // A read that failed (err says why) ends the reading; the lines read
    // before it are still taken first, as a reading in turn would have
    // taken them, and a fault among them is the error.
    auto read_failed = [&] {
        if (read_error) *read_error = true;
        return false;
    };
    // The next block: 1, or 0 at the end, or -1 once a read failed.
    auto next = [&](Block &bk) -> int {
        if (failed) return -1;
        bk.text.swap(carry);
        carry.clear();
        for (;;) {
            if (eof) return bk.text.empty() ? 0 : 1;
            const size_t have = bk.text.size();
            bk.text.resize(have + kBlock);
            const long n = read(bk.text.data() + have, kBlock);
            if (n < 0) {
                failed = true;
                bk.text.resize(have);
                const void *nl = memrchr(bk.text.data(), '\n', have);
                if (!nl) return -1;
                bk.text.resize(size_t(static_cast<const char *>(nl) - bk.text.data()) + 1);
                return 1; // its whole lines; the failure next time
            }
            bk.text.resize(have + size_t(n));
            if (n == 0) {
                eof = true;
                continue;
            }
            const void *nl = memrchr(bk.text.data() + have, '\n', size_t(n));
            if (!nl) continue; // no line ends yet: one longer than a block is held whole
            const size_t cut = size_t(static_cast<const char *>(nl) - bk.text.data()) + 1;
            carry.assign(bk.text.begin() + long(cut), bk.text.end());
            bk.text.resize(cut);
            return 1;
        }
    };
    std::vector<std::pair<const char *, const char *>> f;
    std::vector<std::unique_ptr<Block>> pool;
    for (size_t k = 0; k <= kAhead; ++k) pool.push_back(std::make_unique<Block>());
    // In turn until the header is read (every line to Parser::line).
    Block *first = pool[0].get();
    while (!p.have_header()) {
        const int r = next(*first);
        if (r < 0) return read_failed();
        if (r == 0) return p.finish(err);
        first->rows.clear();
        first->slow = 0;
        first->slow_rel = 0;
        if (!block_rows(p, *first, err)) return false;
    }
    std::mutex mu;
    std::condition_variable cv;
    std::deque<Block *> queue; // read, in file order (this thread pushes and pops)
    bool stop = false;
    auto claim = [&]() -> Block * { // under mu
        for (Block *b : queue)
            if (b->state == Block::Read) {
                b->state = Block::Claimed;
                return b;
            }
        return nullptr;
    };
    auto done = [&](Block *b) {
        {
            std::lock_guard<std::mutex> lk(mu);
            b->state = Block::Done;
        }
        cv.notify_all();
    };
    std::thread helper;
    // Started once two blocks wait (a shorter input is read in turn).
    bool helper_tried = std::thread::hardware_concurrency() <= 1;
    auto start_helper = [&] {
        helper_tried = true;
        try {
            helper = std::thread([&] {
                std::vector<std::pair<const char *, const char *>> fields;
                for (;;) {
                    Block *b;
                    {
                        std::unique_lock<std::mutex> lk(mu);
                        cv.wait(lk, [&] { return stop || std::any_of(queue.begin(), queue.end(), [](Block *q) {
                                                     return q->state == Block::Read;
                                                 }); });
                        if (stop) return;
                        b = claim();
                    }
                    try {
                        block_values(p, *b, fields);
                    } catch (...) { // (out of memory): the block's lines go to Parser::line, on the parser's thread
                        b->rows.clear();
                        b->slow = 0;
                        b->slow_rel = 0;
                    }
                    done(b);
                }
            });
        } catch (const std::system_error &) {
            // in turn, on this thread
        }
    };
    // The helper ends however this does (an error, a tap that throws).
    struct Join {
        std::thread &t;
        std::mutex &mu;
        std::condition_variable &cv;
        bool &stop;
        ~Join() {
            if (!t.joinable()) return;
            {
                std::lock_guard<std::mutex> lk(mu);
                stop = true;
            }
            cv.notify_all();
            t.join();
        }
    } join{helper, mu, cv, stop};
    std::vector<Block *> spare;
    for (auto &b : pool) spare.push_back(b.get());
    for (;;) {
        while (queue.size() < kAhead && !spare.empty()) {
            Block *b = spare.back();
            const int r = next(*b);
            if (r < 0 && queue.empty()) return read_failed();
            if (r <= 0) break;
            spare.pop_back();
            {
                std::lock_guard<std::mutex> lk(mu);
                b->state = Block::Read;
                queue.push_back(b);
            }
            cv.notify_all();
        }
        if (queue.empty()) break;
        if (!helper_tried && queue.size() >= 2) start_helper();
        Block *front = queue.front();
        for (;;) { // front's values: found here, or by the helper (this thread meanwhile finds another's)
            Block *mine;
            {
                std::unique_lock<std::mutex> lk(mu);
                cv.wait(lk, [&] { return front->state != Block::Claimed || std::any_of(queue.begin(), queue.end(), [](Block *q) {
                                             return q->state == Block::Read;
                                         }); });
                if (front->state == Block::Done) break;
                mine = front->state == Block::Read ? front : claim();
                mine->state = Block::Claimed;
            }
            block_values(p, *mine, f);
            done(mine);
        }
        if (!block_rows(p, *front, err)) return false;
        {
            std::lock_guard<std::mutex> lk(mu);
            queue.pop_front();
        }
        spare.push_back(front);
    }
    return p.finish(err);
}

// Reads the source's bytes in order.
struct SourceReader {
    const DatasetSource &s;
    std::string &err;
    size_t off = 0;
    long operator()(char *buf, size_t n) {
        long r;
        if (s.is_file) {
            r = s.file.pread(buf, n, off, err);
        } else {
            r = long(std::min(n, s.text.size() - off));
            std::memcpy(buf, s.text.data() + off, size_t(r));
        }
        if (r > 0) off += size_t(r);
        return r;
    }
};

// The glitch screen (dataset_glitches.h), on a dataset just parsed by `p`:
// the suspect positions' samples are read again, and when some are set
// aside the dataset is parsed once more without them.
bool screen_glitches(Dataset &d, Parser &p, std::string &err) {
    const GlitchScreen s = glitch_suspects(d, p.range());
    d.glitch_z = s.z;
    std::copy(std::begin(s.scale), std::end(s.scale), d.glitch_scale);
    if (!s.any()) return true;
    GlitchJudge judge(d, s);
    const Tap collect = [&](size_t g, size_t row, size_t line, const double *l) {
        if (!s.suspect[g]) return;
        ScreenSample x;
        x.g = g, x.row = row, x.line = line;
        std::copy(l, l + 4, x.l);
        judge.add(x);
    };
    {
        Dataset again;
        Parser p2(d.path, again, &d, &collect);
        if (!stream_lines(SourceReader{*d.source, err}, p2, err)) return false;
    }
    std::vector<DatasetGlitch> glitches;
    std::vector<size_t> rows;
    judge.finish(glitches, rows);
    d.glitch_held = judge.peak_samples();
    if (judge.abandoned()) d.glitch_z = 0; // gave up (kGlitchMaxHeld): not screened
    if (rows.empty()) return true;
    Dataset clean;
    Parser p3(d.path, clean, nullptr, nullptr, &rows);
    if (!stream_lines(SourceReader{*d.source, err}, p3, err)) return false;
    clean.source = d.source;
    clean.glitches = std::move(glitches);
    clean.excluded_rows = std::move(rows);
    clean.glitch_z = d.glitch_z;
    clean.glitch_held = d.glitch_held;
    std::copy(std::begin(d.glitch_scale), std::end(d.glitch_scale), clean.glitch_scale);
    d = std::move(clean);
    return true;
}

bool parse_source(const std::shared_ptr<const DatasetSource> &s, const std::string &src, Dataset &out,
                  std::string &err) {
    Dataset d;
    Parser p(src, d, nullptr, nullptr);
    if (!stream_lines(SourceReader{*s, err}, p, err)) return false;
    d.source = s;
    if (!screen_glitches(d, p, err)) return false;
    out = std::move(d);
    return true;
}
} // namespace

bool parse_dataset(const std::string &text, const std::string &src, Dataset &out, std::string &err) {
    auto s = std::make_shared<DatasetSource>();
    s->text = text;
    return parse_source(s, src, out, err);
}

bool load_dataset(const std::string &path, Dataset &out, std::string &err, bool *io_failure) {
    if (io_failure) *io_failure = false;
    auto s = std::make_shared<DatasetSource>();
    s->is_file = true;
    if (!s->file.open(path, io::kDatasetMaxBytes, err, "dataset")) {
        if (io_failure) *io_failure = true;
        return false;
    }
    // A read error part-way is an I/O failure too, not a malformed file.
    bool read_failed = false;
    Dataset d;
    Parser p(path, d, nullptr, nullptr);
    if (!stream_lines(SourceReader{*s, err}, p, err, &read_failed)) {
        if (io_failure) *io_failure = read_failed;
        return false;
    }
    d.source = std::move(s);
    if (!screen_glitches(d, p, err)) {
        if (io_failure) *io_failure = true; // the file could not be read again, or changed meanwhile
        return false;
    }
    out = std::move(d);
    return true;
}

bool for_each_sample(const Dataset &d, const Visit &visit, std::string &err) {
    if (!d.source) {
        err = d.path + ": the dataset's rows cannot be read again (it was not read by load_dataset or parse_dataset)";
        return false;
    }
    Dataset again;
    const Tap tap = [&](size_t g, size_t, size_t, const double *l) { visit(g, l); };
    Parser p(d.path, again, &d, &tap, &d.excluded_rows, &d.excluded_points);
    return stream_lines(SourceReader{*d.source, err}, p, err);
}

bool without_points(const Dataset &d, const std::vector<long> &points, Dataset &out, std::string &err) {
    if (!d.source) {
        err = d.path + ": the dataset's rows cannot be read again (it was not read by load_dataset or parse_dataset)";
        return false;
    }
    std::vector<long> skip = d.excluded_points;
    skip.insert(skip.end(), points.begin(), points.end());
    std::sort(skip.begin(), skip.end());
    skip.erase(std::unique(skip.begin(), skip.end()), skip.end());
    Dataset again;
    Parser p(d.path, again, nullptr, nullptr, &d.excluded_rows, &skip);
    if (!stream_lines(SourceReader{*d.source, err}, p, err)) return false;
    if (again.pos.empty()) {
        err = d.path + ": no position would be left without points " + std::to_string(skip.size()) + " listed";
        return false;
    }
    // The heights stay the first read's (find_heights decided them on every
    // position): setting positions aside must not turn an off-height
    // reference into a height of its own (the tenth it may be of the jig
    // grows as the jig shrinks), nor a thinned height into an off-height
    // value. Only a height none of whose positions is left goes.
    {
        // (sorted x values and a search per height: a scattered jig has as
        // many heights as positions)
        std::vector<double> xs;
        for (const JigHole &jp : again.pos) xs.push_back(jp.ref[0]);
        std::sort(xs.begin(), xs.end());
        std::vector<double> kept;
        for (double h : d.heights) {
            const auto it = std::lower_bound(xs.begin(), xs.end(), h - 1e-6);
            if (it != xs.end() && std::fabs(*it - h) < 1e-6) kept.push_back(h);
        }
        std::vector<long> off;
        for (long p : d.off_height_points)
            if (!std::binary_search(skip.begin(), skip.end(), p)) off.push_back(p);
        if (!kept.empty()) {
            again.heights = std::move(kept);
            again.off_height_points = std::move(off);
        }
    }
    again.source = d.source;
    again.glitches = d.glitches;
    again.excluded_rows = d.excluded_rows;
    again.glitch_z = d.glitch_z;
    again.glitch_held = d.glitch_held;
    std::copy(std::begin(d.glitch_scale), std::end(d.glitch_scale), again.glitch_scale);
    again.excluded_points = std::move(skip);
    out = std::move(again);
    return true;
}

} // namespace cdm
