// The jig (hole plate + height fixture) is bolted to the frame by hand; its
// frame differs from the device frame by a small rigid motion. Reference
// positions map as p_dev = R(r) p_ref + t, with R the rotation vector r
// (rad) about the device origin. Typical: a few tenths of a degree, < 1 mm.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct JigMisalignment : EffectBase {
    static constexpr Stage kStage = Stage::Jig;
    static EffectDesc describe() {
        EffectDesc d{"jig_misalignment",
                     "Rigid transform between the jig's frame and the device frame: p_dev = R(rx,ry,rz) p_ref + t. "
                     "Rotation vector in rad about the device origin, translation in mm. Typical: 0.1-0.5 deg, "
                     "0.2-1 mm.",
                     kStage, -1, {}};
        // A jig placed by hand on the frame: within a few degrees and a
        // couple of cm of where it is meant to be.
        for (const char *n : {"rx", "ry", "rz"})
            d.params.push_back(param(n, "rad", 5e-3, -0.5, 0.5, 0.0, 1.5e-3, 8e-3)
                                   .plausible(-0.05, 0.05, "a jig turned by over 3 degrees", "a jig turned by over 3 degrees"));
        for (const char *n : {"tx", "ty", "tz"})
            d.params.push_back(param(n, "mm", 0.5, -100, 100, 0.0, 0.2, 1.0)
                                   .plausible(-20, 20, "a jig placed over 20 mm off", "a jig placed over 20 mm off"));
        return d;
    }
    template <class T> static void jig(const T *p, T x[3]) {
        T out[3];
        rotvec_apply<T>(p, x, out);
        for (int k = 0; k < 3; ++k) x[k] = out[k] + p[3 + k];
    }
};
} // namespace cdm
