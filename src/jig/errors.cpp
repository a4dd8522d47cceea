#include "jig/errors.h"

#include <algorithm>
#include <random>

namespace cdm {

std::vector<std::array<double, 3>> jig_true_positions(const std::vector<JigPosition> &plan, int n_holes_per_side,
                                                      const JigErrorOptions &o) {
    // Each component has its own stream, so switching one on or off leaves
    // the others' draws unchanged (a test can add a fixture error to the
    // same holes).
    std::normal_distribution<double> g(0.0, 1.0);
    std::mt19937_64 hole_rng(o.seed), fixture_rng(o.seed ^ 0xA5A5A5A5DEADBEEFull), seat_rng(o.seed * 31 + 7);
    const size_t holes = size_t(n_holes_per_side) * size_t(n_holes_per_side);
    std::vector<double> hole(2 * holes), fixture;
    for (double &e : hole) e = o.hole_mm * g(hole_rng);
    int heights = 0;
    for (const auto &p : plan) heights = std::max(heights, p.height_index + 1);
    fixture.resize(size_t(heights));
    for (double &e : fixture) e = o.fixture_mm * g(fixture_rng);
    std::vector<std::array<double, 3>> out;
    out.reserve(plan.size());
    for (const auto &p : plan) {
        std::array<double, 3> t{p.ref[0], p.ref[1], p.ref[2]};
        if (p.height_index >= 0) t[0] += fixture[size_t(p.height_index)];
        if (p.row >= 0 && p.col >= 0) {
            const size_t h = size_t(p.row) * size_t(n_holes_per_side) + size_t(p.col);
            t[1] += hole[2 * h];
            t[2] += hole[2 * h + 1];
        }
        for (double &v : t) v += o.seat_mm * g(seat_rng);
        out.push_back(t);
    }
    return out;
}

} // namespace cdm
