// Positions set aside as outliers (a mis-seated probe, a wrong hole): the
// tests that find them on the plate, and the ones that keep real structure
// (a reading effect, a local structure) from being set aside.
#pragma once

#include <string>
#include <vector>

#include "calib/evaluation/spatial.h"

namespace cdm {
namespace diag {

// A position the model and its neighbours both disown: its residual fails
// the chi-square against the noise and the jig's tolerance (3 dof, 1 %
// family-wise over the positions, as judge() fails positions), and so does
// its difference from the mean residual of its neighbours on the plate
// (same height; at least two), so it is no part of a smooth structure a
// missing effect would leave. A mis-seated probe, a wrong hole, a bump
// during the samples. More than kOutlierMaxFraction of the positions are
// not "a few bad positions" but a worse jig or a wrong model, and none is
// returned: the verdict judges them (the rounds of calib/calibration/fit_outliers.h cap the
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
