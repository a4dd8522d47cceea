// The pot's sensitivity differs from its nominal mm-per-count: reading =
// (1 + g_i) * length. Typical: 0.2-1 % (pot tolerance, ADC reference).
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct CableGain : EffectBase {
    static constexpr Stage kStage = Stage::Transfer;
    static EffectDesc describe() {
        EffectDesc d{"cable_gain",
                     "Scale error of each pot: reading = (1 + g_i) * length, dimensionless. Typical: 0.2-1 %.",
                     kStage, -1, {}};
        for (int i = 1; i <= 4; ++i) d.params.push_back(
            param("g" + std::to_string(i), "1", 5e-3, -0.2, 0.2, 0.0, 2e-3, 1e-2)
                .plausible(-0.03, 0.03, "a pot scale 3 % low: beyond a pot's and its reference's tolerance",
                           "a pot scale 3 % high: beyond a pot's and its reference's tolerance"));
        return d;
    }
    static constexpr int kCableParams = 1;
    static void cable_params(int cable, int *idx) { idx[0] = cable; }
    template <class T> static void transfer(const T *q, int, const Sample<T> &, TransferState<T> &st) {
        st.reading = (T(1) + q[0]) * st.reading;
    }
};
} // namespace cdm
