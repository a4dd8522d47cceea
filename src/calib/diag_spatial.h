// Spatial structure of the residuals over the jig plate: the neighbour grid,
// the white scatter beyond the noise (the jig's "nugget"), Moran's I, and the
// chi-square verdict that combines them.
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

// White (position-to-position) scatter beyond the noise, per axis.
V3 estimate_nugget(const Eval &E, const Grid &G);
// The part of that scatter each hole shares at every height (the plate's
// drilling error), per axis: the covariance across heights of the same
// second differences (a triple of holes seen at two heights or more), in
// y and z (the plate's plane; x is left at zero). Zero for a scattered
// layout or where it is not significant.
V3 estimate_hole_std(const Eval &E, const Grid &G);
// Each mean reading's own white error beyond the pots' noise of the mean
// (pot hysteresis, a wiper's per-approach offset, a seat that tilts: per
// position and cable), estimated from the cables' misclosure (Eval::mis) by
// fourth differences along the plate: variance (mm^2) and its standard
// error over the plate's lines; sigma (mm) when the variance is more than
// three standard errors above zero, else 0. Not tested (tested false) on a
// scattered layout or fewer than 8 lines.
struct ReadingNoise {
    bool tested = false;
    double variance = 0, se = 0, sigma = 0;
    // How sigma came about: "estimated" (from the model fitted first),
    // "re-estimated" (from the recommended model's misclosure, the
    // diagnosis run again with it).
    std::string source = "estimated";
    // Re-estimated: the first estimate (on the model fitted first), beside
    // the one in use above.
    double first_variance = 0, first_se = 0;
};
ReadingNoise estimate_reading_noise(const Eval &E, const Grid &G);
// The estimate as JSON (reading_noise_mm in the diagnosis and in cdm_fit's
// result).
nlohmann::json reading_noise_json(const ReadingNoise &r);
// The fit's noise model from a jig's white scatter per position (`jig`,
// holes included) and the part of it each hole shares (`hole`, at most
// jig): fo.hole_sigma = hole, fo.jig_sigma = what is left per position.
void set_jig_noise(FitOptions &fo, const V3 &jig, const V3 &hole);

struct Verdict {
    double chi2 = 0, chi2_p = 1;
    int dof = 1;
    double moran_z = 0, moran_p = 1;
    // The plate's holes' correlation across heights (judge's `hole`): the
    // chi-square's Satterthwaite scale c (chi2 / c ~ chi-square(dof / c))
    // and the largest variance ratio Moran's z was divided by (1: none).
    double chi2_scale = 1, moran_scale = 1;
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

// A position the model and its neighbours both disown: its residual fails
// the chi-square against the noise and the jig's tolerance (3 dof, 1 %
// family-wise over the positions, as judge() fails positions), and so does
// its difference from the mean residual of its neighbours on the plate
// (same height; at least two), so it is no part of a smooth structure a
// missing effect would leave. A mis-seated probe, a wrong hole, a bump
// during the samples. More than kOutlierMaxFraction of the positions are
// not "a few bad positions" but a worse jig or a wrong model, and none is
// returned: the verdict judges them (the rounds of fit_outliers.h cap the
// total the same way, against the positions read). Beyond it, up to
// kOutlierScatteredFraction, only when those a round finds look like
// references off (a probe in the wrong hole moves the holder any way) and
// not like a reading effect or a local structure: at most a quarter of them
// deviate as one cable's reading error would move the position, counting
// only cables that two or more of them do so on (one_cable_chi2 within chi-square(2)'s 1 % point:
// a worn spot on a track, a slipping cable), and they are scattered over the plate as chance
// scatters them (join_count_p at least kOutlierScatterLevel). Nor against a model far from the data
// (kOutlierBulkRatio below).
constexpr double kOutlierMaxFraction = 0.02;
constexpr double kOutlierScatteredFraction = 0.10;
constexpr double kOutlierScatterLevel = 0.05;
// Only against a model that fits the bulk of the positions: the median
// position's chi-square at most this many times chi-square(3)'s median.
constexpr double kOutlierBulkRatio = 2.0;
struct Outlier {
    size_t j = 0;          // position index
    double chi2 = 0;       // against the noise and the jig (3 dof)
    double chi2_nb = 0;    // its difference from its neighbours' mean
    V3 res = V3::Zero();   // its residual (mm)
    V3 nb = V3::Zero();    // the neighbours' mean residual (mm)
    V3 var = V3::Zero();   // the variance of res - nb (mm^2): noise, jig, the neighbours' mean
};
// Positions that fail both tests but are kept, and why (empty: none).
struct Declined {
    size_t count = 0;
    std::string why;
};
// E: the residual with the jig's own offsets removed; jig: its tolerance;
// already: the positions set aside before (earlier rounds), of `read`
// (0: the positions of E). declined (optional): what was found but kept.
std::vector<Outlier> find_outliers(const Eval &E, const Grid &G, const V3 &jig, size_t already = 0, size_t read = 0,
                                   Declined *declined = nullptr);

// What is left of a position's deviation d (mm, variance var per axis) once
// the best single cable's reading error is fitted to it (through Jp, the
// position's move per mm of each reading), as a chi-square (2 dof): small
// when one cable's reading explains d. cable (optional): which (0-3; -1
// when no cable's reading moves the position).
double one_cable_chi2(const Eigen::Matrix<double, 3, 4> &Jp, const V3 &d, const V3 &var, int *cable = nullptr);

// The join-count test of spatial randomness: the number of neighbour links
// (G.nb, as listed) between marked positions, against the same count when
// as many positions are marked at random among those that could be (usable,
// with at least two usable neighbours, as find_outliers asks): 999
// relabelings from a fixed seed, drawn without the standard library's
// distributions, so the same answer on every platform. Returns the
// permutation p-value of at least as many links, (1 + #{random >=
// observed}) / 1000; 1 when no two marked positions are linked.
double join_count_p(const Grid &G, const std::vector<char> &ok, const std::vector<char> &mark);

} // namespace diag
} // namespace cdm
