// Jig datasets: CSV `point,x_ref,y_ref,z_ref,l1,l2,l3,l4` (extra columns
// ignored and reported), grouped into per-position statistics.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "io/file.h"

namespace cdm {

struct JigHole {
    long point = 0;
    double ref[3] = {0, 0, 0};
    int n = 0;               // samples
    double mean[4] = {0, 0, 0, 0};
    double cov[4][4] = {};   // sample covariance of the readings (n-1)
    size_t first = 0;        // index of its first sample in Dataset::samples
    // Acquisition order, for drift over the session (issue 8 item 5). Rows
    // of a jig CSV are in acquisition order; without a time column the time
    // is the mean row index times kDatasetNominalRowPeriodS (a nominal
    // figure, so a drift rate from it is per nominal second).
    double mean_row = 0;     // mean 0-based data-row index of its samples
    double t_s = 0;          // mean acquisition time (s)
};

// Nominal time between two jig CSV rows when the file has no time column.
constexpr double kDatasetNominalRowPeriodS = 0.01;

struct Dataset {
    std::string path;
    size_t rows = 0;
    std::vector<std::string> ignored_columns;
    std::vector<JigHole> pos;                 // in order of first appearance
    std::vector<std::array<double, 4>> samples;   // grouped by position
    std::vector<double> heights;                  // distinct x_ref, sorted
};

// Sane magnitudes (mm). A jig reference beyond 5 m from the origin, or a
// cable length outside (0, 10 m], is a unit error or corrupt data, not a
// master of this kind (frames of 10 mm..5 m, see io/device_json.h).
constexpr double kDatasetMaxRefMm = 5000.0;
constexpr double kDatasetMaxLengthMm = 10000.0;

// Parses and groups. On error returns false with `err` naming the file,
// line and column (1-based), e.g. "jig.csv:17:6: l2 is not a number: 'abc'".
// Refuses duplicate columns, non-finite values and magnitudes outside the
// ranges above; a field echoed in a message is cut to ~40 characters.
// `io_failure` (optional) tells a file that could not be read (missing,
// special, too large: CDM_ERR_IO) from one that does not parse.
bool load_dataset(const std::string &path, Dataset &out, std::string &err, bool *io_failure = nullptr);
bool parse_dataset(const std::string &text, const std::string &source, Dataset &out, std::string &err);

// The one dataset writer: the header, then add_row() per sample, then
// commit() (atomic: io::AtomicFile). Rows are written as they come, so a
// recording need not be held in memory. Destroyed without commit(): no file.
class DatasetWriter {
public:
    bool open(const std::string &path, const std::vector<std::string> &protect_paths, std::string &err);
    bool add_row(long point, const double ref[3], const double lengths[4], std::string &err);
    bool commit(std::string &err);

private:
    io::AtomicFile f_;
    std::string buf_;
};



} // namespace cdm
