// The jig as it is: the plate's and the fixture's own errors told apart
// from the device's, so that a real jig's signature is named as the jig's
// and never sent to the user as a missing device effect.
//
// A plate is drilled once: each hole's error is the same at every fixture
// height, and independent from hole to hole (drilling errors do not follow
// each other). A spacer is machined once: each height's error is the same at
// every hole. jig/errors.h simulates both. Here they are estimated from a
// model's position residuals:
//  - fixture: the per-height mean residual per axis (taken out by the fit,
//    FitOptions::fixture, in x, and by the judge on every axis), up to
//    kFixtureMaxMm; larger ones are not a spacer's and stay the model's;
//  - holes: a variance component, from a one-way analysis of variance of
//    the residual by hole (per-height means removed); named as the plate's
//    only when the hole means are spatially white (Moran's I over the
//    plate), since a device effect that does not vary with height also
//    repeats at every height but is smooth over the plate.
#pragma once

#include <cmath>

#include "calib/fit.h"

#include <map>
#include <utility>

#include <nlohmann/json.hpp>

#include "calib/diag_eval.h"
#include "calib/diag_spatial.h"

namespace cdm {
namespace diag {

// (height index, axis) -> the fixture's offset (mm): the weighted per-height
// mean residual, for every (height, axis) whose mean is within
// kFixtureMaxMm. Empty for a layout without fixture heights.
using FixtureOffsets = std::map<std::pair<int, int>, double>;
FixtureOffsets fixture_offsets(const Eval &E, const Grid &G, const V3 &jig);

// E with the fixture's offsets subtracted from its residuals.
Eval without_fixture(const Eval &E, const Grid &G, const FixtureOffsets &f);

// The jig's own errors in E's residual. report: {"fixture": {...},
// "holes": {...}, "seat_std_mm": [x,y,z], "text": [...], "finding": ...}
// (docs/calibration.md, "The jig as it is"); a sentence in "text" only for
// what is significant and at least a tenth of the noise floor `noise` (3-D).
// When the residual repeats at every height but is smooth over the plate,
// "finding" holds a residual finding (the device's, not the jig's) in the
// shape of residual_findings(). offset: per position, the jig's estimated
// error (the fixture's per-height offsets, and each hole's shrunken mean
// when the plate's holes are named), for the residual analysis to take out
// before it looks for the device's structure.
struct JigAnalysis {
    nlohmann::json report;
    std::vector<V3> offset;
};
// fixture_lr: the chi-square the model gains back when refitted without
// the fixture's per-height x offsets (fixture_lr_chi2 below), the x axis's
// test statistic (chi-square, K - 1 degrees of freedom). NaN: x is tested
// like y and z, by the per-height means against their standard errors,
// which ignores that the device's parameters were fitted beside the offsets.
JigAnalysis jig_analysis(const Eval &E, const Grid &G, const std::vector<PreparedPos> &pos, const V3 &jig,
                         const V3 &noise, double fixture_lr = NAN);

// The likelihood ratio of the fixture's x offsets for model `m` (fitted
// with them under `fo`): m refitted with them and without them, from m's
// parameters, the same weights; their chi-square difference (>= 0). NaN
// when fo has no fixture, or a fit fails or is cancelled (`cancelled`).
// A device effect that can mimic a trend over the heights (a scale against
// cable_stretch or holder_geometry) takes the offsets' place without them:
// the per-height means alone called such a trend the fixture's (p 1e-54 on
// data with none: an independent tester's case, docs/calibration.md).
double fixture_lr_chi2(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &fo, bool &cancelled);

} // namespace diag
} // namespace cdm
