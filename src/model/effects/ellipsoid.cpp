#include "model/effect.h"

namespace cdm {
// The seed paper's empirical compensation (eq. 4): x_c = L(1 - sqrt(1 +
// y^2/M^2 + z^2/N^2)) and the compensated x is x_e - x_c. Not a physical
// effect: it acts on the estimated position, and is the baseline to beat.
// The paper's fit: L = 5989.1, M = 2950.2, N = 3092.8 mm.
EffectDesc make_ellipsoid() {
    EffectDesc d{"ellipsoid",
                 "The seed's empirical x compensation (eq. 4-5): x_c = L*(1 - sqrt(1 + y^2/M^2 + z^2/N^2)), "
                 "x_compensated = x_e - x_c, fitted to the x error over the jig (eq. 5). Not physical: the "
                 "baseline to beat. Seed's values: L = 5989.1, M = 2950.2, N = 3092.8 mm.",
                 Stage::Position, E_ELLIPSOID, {}};
    d.params.push_back({"L", "mm", 1e3, -1e9, 1e9, 0.0, 0, 0});
    d.params.push_back({"M", "mm", 1e3, 1.0, 1e9, 1e6, 0, 0});
    d.params.push_back({"N", "mm", 1e3, 1.0, 1e9, 1e6, 0, 0});
    return d;
}
} // namespace cdm
