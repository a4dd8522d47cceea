// Glitch screening of a jig dataset: the test is in glitches.h.
#include "calib/dataset/glitches.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <nlohmann/json.hpp>

#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>

namespace cdm {

namespace {

// Median of chi-square(k) / k.
double chi2_median_ratio(double k) { return boost::math::median(boost::math::chi_squared(k)) / k; }

double median(std::vector<double> &v) {
    const size_t h = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(h), v.end());
    const double hi = v[h];
    if (v.size() % 2) return hi;
    return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + std::ptrdiff_t(h)));
}

constexpr double kScreenAlpha = 0.01;   // family-wise, over every reading
constexpr int kScreenMinSamples = 3;    // a median needs three
constexpr size_t kScreenMinPositions = 10; // for the pooled noise scale
constexpr double kMadToSd = 1.4826;     // Gaussian consistency of the MAD

} // namespace

double glitch_inflation(int n) { return std::sqrt(1 + 1.5707963267948966 / double(n)); }

bool GlitchScreen::any() const { return std::find(suspect.begin(), suspect.end(), 1) != suspect.end(); }

GlitchScreen glitch_suspects(const Dataset &d, const std::vector<ReadingRange> &range) {
    GlitchScreen s;
    if (d.rows == 0) return s;
    for (int c = 0; c < 4; ++c) {
        std::vector<double> v;
        for (auto &p : d.pos)
            if (p.n >= kScreenMinSamples) v.push_back(p.cov[c][c] / chi2_median_ratio(p.n - 1));
        if (v.size() < kScreenMinPositions) return GlitchScreen{}; // too few positions to know the noise
        s.scale[c] = std::max(std::sqrt(std::max(0.0, median(v))), d.resolution[c]);
    }
    s.z = boost::math::quantile(boost::math::complement(boost::math::normal(), kScreenAlpha / (8.0 * double(d.rows))));
    s.suspect.assign(d.pos.size(), 0);
    for (size_t g = 0; g < d.pos.size(); ++g) {
        const JigHole &p = d.pos[g];
        if (p.n < kScreenMinSamples) continue;
        // A reading is set aside only when |reading - median| > t, t at
        // least z * inflate * scale; then the extreme on its side is as far
        // from the median, and the median is within the readings'
        // (population) sd of their mean, for any distribution (Hotelling and
        // Solomons). So a position can hold a glitch only when an extreme
        // is more than t - sd from the mean: on clean data about one
        // position in a thousand, where the range alone let through 40 %.
        const double t = s.z * glitch_inflation(p.n);
        for (int c = 0; c < 4; ++c) {
            if (!(s.scale[c] > 0)) continue;
            const double sd = std::sqrt(std::max(0.0, p.cov[c][c]) * double(p.n - 1) / double(p.n));
            const double room = t * s.scale[c] - sd;
            if (range[g][4 + size_t(c)] - p.mean[c] > room || p.mean[c] - range[g][size_t(c)] > room) s.suspect[g] = 1;
        }
    }
    return s;
}

void GlitchJudge::add(const ScreenSample &x) {
    if (abandoned_) return;
    if (open_.empty()) open_.resize(d_.pos.size());
    if (held_ >= kGlitchMaxHeld) {
        // An interleaved file (or one enormous position): its suspects'
        // samples would pile up; the screen gives up rather than the memory.
        abandoned_ = true;
        std::vector<std::vector<ScreenSample>>().swap(open_);
        held_ = 0;
        return;
    }
    auto &v = open_[x.g];
    v.push_back(x);
    peak_ = std::max(peak_, ++held_);
    if (v.size() < size_t(d_.pos[x.g].n)) return;
    judge(v);
    held_ -= v.size();
    std::vector<ScreenSample>().swap(v);
}

void GlitchJudge::judge(std::vector<ScreenSample> &samples) {
    const size_t n = samples.size();
    std::vector<double> v;
    double med[4], sd[4];
    // The median is itself estimated (variance pi/2 sigma^2/n for Gaussian
    // noise): a reading's distance to it has sd sigma * sqrt(1 + pi/(2n)),
    // without which 3 samples a position would lose a clean one in about
    // one dataset of twelve instead of one of a hundred.
    const double inflate = glitch_inflation(int(n));
    for (int c = 0; c < 4; ++c) {
        v.clear();
        for (auto &x : samples) v.push_back(x.l[c]);
        med[c] = median(v);
        for (auto &y : v) y = std::fabs(y - med[c]);
        sd[c] = inflate * std::max(s_.scale[c], kMadToSd * median(v));
    }
    std::vector<DatasetGlitch> here;
    std::vector<size_t> here_rows;
    for (auto &x : samples) {
        int worst = -1;
        double zmax = 0;
        for (int c = 0; c < 4; ++c) {
            if (!(sd[c] > 0)) continue;
            const double z = std::fabs(x.l[c] - med[c]) / sd[c];
            if (z > zmax) zmax = z, worst = c;
        }
        if (zmax > s_.z) {
            DatasetGlitch gl;
            gl.line = x.line;
            gl.point = d_.pos[x.g].point;
            gl.cable = worst + 1;
            gl.reading = x.l[worst];
            gl.median = med[worst];
            gl.z = zmax;
            here.push_back(gl);
            here_rows.push_back(x.row);
        }
    }
    // Glitches are rare; a quarter of a position's samples apart is two
    // populations, not glitches (glitches.h).
    if (!here.empty() && here.size() <= std::max<size_t>(1, n / 4)) {
        glitches_.insert(glitches_.end(), here.begin(), here.end());
        rows_.insert(rows_.end(), here_rows.begin(), here_rows.end());
    }
}

void GlitchJudge::finish(std::vector<DatasetGlitch> &glitches, std::vector<size_t> &rows) {
    if (abandoned_) {
        glitches.clear();
        rows.clear();
        return;
    }
    // Every suspect position is complete after a whole pass; what is still
    // open would be a file that changed, which the pass itself refuses.
    for (auto &v : open_)
        if (!v.empty()) judge(v);
    open_.clear();
    std::sort(glitches_.begin(), glitches_.end(),
              [](const DatasetGlitch &a, const DatasetGlitch &b) { return a.line < b.line; });
    std::sort(rows_.begin(), rows_.end());
    glitches = std::move(glitches_);
    rows = std::move(rows_);
}

// See dataset.h.
nlohmann::json glitches_json(const Dataset &d) {
    std::set<long> points;
    nlohmann::json list = nlohmann::json::array();
    for (auto &g : d.glitches) {
        points.insert(g.point);
        if (list.size() < kGlitchesListed)
            list.push_back({{"line", g.line}, {"point", g.point}, {"cable", g.cable}, {"reading_mm", g.reading},
                            {"median_mm", g.median}, {"sd", g.z}});
    }
    return {{"screened", d.glitch_z > 0},
            {"count", d.glitches.size()},
            {"positions", points.size()},
            {"threshold_sd", d.glitch_z},
            {"noise_sd_mm", std::vector<double>(d.glitch_scale, d.glitch_scale + 4)},
            {"test", "|reading - position median| > threshold_sd * max(cable's pooled noise sd, position's 1.4826 MAD); "
                     "threshold: two-sided Gaussian, Bonferroni 0.01 over every reading, times sqrt(1 + pi/(2n)) for the "
                     "median of n samples; not screened (screened: false) with fewer than 10 positions of 3 samples or "
                     "when the suspects' samples would exceed 2^20 held at once"},
            {"samples", list}};
}

} // namespace cdm
