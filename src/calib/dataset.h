// Jig datasets: CSV `point,x_ref,y_ref,z_ref,l1,l2,l3,l4` (extra columns
// ignored and reported), grouped into per-position statistics.
#pragma once

#include <array>
#include <string>
#include <vector>

namespace cdm {

struct JigHole {
    long point = 0;
    double ref[3] = {0, 0, 0};
    int n = 0;               // samples
    double mean[4] = {0, 0, 0, 0};
    double cov[4][4] = {};   // sample covariance of the readings (n-1)
    size_t first = 0;        // index of its first sample in Dataset::samples
};

struct Dataset {
    std::string path;
    size_t rows = 0;
    std::vector<std::string> ignored_columns;
    std::vector<JigHole> pos;                 // in order of first appearance
    std::vector<std::array<double, 4>> samples;   // grouped by position
    std::vector<double> heights;                  // distinct x_ref, sorted
};

// Parses and groups. On error returns false with `err` naming the file,
// line and column (1-based), e.g. "jig.csv:17:6: l2 is not a number: 'abc'".
bool load_dataset(const std::string &path, Dataset &out, std::string &err);
bool parse_dataset(const std::string &text, const std::string &source, Dataset &out, std::string &err);

// Writes a dataset CSV atomically (FILE.tmp then rename).
bool write_dataset_csv(const std::string &path, const std::vector<long> &point,
                       const std::vector<std::array<double, 3>> &ref,
                       const std::vector<std::array<double, 4>> &lengths, std::string &err);

} // namespace cdm
