// The noise model estimated over the jig plate's lines: the white scatter
// beyond the pots' noise (the jig's "nugget"), the part of it each plate hole
// shares at every height, and each mean reading's own error from the
// cables' misclosure; what the fit's options take from them.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "calib/evaluation/spatial.h"

namespace cdm {
namespace diag {

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

} // namespace diag
} // namespace cdm
