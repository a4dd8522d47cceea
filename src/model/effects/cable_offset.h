// The pot's zero (ADC count at which the length is taken as 0) is off:
// reading = length + o_i. Typical: 0.2-1 mm.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct CableOffset : EffectBase {
    static constexpr Stage kStage = Stage::Transfer;
    static EffectDesc describe() {
        EffectDesc d{"cable_offset", "Zero offset of each pot: reading = length + o_i, mm. Typical: 0.2-1 mm.",
                     kStage, -1, {}};
        for (int i = 1; i <= 4; ++i)
            d.params.push_back(param("o" + std::to_string(i), "mm", 0.5, -20, 20, 0.0, 0.2, 1.0)
                                   .plausible(-10, 10, "a zero 10 mm off: another pot, or a stand-in",
                                              "a zero 10 mm off: another pot, or a stand-in"));
        return d;
    }
    static constexpr int kCableParams = 1;
    static void cable_params(int cable, int *idx) { idx[0] = cable; }
    template <class T> static void transfer(const T *q, int, const Sample<T> &, TransferState<T> &st) {
        st.reading = q[0] + st.reading;
    }
};
} // namespace cdm
