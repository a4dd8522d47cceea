// Test helper: a simulated jig dataset as CSV lines, to be tampered with
// (spikes in the readings) before it is parsed. Include after <cmocka.h>.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "calib/simulate.h"

namespace cdm {
namespace test {

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

} // namespace test
} // namespace cdm
