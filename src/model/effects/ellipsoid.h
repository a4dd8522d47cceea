// The seed paper's empirical compensation (eq. 4): x_c = L(1 - sqrt(1 +
// y^2/M^2 + z^2/N^2)) and the compensated x is x_e - x_c. Not a physical
// effect: it acts on the estimated position, and is the baseline to beat.
// The paper's fit: L = 5989.1, M = 2950.2, N = 3092.8 mm.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct EllipsoidCorrection : EffectBase {
    static constexpr Stage kStage = Stage::Position;
    static EffectDesc describe() {
        EffectDesc d{"ellipsoid",
                     "The seed's empirical x compensation (eq. 4-5): x_c = L*(1 - sqrt(1 + y^2/M^2 + z^2/N^2)), "
                     "x_compensated = x_e - x_c, fitted to the x error over the jig (eq. 5). Not physical: the "
                     "baseline to beat. Seed's values: L = 5989.1, M = 2950.2, N = 3092.8 mm.",
                     kStage, -1, {}};
        d.params.push_back(param("L", "mm", 1e3, -1e9, 1e9, 0.0, 0, 0));
        d.params.push_back(param("M", "mm", 1e3, 1.0, 1e9, 1e6, 0, 0));
        d.params.push_back(param("N", "mm", 1e3, 1.0, 1e9, 1e6, 0, 0));
        return d;
    }
    template <class T> static void position(const T *p, T x[3]) {
        using std::sqrt;
        const T &L = p[0], &M = p[1], &N = p[2];
        const T xc = L * (T(1.0) - sqrt(T(1.0) + x[1] * x[1] / (M * M) + x[2] * x[2] / (N * N)));
        x[0] = x[0] - xc;
    }
};
} // namespace cdm
