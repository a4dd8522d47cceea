// The one dataset writer (see dataset.h): the jig CSV's header, its rows as
// they come, the file committed atomically.
#include "calib/dataset.h"

#include <cmath>
#include <cstdio>

namespace cdm {

bool DatasetWriter::open(const std::string &path, const std::vector<std::string> &protect, std::string &err) {
    buf_.clear(); // the header waits for the first row: it decides the t_s column
    timed_ = -1;
    return f_.open(path, protect, err);
}

bool DatasetWriter::add_row(long point, const double ref[3], const double len[4], std::string &err, double t_s,
                            bool *usage) {
    const int timed = std::isfinite(t_s) ? 1 : 0;
    if (timed_ < 0) {
        timed_ = timed;
        buf_ = timed ? "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s\n" : "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
    } else if (timed != timed_) {
        err = std::string("dataset row for point ") + std::to_string(point) +
              (timed ? " has a time, but the file's rows have none" : " has no time, but the file's rows have t_s");
        if (usage) *usage = true;
        return false;
    }
    char line[256];
    const int n = timed ? std::snprintf(line, sizeof line, "%ld,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.6f\n", point,
                                        ref[0], ref[1], ref[2], len[0], len[1], len[2], len[3], t_s)
                        : std::snprintf(line, sizeof line, "%ld,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", point, ref[0],
                                        ref[1], ref[2], len[0], len[1], len[2], len[3]);
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
    if (timed_ < 0) buf_ = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n"; // no rows: the header alone
    timed_ = 0;
    if (!buf_.empty() && !f_.write(buf_, err)) return false;
    buf_.clear();
    return f_.commit(err);
}

} // namespace cdm
