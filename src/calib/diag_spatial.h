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

} // namespace diag
} // namespace cdm
