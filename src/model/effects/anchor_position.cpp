#include "model/effect.h"

namespace cdm {
// Each cable's exit point sits off the drawing by machining and assembly
// tolerance: A_i = A_i,nominal + (dx, dy, dz). Since the cables run nearly
// parallel to the cable plane, an in-plane error of a few tenths of a mm
// moves the x estimate by several times that. Typical: 0.2-1 mm.
EffectDesc make_anchor_position() {
    EffectDesc d{"anchor_position",
                 "3-D displacement of each cable's exit point (anchor) from the drawing, mm. "
                 "Typical: 0.2-1 mm per coordinate. With jig_misalignment on, the anchors' common rigid motion "
                 "is a gauge freedom and is fixed to zero (the jig transform carries it).",
                 Stage::Geometry, E_ANCHOR, {}};
    for (int i = 1; i <= 4; ++i)
        for (const char *c : {"x", "y", "z"})
            d.params.push_back({"a" + std::to_string(i) + "_" + c, "mm", 0.5, -10, 10, 0.0, 0.2, 1.0});
    return d;
}
} // namespace cdm
