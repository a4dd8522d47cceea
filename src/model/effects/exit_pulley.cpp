#include "model/effect.h"

namespace cdm {
// The cable leaves its pot along the pot's axis u (default +x, out of the
// frame plane; the device description may give it per cable), meets a round
// guide of radius r at the anchor, wraps over it by the angle beta and runs
// straight to the holder: length = r * beta + free length (pulley
// kinematics). The guide swivels so that it lies in the plane of u and the
// holder. The straight-line model is r = 0. Typical r: 3-10 mm.
EffectDesc make_exit_pulley() {
    EffectDesc d{"exit_pulley",
                 "The cable leaves its pot along the pot axis (exit_axis, default +x), bends over a round guide of "
                 "radius r starting at the anchor and runs straight to the holder: length = r*beta + free length. "
                 "One radius for the four guides, mm. Typical: 3-10 mm.",
                 Stage::Path, E_PULLEY, {}};
    d.params.push_back({"radius_mm", "mm", 3.0, 0.0, 40.0, 0.0, 3.0, 10.0, false});
    return d;
}
} // namespace cdm
