// The jig CSV reader's parts (private to calib: read.cpp is the public
// side). Parser: one line at a time, into per-position statistics
// (parser.cpp); stream_lines: a byte source fed to a Parser in
// blocks of whole lines, the lines' values found on a second thread and
// the rows taken in file order (stream.cpp).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "calib/dataset/dataset.h"
#include "calib/dataset/glitches.h"

namespace cdm {
namespace dataset_detail {

// The distinct values of one cable's readings, as a sorted vector (8 bytes
// a value) fed through a small unsorted buffer; at most `cap` are kept.
class DistinctValues {
public:
    void add(double v) {
        if (v == last_ || full_) return; // quantised data repeats itself
        last_ = v;
        // A position's samples repeat a few values: one seen lately (a
        // small table by the value's bits; it is in sorted_ or pending_
        // already) is not sorted in again. The flushes come every 4096
        // values counted, those not sorted in included, so the set kept once
        // full is the same as if each were sorted in.
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

// Feeds read(buf, n) (bytes read, 0 at the end, < 0 on error, err set) to
// the parser; see stream.cpp. read_error (optional): set when the
// failure returned is read's.
bool stream_lines(const std::function<long(char *, size_t)> &read, Parser &p, std::string &err,
                  bool *read_error = nullptr);

} // namespace dataset_detail
} // namespace cdm
