// See panels.h.
#include "calib/diagnosis/panels.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {

// Fewer values than this in a bin make its mean too noisy to compare.
constexpr int kMinPerBin = 10;
constexpr int kMaxBins = 10;

struct Series {
    const char *panel, *variable;
    int cable; // 1-4, 0: not a cable's
    int axis;  // 0-2 a position axis, -1 the cable's reading
    std::vector<double> x, y;
};

} // namespace

BinnedTrend binned_trend(const std::vector<double> &x, const std::vector<double> &y, int bins) {
    BinnedTrend t;
    std::vector<size_t> idx;
    for (size_t i = 0; i < x.size() && i < y.size(); ++i)
        if (std::isfinite(x[i]) && std::isfinite(y[i])) idx.push_back(i);
    const int n = int(idx.size());
    bins = std::min(bins, n / kMinPerBin);
    if (bins < 3) return t;
    std::stable_sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return x[a] < x[b]; });
    std::vector<double> sum(size_t(bins), 0.0), cnt(size_t(bins), 0.0);
    for (int r = 0; r < n; ++r) {
        const size_t b = size_t(int64_t(r) * bins / n);
        sum[b] += y[idx[size_t(r)]];
        cnt[b] += 1;
    }
    double total = 0, lo = INFINITY, hi = -INFINITY;
    for (int b = 0; b < bins; ++b) {
        total += sum[size_t(b)];
        const double m = sum[size_t(b)] / cnt[size_t(b)];
        lo = std::min(lo, m), hi = std::max(hi, m);
    }
    const double grand = total / n;
    double between = 0, within = 0;
    for (int r = 0; r < n; ++r) {
        const size_t b = size_t(int64_t(r) * bins / n);
        const double d = y[idx[size_t(r)]] - sum[b] / cnt[b];
        within += d * d;
    }
    for (int b = 0; b < bins; ++b) {
        const double d = sum[size_t(b)] / cnt[size_t(b)] - grand;
        between += cnt[size_t(b)] * d * d;
    }
    t.bins = bins;
    t.d1 = bins - 1;
    t.d2 = n - bins;
    t.F = within > 0 ? (between / t.d1) / (within / t.d2) : (between > 0 ? INFINITY : 0.0);
    t.p = std::isfinite(t.F) ? f_sf(t.F, t.d1, t.d2) : 0.0;
    t.range_mm = hi - lo;
    return t;
}

json panel_trends(const std::vector<PreparedPos> &pos, const Eval &E, const LengthView &lv) {
    const size_t P = pos.size();
    std::vector<Series> s;
    auto position_series = [&](const char *var, int cable, auto value) {
        for (int a = 0; a < 3; ++a) {
            Series q{"vs_variables", var, cable, a, {}, {}};
            for (size_t j = 0; j < P; ++j)
                if (j < E.ok.size() && E.ok[j] && j < E.res.size()) {
                    q.x.push_back(value(j));
                    q.y.push_back(E.res[j](a));
                }
            s.push_back(std::move(q));
        }
    };
    position_series("height", 0, [&](size_t j) { return pos[j].ref(0); });
    position_series("radius", 0, [&](size_t j) { return std::hypot(pos[j].ref(1), pos[j].ref(2)); });
    for (int c = 0; c < 4; ++c) {
        if (lv.lmean.size() != P) break;
        position_series("length", c + 1, [&](size_t j) { return lv.lmean[j][size_t(c)]; });
        position_series("angle", c + 1, [&](size_t j) { return lv.angle[j][size_t(c)]; });
        Series q{"vs_cable_length", "length", c + 1, -1, {}, {}};
        for (size_t j = 0; j < P; ++j) {
            q.x.push_back(lv.lmean[j][size_t(c)]);
            q.y.push_back(lv.lres[j][size_t(c)]);
        }
        s.push_back(std::move(q));
    }
    json out = json::array();
    const double M = double(s.size());
    static const char *kAxis[3] = {"x", "y", "z"};
    for (const Series &q : s) {
        const BinnedTrend t = binned_trend(q.x, q.y, kMaxBins);
        if (t.bins == 0) continue;
        const double p = false_alarm(t.p, M);
        out.push_back({{"panel", q.panel}, {"variable", q.variable},
                       {"cable", q.cable ? json(q.cable) : json(nullptr)},
                       {"axis", q.axis >= 0 ? kAxis[q.axis] : "reading"},
                       {"F", std::isfinite(t.F) ? json(t.F) : json(nullptr)}, {"dof", {t.d1, t.d2}},
                       {"p_value", p}, {"range_mm", t.range_mm}, {"significant", p < kFindingLevel}});
    }
    return out;
}

} // namespace diag
} // namespace cdm
