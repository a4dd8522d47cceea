#include "model/effect.h"

namespace cdm {
// The torsion spring pulls the cable with a tension that rises with the
// extension, T = T0 + K*L; the cable stretches by the strain T/EA, and the
// drum counts only the unstretched cable: reading = L * (1 - s0 - s1*L) with
// s0 = T0/EA and s1 = K/EA, the same for the four cables (same cable, same
// springs). Typical for a braided polymer cord: s0 2e-4..2e-3, s1 1e-6..5e-6
// /mm (0.05-0.4 mm at 150 mm); negligible for steel cable.
EffectDesc make_cable_stretch() {
    EffectDesc d{"cable_stretch",
                 "Elastic elongation under the spring's tension, T = T0 + K*L: reading = L*(1 - s0 - s1*L), "
                 "s0 = T0/EA (1), s1 = K/EA (1/mm), common to the four cables. Typical: s0 2e-4..2e-3, "
                 "s1 1e-6..5e-6 /mm. s0 is the common part of cable_gain and s1 that of pot_nonlinearity: with "
                 "those on, the shared parameter is fixed (gauge).",
                 Stage::Transfer, E_STRETCH, {}};
    d.params.push_back({"s0", "1", 1e-3, -0.05, 0.05, 0.0, 2e-4, 2e-3, false});
    d.params.push_back({"s1_per_mm", "1/mm", 3e-6, -1e-3, 1e-3, 0.0, 1e-6, 5e-6, false});
    return d;
}
} // namespace cdm
