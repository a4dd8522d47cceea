#include "model/effect.h"

namespace cdm {
// The cables are tied to the holder's corners by hand: each attachment point
// is off the nominal square of side m. Typical: 0.1-0.5 mm.
EffectDesc make_holder_geometry() {
    EffectDesc d{"holder_geometry",
                 "Offset of each cable's attachment point on the holder from the nominal square of side m, mm. "
                 "Typical: 0.1-0.5 mm. Their common translation is a gauge freedom when the jig transform or "
                 "the anchors are also fitted, and is then fixed to zero.",
                 Stage::Geometry, E_HOLDER, {}};
    for (int i = 1; i <= 4; ++i)
        for (const char *c : {"x", "y", "z"})
            d.params.push_back({"h" + std::to_string(i) + "_" + c, "mm", 0.3, -5, 5, 0.0, 0.1, 0.5});
    return d;
}
} // namespace cdm
