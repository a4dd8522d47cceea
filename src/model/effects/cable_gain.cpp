#include "model/effect.h"

namespace cdm {
// The pot's sensitivity differs from its nominal mm-per-count: reading =
// (1 + g_i) * length. Typical: 0.2-1 % (pot tolerance, ADC reference).
EffectDesc make_cable_gain() {
    EffectDesc d{"cable_gain",
                 "Scale error of each pot: reading = (1 + g_i) * length, dimensionless. Typical: 0.2-1 %.",
                 Stage::Transfer, E_GAIN, {}};
    for (int i = 1; i <= 4; ++i)
        d.params.push_back({"g" + std::to_string(i), "1", 5e-3, -0.2, 0.2, 0.0, 2e-3, 1e-2});
    return d;
}
} // namespace cdm
