// Test helpers: the diagnosis tests' simulated jig, and a simulated jig
// dataset as CSV lines, to be tampered with (spikes in the readings,
// misplaced references) before it is parsed. Include after <cmocka.h>.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <random>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "calib/dataset/simulate.h"

namespace cdm {
namespace test {

// The half-resolution jig the diagnosis tests simulate: 13 x 13 holes at
// 10 mm, 40 samples, 5 heights, noise seed `seed`.
inline JigSimOptions half_jig(uint64_t seed) {
    JigSimOptions o;
    o.n = 13;
    o.pitch_mm = 10;
    o.samples = 40;
    o.seed = seed;
    return o;
}

// The simulator's CSV as lines (header first).
inline std::vector<std::string> simulated_lines(const JigSimOptions &o, const Model &truth = Model{DeviceGeometry{}}) {
    char p[] = "/tmp/cdm_gl_XXXXXX";
    const int fd = mkstemp(p);
    assert_true(fd >= 0);
    close(fd);
    std::string err;
    if (!simulate_jig_csv(truth, o, p, {}, err)) fail_msg("%s", err.c_str());
    std::vector<std::string> lines;
    FILE *f = std::fopen(p, "r");
    assert_non_null(f);
    char buf[512];
    while (std::fgets(buf, sizeof buf, f)) {
        std::string s(buf);
        if (!s.empty() && s.back() == '\n') s.pop_back();
        lines.push_back(s);
    }
    std::fclose(f);
    unlink(p);
    return lines;
}

inline std::string join(const std::vector<std::string> &lines) {
    std::string t;
    for (auto &l : lines) t += l + "\n";
    return t;
}

// Adds `mm` to cable `c` (0-3) of the data line `lines[k]`.
inline void spike(std::vector<std::string> &lines, size_t k, int c, double mm) {
    std::vector<std::string> f;
    std::stringstream ss(lines[k]);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    char v[64];
    std::snprintf(v, sizeof v, "%.4f", std::atof(f[size_t(4 + c)].c_str()) + mm);
    f[size_t(4 + c)] = v;
    std::string s;
    for (size_t i = 0; i < f.size(); ++i) s += (i ? "," : "") + f[i];
    lines[k] = s;
}

// Adds to every reading of each position an offset of its own per cable,
// N(0, sd^2), the same for all the position's samples (a pot's hysteresis,
// a wiper's offset per approach): each mean reading's own white error.
inline void per_position_offsets(std::vector<std::string> &lines, double sd, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> g(0.0, sd);
    std::string point;
    double off[4] = {0, 0, 0, 0};
    for (size_t k = 1; k < lines.size(); ++k) {
        const std::string p = lines[k].substr(0, lines[k].find(','));
        if (p != point) {
            point = p;
            for (double &o : off) o = g(rng);
        }
        for (int c = 0; c < 4; ++c) spike(lines, k, c, off[c]);
    }
}

// Moves the reference of every row of `point` by (0, dy, dz) mm: the jig
// says the probe was there, it was not (a mis-seated probe, a wrong hole).
inline void misplace(std::vector<std::string> &lines, long point, double dy, double dz) {
    const std::string id = std::to_string(point) + ",";
    for (size_t k = 1; k < lines.size(); ++k) {
        if (lines[k].compare(0, id.size(), id) != 0) continue;
        std::vector<std::string> f;
        std::stringstream ss(lines[k]);
        for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
        char v[64];
        std::snprintf(v, sizeof v, "%.4f", std::atof(f[2].c_str()) + dy);
        f[2] = v;
        std::snprintf(v, sizeof v, "%.4f", std::atof(f[3].c_str()) + dz);
        f[3] = v;
        std::string s;
        for (size_t i = 0; i < f.size(); ++i) s += (i ? "," : "") + f[i];
        lines[k] = s;
    }
}

} // namespace test
} // namespace cdm
