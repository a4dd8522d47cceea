#include "model/effect.h"

namespace cdm {
// A conductive-plastic pot's track is not perfectly linear: its transfer
// curve V(L) has a quadratic term, so after the nominal linear calibration
// reading = length + k_i * length^2. Typical |k| 0.5-2e-5 /mm (0.1-0.5 mm at
// 150 mm of cable; a 0.1-0.25 % linearity spec).
EffectDesc make_pot_nonlinearity() {
    EffectDesc d{"pot_nonlinearity",
                 "Quadratic term in each pot's transfer curve: reading = length + k_i * length^2, 1/mm "
                 "(length = the pulled-out cable, from the pot's zero). Typical: |k| 0.5-2e-5 /mm.",
                 Stage::Transfer, E_NONLIN, {}};
    for (int i = 1; i <= 4; ++i)
        d.params.push_back({"k" + std::to_string(i), "1/mm", 1e-5, -1e-3, 1e-3, 0.0, 5e-6, 2e-5});
    return d;
}
} // namespace cdm
