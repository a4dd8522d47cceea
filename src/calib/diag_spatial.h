// Spatial structure of the residuals over the jig plate: the neighbour grid,
// Moran's I, and the chi-square verdict that combines them with the noise
// model (the noise estimates over the plate's lines: diag_noise.h; the
// positions set aside: diag_outliers.h).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "calib/diag_eval.h"
#include "calib/fit.h"

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
