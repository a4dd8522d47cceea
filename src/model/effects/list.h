// The built-in effects, in the order they act on a reading. This list is
// the single source of truth: the registry (`cdm calib effects`, the
// catalogue table in docs/calibration.md), the measurement kernel, the
// forward kinematics and the fit's Jacobian are generated from it.
//
// Adding a built-in: write effects/NAME.h (docs/effects.md), include it
// here and add its line to CDM_BUILTIN_EFFECTS at the place where it acts.
// Stages must not decrease down the list (checked at compile time in
// kernel.h): Jig, Geometry, Path, Transfer, Position; user effects (C
// callbacks) run between Transfer and Position.
#pragma once

#include "model/effects/anchor_position.h"
#include "model/effects/cable_gain.h"
#include "model/effects/cable_offset.h"
#include "model/effects/cable_stretch.h"
#include "model/effects/drum_eccentricity.h"
#include "model/effects/ellipsoid.h"
#include "model/effects/exit_pulley.h"
#include "model/effects/holder_geometry.h"
#include "model/effects/jig_misalignment.h"
#include "model/effects/pot_drift.h"
#include "model/effects/pot_nonlinearity.h"

// clang-format off
#define CDM_BUILTIN_EFFECTS(_) \
    _(JigMisalignment)         \
    _(AnchorPosition)          \
    _(HolderGeometry)          \
    _(ExitPulley)              \
    _(CableStretch)            \
    _(CableGain)               \
    _(CableOffset)             \
    _(PotNonlinearity)         \
    _(DrumEccentricity)        \
    _(PotDrift)                \
    _(EllipsoidCorrection)
// clang-format on
