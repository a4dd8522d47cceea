// See heights.h.
#include "calib/dataset/heights.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <utility>
#include <vector>

namespace cdm {

// Dataset::heights and off_height_points (dataset.h). Equal x_ref: within
// 1e-6 mm (the CSV's four decimals).
void find_heights(Dataset &d) {
    struct X {
        double x;
        long point;
        size_t pos; // index in d.pos
        bool operator<(const X &o) const { return x < o.x || (x == o.x && point < o.point); }
    };
    std::vector<X> xs;
    for (size_t j = 0; j < d.pos.size(); ++j) xs.push_back({d.pos[j].ref[0], d.pos[j].point, j});
    std::sort(xs.begin(), xs.end());
    // Runs of equal x_ref: [first, end) in xs.
    std::vector<std::pair<size_t, size_t>> runs;
    size_t largest = 0;
    for (size_t i = 0; i < xs.size();) {
        size_t k = i + 1;
        while (k < xs.size() && std::fabs(xs[k].x - xs[i].x) < 1e-6) ++k;
        runs.emplace_back(i, k);
        largest = std::max(largest, k - i);
        i = k;
    }
    // A plate hole: (y_ref, z_ref) at the CSV's resolution.
    auto hole = [&](size_t j) {
        return std::make_pair(std::llround(d.pos[j].ref[1] * 1e5), std::llround(d.pos[j].ref[2] * 1e5));
    };
    // The full heights: shared by at least two positions and a quarter as
    // many as the fullest.
    std::vector<size_t> full;
    for (size_t r = 0; r < runs.size(); ++r) {
        const size_t m = runs[r].second - runs[r].first;
        if (m >= 2 && 4 * m >= largest) full.push_back(r);
    }
    // Each full height's holes, built when a smaller group first asks.
    std::vector<std::set<std::pair<long long, long long>>> holes_of(runs.size());
    std::vector<double> all, shared;
    std::vector<long> alone;
    for (size_t r = 0; r < runs.size(); ++r) {
        const auto [i, k] = runs[r];
        all.push_back(xs[i].x);
        bool height = std::find(full.begin(), full.end(), r) != full.end();
        if (!height && k - i >= 2 && !full.empty()) {
            // A smaller group is a height when it measures holes the nearest
            // full height also has (a height with fewer holes, or one the
            // recording stopped part-way through); references moved off a
            // height to the same wrong x (a typed value, a spacer left in for
            // two holes) are that height's missing holes. As a height of
            // their own they had an offset that absorbed their error and no
            // neighbours.
            size_t near = full.front();
            for (size_t f : full)
                if (std::fabs(xs[runs[f].first].x - xs[i].x) < std::fabs(xs[runs[near].first].x - xs[i].x)) near = f;
            auto &holes = holes_of[near];
            if (holes.empty())
                for (size_t j = runs[near].first; j < runs[near].second; ++j) holes.insert(hole(xs[j].pos));
            for (size_t j = i; j < k && !height; ++j) height = holes.count(hole(xs[j].pos)) > 0;
        }
        if (height) shared.push_back(xs[i].x);
        else
            for (size_t j = i; j < k; ++j) alone.push_back(xs[j].point);
    }
    d.off_height_points.clear();
    if (!shared.empty() && !alone.empty() && alone.size() * 10 <= xs.size()) {
        d.heights = std::move(shared);
        std::sort(alone.begin(), alone.end());
        d.off_height_points = std::move(alone);
    } else {
        d.heights = std::move(all);
    }
}

} // namespace cdm
