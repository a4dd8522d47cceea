// Glitch screening of a jig dataset: the test is in dataset_glitches.h.
#include "calib/dataset_glitches.h"

#include <algorithm>
#include <cmath>

#include <boost/math/distributions/normal.hpp>

namespace cdm {

namespace {

// Median of chi-square(k) / k (Wilson-Hilferty; within 0.3 % for k >= 2).
double chi2_median_ratio(double k) { return std::pow(1 - 2 / (9 * k), 3); }

double median(std::vector<double> &v) {
    const size_t h = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(h), v.end());
    const double hi = v[h];
    if (v.size() % 2) return hi;
    return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + std::ptrdiff_t(h)));
}

constexpr double kScreenAlpha = 0.01;   // family-wise, over every reading
constexpr int kScreenMinSamples = 3;    // a median needs three
constexpr double kMadToSd = 1.4826;     // Gaussian consistency of the MAD

} // namespace

bool GlitchScreen::any() const { return std::find(suspect.begin(), suspect.end(), 1) != suspect.end(); }

GlitchScreen glitch_suspects(const Dataset &d, const std::vector<ReadingRange> &range) {
    GlitchScreen s;
    if (d.rows == 0) return s;
    for (int c = 0; c < 4; ++c) {
        std::vector<double> v;
        for (auto &p : d.pos)
            if (p.n >= kScreenMinSamples) v.push_back(p.cov[c][c] / chi2_median_ratio(p.n - 1));
        if (v.size() < 3) return GlitchScreen{}; // too few positions to know the noise
        s.scale[c] = std::max(std::sqrt(std::max(0.0, median(v))), d.resolution[c]);
    }
    s.z = boost::math::quantile(boost::math::complement(boost::math::normal(), kScreenAlpha / (8.0 * double(d.rows))));
    s.suspect.assign(d.pos.size(), 0);
    for (size_t g = 0; g < d.pos.size(); ++g) {
        if (d.pos[g].n < kScreenMinSamples) continue;
        for (int c = 0; c < 4; ++c)
            if (s.scale[c] > 0 && range[g][4 + size_t(c)] - range[g][size_t(c)] > s.z * s.scale[c]) s.suspect[g] = 1;
    }
    return s;
}

void glitch_flags(const Dataset &d, const GlitchScreen &s, std::vector<ScreenSample> &samples,
                  std::vector<DatasetGlitch> &glitches, std::vector<size_t> &rows) {
    std::stable_sort(samples.begin(), samples.end(),
                     [](const ScreenSample &a, const ScreenSample &b) { return a.g < b.g; });
    std::vector<double> v;
    std::vector<DatasetGlitch> here;
    std::vector<size_t> here_rows;
    for (size_t b = 0; b < samples.size();) {
        size_t e = b;
        while (e < samples.size() && samples[e].g == samples[b].g) ++e;
        const size_t n = e - b;
        double med[4], sd[4];
        for (int c = 0; c < 4; ++c) {
            v.clear();
            for (size_t k = b; k < e; ++k) v.push_back(samples[k].l[c]);
            med[c] = median(v);
            for (auto &x : v) x = std::fabs(x - med[c]);
            sd[c] = std::max(s.scale[c], kMadToSd * median(v));
        }
        here.clear();
        here_rows.clear();
        for (size_t k = b; k < e; ++k) {
            int worst = -1;
            double zmax = 0;
            for (int c = 0; c < 4; ++c) {
                if (!(sd[c] > 0)) continue;
                const double z = std::fabs(samples[k].l[c] - med[c]) / sd[c];
                if (z > zmax) zmax = z, worst = c;
            }
            if (zmax > s.z) {
                DatasetGlitch gl;
                gl.line = samples[k].line;
                gl.point = d.pos[samples[k].g].point;
                gl.cable = worst + 1;
                gl.reading = samples[k].l[worst];
                gl.median = med[worst];
                gl.z = zmax;
                here.push_back(gl);
                here_rows.push_back(samples[k].row);
            }
        }
        // Glitches are rare; a quarter of a position's samples apart is two
        // populations, not glitches (dataset_glitches.h).
        if (!here.empty() && here.size() <= std::max<size_t>(1, n / 4)) {
            glitches.insert(glitches.end(), here.begin(), here.end());
            rows.insert(rows.end(), here_rows.begin(), here_rows.end());
        }
        b = e;
    }
    std::sort(glitches.begin(), glitches.end(),
              [](const DatasetGlitch &a, const DatasetGlitch &b) { return a.line < b.line; });
    std::sort(rows.begin(), rows.end());
}

} // namespace cdm
