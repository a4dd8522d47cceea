#include "model/effect.h"

namespace cdm {
// The pot's zero (ADC count at which the length is taken as 0) is off:
// reading = length + o_i. Typical: 0.2-1 mm.
EffectDesc make_cable_offset() {
    EffectDesc d{"cable_offset", "Zero offset of each pot: reading = length + o_i, mm. Typical: 0.2-1 mm.",
                 Stage::Transfer, E_OFFSET, {}};
    for (int i = 1; i <= 4; ++i)
        d.params.push_back({"o" + std::to_string(i), "mm", 0.5, -20, 20, 0.0, 0.2, 1.0});
    return d;
}
} // namespace cdm
