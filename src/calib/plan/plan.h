// A planned jig session: which of the plate's positions (holes x heights) to
// measure, from the geometry and the catalogue alone, before any data.
//
// The design model is the nominal device with the effects to plan for
// (default: every built-in effect on the cable's geometry, path or pot
// transfer), the jig's placement and each fixture height's x offset (which
// every fit takes out: a design that leans on x across heights learns
// less than it seems), linearised with each parameter at its typical size
// (the simulator's middle magnitude). A position's
// information is J' W J: J the four readings' derivative in the
// parameters there, W the inverse of the mean readings' covariance (the
// pots' noise over the samples, plus the jig's seating tolerance through
// the cables' directions). Two stages, greedy:
//  1. detectability: while an effect's likelihood-ratio test against the
//     nominal model (its own parameters added to the jig's placement, at
//     level alpha) has power below the target at the effect's typical size,
//     the position that adds most to the weakest one's non-centrality is
//     taken (power from the non-central chi-square, Boost.Math);
//  2. I-optimal: then, one at a time, the position that lowers most the
//     predicted position variance averaged over the workspace (the plate's
//     box at every height: trace of A J C J' A', C the parameters'
//     covariance in the fit's gauge with its weak priors, the jig's
//     placement left out). For the model given; without one, for each
//     catalogued effect beside the jig's placement at once (the sum of
//     each one's gain over its variance with the whole plate): the device
//     has some of them and nobody knows which (docs/calibration.md,
//     "Planning a session", compares the two with random subsets).
// The chosen positions are returned in an order a person can walk: height
// by height (lowest first), rows along y, each row's holes along z going
// back and forth.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "jig/plan.h"
#include "model/model.h"

namespace cdm {

struct PlanOptions {
    JigPlanOptions jig;                // the plate and heights to choose from; samples per chosen position
    int positions = 312;               // how many to choose
    std::vector<std::string> effects;  // the design model's (empty: the catalogue's, see above)
    double noise_mm = 0.05;            // per-sample pot noise (std)
    double jig_tolerance_mm = 0.03;    // each visit's seating error (std per axis)
    double alpha = 1e-3;               // the detectability test's level
    double power = 0.9;                // its target power
    // A session planned on from the data so far: the positions already
    // measured (x, y, z mm, jig frame, each a hole of the plate at one of its
    // heights) are in the design from the start, and `positions` more are
    // chosen. Their samples are taken as `jig.samples`.
    std::vector<std::array<double, 3>> measured;
    // When not empty, the only positions that may be chosen (what is left of
    // a planned session, say): each a hole of the plate at one of its heights.
    std::vector<std::array<double, 3>> allowed;
    std::function<bool(double)> progress; // fraction done; false cancels
};

struct EffectPower {
    std::string name;
    int dof = 0; // the test's degrees of freedom: the effect's parameters in its gauge beside the jig
    double lambda = 0, power = 0;         // with the plan
    double lambda_all = 0, power_all = 0; // with every position of the plate
};

struct PlanResult {
    std::vector<JigPosition> chosen;      // in walking order (the measured ones not among them)
    int samples = 0;
    int detect_picks = 0;                 // chosen in stage 1
    // Predicted 1-sigma position error (mm, root of the mean trace over the
    // workspace) with the plan and with every position of the plate.
    // With `measured`, the plan's includes them.
    double sigma_mm = 0, sigma_all_mm = 0;
    std::vector<std::string> effects;     // the design model's
    std::vector<std::pair<std::string, std::string>> excluded; // effects left out, and why
    std::vector<EffectPower> power;
};

// False + err on bad options (naming the field), an unknown effect, a
// measured or allowed position that is no hole of the plate, more positions
// asked than are left to choose from, or cancellation.
bool plan_session(const DeviceGeometry &g, const PlanOptions &o, PlanResult &out, std::string &err);

} // namespace cdm
