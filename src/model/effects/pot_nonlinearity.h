// A conductive-plastic pot's track is not perfectly linear: its transfer
// curve V(L) has a quadratic term, so after the nominal linear calibration
// reading = length + k_i * length^2. Typical |k| 0.5-2e-5 /mm (0.1-0.5 mm at
// 150 mm of cable; a 0.1-0.25 % linearity spec).
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct PotNonlinearity : EffectBase {
    static constexpr Stage kStage = Stage::Transfer;
    static EffectDesc describe() {
        EffectDesc d{"pot_nonlinearity",
                     "Quadratic term in each pot's transfer curve: reading = length + k_i * length^2, 1/mm "
                     "(length = the pulled-out cable, from the pot's zero). Typical: |k| 0.5-2e-5 /mm.",
                     kStage, -1, {}};
        for (int i = 1; i <= 4; ++i)
            d.params.push_back(param("k" + std::to_string(i), "1/mm", 1e-5, -1e-3, 1e-3, 0.0, 5e-6, 2e-5)
                                   .plausible(-1e-4, 1e-4, "a curvature ten times a pot's linearity tolerance",
                                              "a curvature ten times a pot's linearity tolerance"));
        return d;
    }
    static constexpr int kCableParams = 1;
    static void cable_params(int cable, int *idx) { idx[0] = cable; }
    // The track position is the counted length, not the reading.
    template <class T> static void transfer(const T *q, int, const Sample<T> &, TransferState<T> &st) {
        st.reading = st.reading + q[0] * st.length * st.length;
    }
};
} // namespace cdm
