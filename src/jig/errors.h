// The jig's own errors: the one model of how a real plate and fixture put
// the holder somewhere other than their nominal reference position. Both
// simulators (the dataset simulator in calib/ and the simulated master's
// jig motion in device/sim/) draw their jig errors here, so a dataset made
// either way has the same jig in it.
//
// Three components, each a zero-mean normal with its own standard deviation:
//  - hole:    each plate hole is off in y and z by the same amount at every
//             fixture height (the plate is drilled once);
//  - fixture: each fixture height is off in x by the same amount at every
//             hole (the spacer is machined once);
//  - seat:    every visit of a position seats the grip a little differently,
//             on all three axes (repeatability of putting the grip in).
// Scattered positions (no holes, no heights) get the seat component only.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "jig/plan.h"

namespace cdm {

struct JigErrorOptions {
    double hole_mm = 0.0;
    double fixture_mm = 0.0;
    double seat_mm = 0.0;
    uint64_t seed = 1;
};

// The true position of each plan entry in the jig frame: its reference plus
// the jig's errors. Deterministic in (plan, options).
std::vector<std::array<double, 3>> jig_true_positions(const std::vector<JigPosition> &plan, int n_holes_per_side,
                                                      const JigErrorOptions &o);

} // namespace cdm
