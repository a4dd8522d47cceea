// Spatial structure of the residuals over the jig plate: the neighbour grid,
// the per-height means (the fixture's offsets), Moran's I, and the chi-square verdict that combines them with the noise
// model (the noise estimates over the plate's lines: noise.h; the
// positions set aside: outliers.h).
#pragma once

#include <array>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "calib/evaluation/eval.h"
#include "calib/fit/fit.h"

namespace cdm {
namespace diag {

struct Grid {
    std::vector<std::vector<int>> nb;                 // neighbours (same height)
    std::vector<std::array<int, 2>> ypair, zpair;     // second-difference triples: centre j, (l, r)
    std::vector<int> ycentre, zcentre;
    std::vector<int> height_index;
    // The plate's hole each position is in: positions of a layered jig with
    // the same (y, z) reference, at whatever height (-1: scattered layout).
    std::vector<int> hole_index;
    // Each position's plate cell: (y, z) in pitches, rounded.
    std::vector<std::array<long, 2>> cell;
    double pitch = 5;
    bool layered = true; // positions on a few fixture heights (the seed's jig)
};
Grid make_grid(const std::vector<PreparedPos> &pos, const std::vector<double> &heights);

struct Verdict {
    double chi2 = 0, chi2_p = 1;
    int dof = 1;
    double moran_z = 0, moran_p = 1;
    // The plate's holes' correlation across heights (judge's `hole`): the
    // chi-square's Satterthwaite scale c (chi2 / c ~ chi-square(dof / c))
    // and the largest variance ratio Moran's z was divided by (1: none).
    double chi2_scale = 1, moran_scale = 1;
    // A scale that prints as 1.00 (the two decimals the words give it) is
    // not called a widening.
    static constexpr double kWidenedShown = 1.005;
    bool chi2_widened() const { return chi2_scale > kWidenedShown; }
    bool widened() const { return chi2_scale > kWidenedShown || moran_scale > kWidenedShown; }
    bool explained = false;
    std::vector<char> failing;
    int n_failing = 0;
};

// (height index, axis) -> the fixture's offset (mm): the weighted per-height
// mean residual, clamped to +-kFixtureMaxMm (the fit's bound on its
// offsets: a cliff at the bound, where 0.149 mm would be all the jig's and
// 0.151 mm none of it, would make the judge disagree with the fit it judges).
// Empty for a layout without fixture heights.
using FixtureOffsets = std::map<std::pair<int, int>, double>;

// Weighted per-height mean residual and its standard error, per axis:
// (height index, axis) -> mean, weights 1 / (the mean's noise + jig^2).
struct HeightMean {
    double sw = 0, swr = 0;
    double mean() const { return sw > 0 ? swr / sw : 0.0; }
    double se() const { return sw > 0 ? 1.0 / std::sqrt(sw) : INFINITY; }
};
std::map<std::pair<int, int>, HeightMean> height_means(const Eval &E, const Grid &G, const V3 &jig);
FixtureOffsets fixture_offsets(const Eval &E, const Grid &G, const V3 &jig);

// Moran's z of standardised residuals zv over G's neighbour graph.
double moran_z(const std::vector<double> &zv, const std::vector<char> &ok, const Grid &G);
// Chi-square of the residuals against noise + jig tolerance (per-height
// fixture offsets removed) and the spatial-structure test; n_free fitted
// parameters.
// hole: the part of jig each plate hole shares at every height (the fit's
// FitOptions::hole_sigma): the residuals of a hole's positions then
// correlate, and both tests widen by the variance that adds (Satterthwaite's
// scaled chi-square; Moran's z over its inflated standard deviation).
Verdict judge(const Eval &E, const Grid &G, const V3 &jig, int n_free, const V3 &hole = V3::Zero());

} // namespace diag
} // namespace cdm
