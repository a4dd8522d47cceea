// Spatial structure of the residuals over the jig plate: the neighbour grid,
// the white scatter beyond the noise (the jig's "nugget"), Moran's I, and the
// chi-square verdict that combines them.
#pragma once

#include <array>
#include <vector>

#include "calib/diag_eval.h"

namespace cdm {
namespace diag {

struct Grid {
    std::vector<std::vector<int>> nb;                 // neighbours (same height)
    std::vector<std::array<int, 2>> ypair, zpair;     // second-difference triples: centre j, (l, r)
    std::vector<int> ycentre, zcentre;
    std::vector<int> height_index;
    double pitch = 5;
    bool layered = true; // positions on a few fixture heights (the seed's jig)
};
Grid make_grid(const std::vector<PreparedPos> &pos, const std::vector<double> &heights);

// White (position-to-position) scatter beyond the noise, per axis.
V3 estimate_nugget(const Eval &E, const Grid &G);

struct Verdict {
    double chi2 = 0, chi2_p = 1;
    int dof = 1;
    double moran_z = 0, moran_p = 1;
    bool explained = false;
    std::vector<char> failing;
    int n_failing = 0;
};

// Moran's z of standardised residuals zv over G's neighbour graph.
double moran_z(const std::vector<double> &zv, const std::vector<char> &ok, const Grid &G);
// Chi-square of the residuals against noise + jig tolerance (per-height
// fixture offsets removed) and the spatial-structure test; n_free fitted
// parameters.
Verdict judge(const Eval &E, const Grid &G, const V3 &jig, int n_free);

// A position the model and its neighbours both disown: its residual fails
// the chi-square against the noise and the jig's tolerance (3 dof, 1 %
// family-wise over the positions, as judge() fails positions), and so does
// its difference from the mean residual of its neighbours on the plate
// (same height; at least two), so it is no part of a smooth structure a
// missing effect would leave. A mis-seated probe, a wrong hole, a bump
// during the samples. More than kOutlierMaxFraction of the positions are
// not "a few bad positions" but a worse jig or a wrong model, and none is
// returned: the verdict judges them (diagnose() also caps the total over
// its rounds at this fraction of the positions read). Nor against a model
// far from the data (kOutlierBulkRatio below).
constexpr double kOutlierMaxFraction = 0.02;
// Only against a model that fits the bulk of the positions: the median
// position's chi-square at most this many times chi-square(3)'s median.
constexpr double kOutlierBulkRatio = 2.0;
struct Outlier {
    size_t j = 0;          // position index
    double chi2 = 0;       // against the noise and the jig (3 dof)
    double chi2_nb = 0;    // its difference from its neighbours' mean
    V3 res = V3::Zero();   // its residual (mm)
    V3 nb = V3::Zero();    // the neighbours' mean residual (mm)
};
// E: the residual with the jig's own offsets removed; jig: its tolerance.
std::vector<Outlier> find_outliers(const Eval &E, const Grid &G, const V3 &jig);

} // namespace diag
} // namespace cdm
