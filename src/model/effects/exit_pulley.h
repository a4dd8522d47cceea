// The cable leaves its pot along the pot's axis u (default +x, out of the
// frame plane; the device description may give it per cable), meets a round
// guide of radius r at the anchor, wraps over it by the angle beta and runs
// straight to the holder: length = r * beta + free length (pulley
// kinematics). The guide swivels so that it lies in the plane of u and the
// holder. The straight-line model is r = 0. Typical r: 3-10 mm.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct ExitPulley : EffectBase {
    static constexpr Stage kStage = Stage::Path;
    static EffectDesc describe() {
        EffectDesc d{"exit_pulley",
                     "The cable leaves its pot along the pot axis (exit_axis, default +x), bends over a round guide "
                     "of radius r starting at the anchor and runs straight to the holder: length = r*beta + free "
                     "length. One radius for the four guides, mm. Typical: 3-10 mm.",
                     kStage, -1, {}};
        // A guide that fits the frame's corner: a few mm to a few cm.
        d.params.push_back(param("radius_mm", "mm", 3.0, 0.0, 40.0, 0.0, 3.0, 10.0, false)
                               .plausible(0.5, 25, "a guide of under 0.5 mm: no guide, or a stand-in",
                                          "a guide over 25 mm across its corner: larger than the frame's pulleys"));
        return d;
    }
    static constexpr int kCableParams = 1;
    static void cable_params(int, int *idx) { idx[0] = 0; }
    // The path round the guide replaces the straight length (it is computed
    // from the anchor-holder vector, not from the length on entry): the
    // kernel's order check puts it first among the Path-stage effects, so
    // no effect's change to the length can be overwritten by it.
    static constexpr bool kReplacesLength = true;
    // In the plane of u and the holder (s along u, t along n, the unit vector
    // from the axis toward the holder) the guide's centre is (0, r) and H is
    // (hs, ht); the cable goes round from the angle -pi/2 to the tangent
    // point at phi - acos(r/D), phi = atan2(ht - r, hs), D = |H - C|:
    // wrap beta = phi + pi/2 - acos(r/D), free length sqrt(D^2 - r^2).
    template <class T>
    static void path(const T *q, int, const Sample<T> &, const PathIn<T> &in, T &length) {
        using std::acos;
        using std::sqrt;
        const T &r = q[0];
        const T *d = in.d;
        const double *u = in.u;
        T hs = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
        T p0 = d[0] - hs * u[0], p1 = d[1] - hs * u[1], p2 = d[2] - hs * u[2];
        T ht = sqrt(p0 * p0 + p1 * p1 + p2 * p2);
        T dt = ht - r;
        T D2 = hs * hs + dt * dt;
        T D = sqrt(D2);
        T beta = kernel_atan2(dt, hs) + T(M_PI / 2) - acos(r / D);
        length = r * beta + sqrt(D2 - r * r);
    }
};
} // namespace cdm
