#include "jig/plan.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

namespace cdm {

bool check_jig_options(const JigPlanOptions &o, std::string &err) {
    if (o.n < 1 || o.n > 1000) {
        err = "jig_n must be 1..1000, got " + std::to_string(o.n);
        return false;
    }
    if (!(o.pitch_mm > 0) || !std::isfinite(o.pitch_mm)) {
        err = "jig_pitch must be a positive number of mm";
        return false;
    }
    if (o.heights_mm.empty()) {
        err = "jig_heights must list at least one height";
        return false;
    }
    for (size_t i = 0; i < o.heights_mm.size(); ++i) {
        const double h = o.heights_mm[i];
        if (!(h > 0) || !std::isfinite(h)) {
            err = "jig_heights must be positive (mm from the cable plane)";
            return false;
        }
        // One fixture setting is one height: a repeat would visit each of
        // its holes twice under one position's label.
        for (size_t k = 0; k < i; ++k)
            if (o.heights_mm[k] == h) {
                char text[64];
                std::snprintf(text, sizeof text, "%g", h);
                err = "jig_heights lists " + std::string(text) + " mm twice (each height is one fixture setting)";
                return false;
            }
    }
    if (o.samples < 1) {
        err = "jig_samples must be at least 1, got " + std::to_string(o.samples);
        return false;
    }
    return true;
}

std::vector<JigPosition> make_jig_plan(const JigPlanOptions &o) {
    std::vector<JigPosition> plan;
    plan.reserve(size_t(o.n) * o.n * o.heights_mm.size());
    // Centred: (n-1)/2 is a half-integer for even n, so an even plate has no
    // hole at the centre, as a real even plate would not.
    const double c = (o.n - 1) / 2.0;
    int id = 0;
    for (size_t h = 0; h < o.heights_mm.size(); ++h) {
        for (int r = 0; r < o.n; ++r) {
            for (int k = 0; k < o.n; ++k) {
                JigPosition p;
                p.point = id++;
                p.height_index = int(h);
                p.row = r;
                p.col = k;
                p.ref[0] = o.heights_mm[h];
                p.ref[1] = (r - c) * o.pitch_mm;
                p.ref[2] = (k - c) * o.pitch_mm;
                plan.push_back(p);
            }
        }
    }
    return plan;
}

std::vector<JigPosition> make_scattered_plan(const JigPlanOptions &o, uint64_t seed) {
    std::vector<JigPosition> plan = make_jig_plan(o);
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    double hlo = o.heights_mm.front(), hhi = hlo;
    for (double h : o.heights_mm) {
        hlo = std::min(hlo, h);
        hhi = std::max(hhi, h);
    }
    const double half = (o.n - 1) / 2.0 * o.pitch_mm;
    for (auto &p : plan) {
        p.height_index = p.row = p.col = -1;
        p.ref[0] = hlo + (hhi - hlo) * u(rng);
        p.ref[1] = (2 * u(rng) - 1) * half;
        p.ref[2] = (2 * u(rng) - 1) * half;
    }
    return plan;
}

bool parse_heights(const std::string &text, std::vector<double> &out, std::string &err) {
    std::vector<double> v;
    size_t start = 0;
    while (start <= text.size()) {
        size_t end = text.find(',', start);
        if (end == std::string::npos) end = text.size();
        const std::string item = text.substr(start, end - start);
        char *stop = nullptr;
        errno = 0;
        const double h = item.empty() ? 0.0 : std::strtod(item.c_str(), &stop);
        if (item.empty() || errno != 0 || *stop != '\0' || !(h > 0) || !std::isfinite(h)) {
            err = "jig heights: \"" + item + "\" in \"" + text + "\" is not a positive number of mm";
            return false;
        }
        v.push_back(h);
        start = end + 1;
    }
    out = v;
    return true;
}

} // namespace cdm
