// The one dataset writer (see dataset.h): the jig CSV's header, its rows as
// they come, the file committed atomically. A row is checked, as the file
// would hold it, by the reader's own rule before a byte of it is kept, so a
// file this writer commits is one load_dataset reads.
#include "calib/dataset/dataset.h"

#include <charconv>
#include <cmath>
#include <cstring>

namespace cdm {

namespace {

const char *const kHeader = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4";

// The caller's value, shortest form ("nan", "-1", "1e-05"): what a message
// shows of it.
std::string shortest(double v) {
    char b[32];
    const auto r = std::to_chars(b, b + sizeof b, v);
    return std::string(b, r.ptr);
}

// A row as it is built: fields appended with '.' as the decimal point
// whatever the locale (printf's %f would write "30,0000" under a comma
// locale, which the reader splits into two fields).
struct Line {
    char buf[512]; // fits any row: the checked fields are short, and a finite t_s has at most 309 digits
    char *p = buf;
    bool fits = true;
    char *end() { return buf + sizeof buf; }
    const char *field = buf; // the last field appended
    // Appends ",v" with `decimals` decimals.
    void fixed(double v, int decimals) {
        if (!fits || p == end()) return void(fits = false);
        *p++ = ',';
        field = p;
        const auto r = std::to_chars(p, end(), v, std::chars_format::fixed, decimals);
        fits = r.ec == std::errc();
        p = r.ptr;
    }
    // What the reader gets back from the last field appended.
    double read_back() const {
        double v = NAN;
        std::from_chars(field, p, v);
        return v;
    }
    std::string last() const { return std::string(field, size_t(p - field)); }
};

} // namespace

bool DatasetWriter::open(const std::string &path, const std::vector<std::string> &protect, std::string &err) {
    buf_.clear(); // the header waits for the first row: it decides the t_s column
    timed_ = -1;
    committed_ = false;
    failed_.clear();
    refs_.clear();
    path_ = path;
    return f_.open(path, protect, err);
}

bool DatasetWriter::add_row(long point, const double ref[3], const double len[4], std::string &err, double t_s,
                            bool *usage) {
    auto refuse = [&](const std::string &why) {
        err = "dataset row for point " + std::to_string(point) + ": " + why;
        if (usage) *usage = true;
        return false;
    };
    if (committed_) return refuse(path_ + " was already committed; a row added now would be lost (open a new writer)");
    if (!failed_.empty()) {
        err = failed_ + " (an earlier failure ended this dataset: nothing more is written)";
        return false;
    }
    const int timed = std::isfinite(t_s) ? 1 : 0;
    if (timed_ >= 0 && timed != timed_)
        return refuse(timed ? "has a time, but the file's rows have none"
                            : "has no time, but the file's rows have t_s");

    // The row, checked value by value as the reader will read it back.
    static const char *const kArg[kDatasetValues] = {"point",          "ref_mm[0] (x_ref)",  "ref_mm[1] (y_ref)",
                                                     "ref_mm[2] (z_ref)", "lengths_mm[0] (l1)", "lengths_mm[1] (l2)",
                                                     "lengths_mm[2] (l3)", "lengths_mm[3] (l4)"};
    Line line;
    if (const DatasetFault f = dataset_value_fault(0, double(point)); f != DatasetFault::None)
        return refuse(dataset_fault_text(f, 0, kArg[0], std::to_string(point)));
    line.p = std::to_chars(line.buf, line.end(), point).ptr;
    double written[kDatasetValues] = {double(point)};
    for (int k = 1; k < kDatasetValues; ++k) {
        const double v = k < 4 ? ref[k - 1] : len[k - 4];
        if (!std::isfinite(v)) return refuse(dataset_fault_text(DatasetFault::NotFinite, k, kArg[k], shortest(v)));
        line.fixed(v, 4);
        if (!line.fits) break;
        written[k] = line.read_back();
        if (const DatasetFault f = dataset_value_fault(k, written[k]); f != DatasetFault::None) {
            const std::string shown = written[k] == v ? shortest(v) : shortest(v) + ", " + line.last() + " in the file";
            return refuse(dataset_fault_text(f, k, kArg[k], shown));
        }
    }
    if (timed) line.fixed(t_s, 6);
    if (!line.fits || line.p == line.end()) // cannot happen with checked values; never a partial row
        return refuse("does not fit a CSV line of " + std::to_string(sizeof line.buf) + " characters");
    *line.p++ = '\n';
    const auto known = refs_.find(point);
    if (known != refs_.end())
        for (int k = 0; k < 3; ++k)
            if (known->second[size_t(k)] != written[1 + k])
                return refuse(std::string(kArg[1 + k]) + " is " + shortest(ref[k]) +
                              " but the point's first row gave " + shortest(known->second[size_t(k)]) +
                              ": a point's reference is fixed (the reader refuses a file where it moves)");

    // Accepted: from here on the row is the file's.
    if (timed_ < 0) {
        timed_ = timed;
        buf_ = std::string(kHeader) + (timed ? ",t_s\n" : "\n");
    }
    if (known == refs_.end()) refs_.emplace(point, std::array<double, 3>{written[1], written[2], written[3]});
    buf_.append(line.buf, size_t(line.p - line.buf));
    // Flush in 64 kB pieces: bounded memory for long recordings.
    if (buf_.size() >= 65536) {
        if (!f_.write(buf_, err)) { // AtomicFile abandoned the temporary: the file is lost
            failed_ = err;
            return false;
        }
        buf_.clear();
    }
    return true;
}

bool DatasetWriter::commit(std::string &err, bool *usage) {
    if (committed_) {
        err = path_ + ": the dataset was already committed (a writer commits once)";
        if (usage) *usage = true;
        return false;
    }
    if (!failed_.empty()) {
        err = failed_ + " (an earlier failure ended this dataset: nothing more is written)";
        return false;
    }
    // No row: a file the reader refuses ("no rows"), and it would replace
    // whatever `path` held (an earlier session's dataset lost to one that
    // recorded nothing). Refused; the writer can still take rows.
    if (timed_ < 0) {
        err = path_ + ": no row was added: nothing to commit, the file is left as it was";
        if (usage) *usage = true;
        return false;
    }
    if ((!buf_.empty() && !f_.write(buf_, err)) || !f_.commit(err)) {
        failed_ = err;
        return false;
    }
    buf_.clear();
    buf_.shrink_to_fit();
    committed_ = true;
    return true;
}

} // namespace cdm
