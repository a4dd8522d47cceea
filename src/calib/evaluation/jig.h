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
//    kFixtureMaxMm: a larger mean is taken out up to that bound, as the
//    fit's bounded offset is, and the rest stays the model's;
//  - holes: a variance component, from a one-way analysis of variance of
//    the residual by hole (per-height means removed); named as the plate's
//    only when the hole means are spatially white (Moran's I over the
//    plate), since a device effect that does not vary with height also
//    repeats at every height but is smooth over the plate.
#pragma once

#include <cmath>
#include <map>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

#include "calib/evaluation/eval.h"
#include "calib/evaluation/spatial.h"
#include "calib/fit/fit.h"

namespace cdm {
namespace diag {

// E with the fixture's offsets subtracted from its residuals.
Eval without_fixture(const Eval &E, const Grid &G, const FixtureOffsets &f);

// The per-sample x RMS of E with the fixture's per-height offsets
// (fixture_offsets) out: what the judge's tests see in x. NaN without
// fixture heights.
double x_rms_without_fixture(const Eval &E, const Grid &G, const V3 &jig, const std::vector<PreparedPos> &pos);

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
// The x fixture's likelihood ratio (fixture_lr below). lr: null when not
// computed (x is then tested like y and z, by the per-height means against
// their standard errors, which ignores that the device's parameters were
// fitted beside the offsets: calibration_outliers needs only the offsets,
// which do not depend on it); computed but untested (`why`): x's p_value is
// null and nothing is named in x.
struct FixtureLR {
    bool tested = false;
    double chi2 = NAN; // chi-square gained back without the offsets
    double scale = 1;  // the named model's chi2/dof when above 1 (overdispersion)
    std::string why;   // when not tested
};
JigAnalysis jig_analysis(const Eval &E, const Grid &G, const std::vector<PreparedPos> &pos, const V3 &jig,
                         const V3 &noise, const FixtureLR *lr = nullptr);

// The likelihood ratio of the fixture's x offsets for model `m` (fitted
// with them under `fo`): m refitted with them and without them, from m's
// parameters, with the same weights; chi2 their chi-square difference (>= 0),
// scale the with-fit's chi2/dof when above 1 (the test divides by it: a
// model that misfits inflates every difference). Untested, with the reason,
// when either refit does not converge (a without-fit stopped early on its
// way along the valley would inflate the difference), or fo has no fixture.
// False only when a fit was cancelled or failed (err).
// A device effect that can mimic a trend over the heights (a scale against
// cable_stretch or holder_geometry) takes the offsets' place without them:
// the per-height means alone call such a trend the fixture's (p 7e-54 on
// data with none: docs/calibration.md, "The jig as it is").
bool fixture_lr(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &fo, FixtureLR &out,
                std::string &err);

} // namespace diag
} // namespace cdm
