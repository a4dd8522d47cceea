// A drum (or its shaft, or the pot's wiper track) that is not perfectly
// round: the pot counts the cable through a radius that varies once per
// turn, so the reading error is periodic in the cable's own length, with the
// period of one turn (2*pi*r, about 60-130 mm for these drums). The four pots
// are one make: one period, fitted; amplitude and phase per cable, as a sine
// and a cosine coefficient. Typical amplitude 0.05-0.2 mm.
//
// The period enters non-linearly: declared ParamRole::LengthPeriod, the
// diagnosis starts it from the peak of the cable-length periodogram of the
// residual and refines it jointly with the amplitudes; its standard error
// comes with the fit.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct DrumEccentricity : EffectBase {
    static constexpr Stage kStage = Stage::Transfer;
    static EffectDesc describe() {
        EffectDesc d{"drum_eccentricity",
                     "Eccentric drum (or shaft, or a ripple of the pot's track): reading += a_i*sin(2*pi*L/period) + "
                     "b_i*cos(2*pi*L/period), L the counted cable length; one period (one turn of the drum, mm) for "
                     "the four pots, amplitude and phase per cable, mm. Typical: period 60-130 mm, amplitude "
                     "0.05-0.2 mm.",
                     kStage, -1, {}};
        // One turn of a string pot's drum is a few cm to a few dm; an
        // eccentricity or track ripple of a mm would be seen by eye.
        d.params.push_back(param("period", "mm", 10.0, 5.0, 400.0, 100.0, 60.0, 130.0, false)
                               .as(ParamRole::LengthPeriod)
                               .plausible(20, 300, "a period shorter than any drum's turn",
                                          "a period longer than any drum's turn: a smooth trend in length"));
        for (int i = 1; i <= 4; ++i) {
            d.params.push_back(param("a" + std::to_string(i), "mm", 0.1, -5, 5, 0.0, 0.05, 0.2)
                                   .plausible(-1, 1, "a ripple over 1 mm", "a ripple over 1 mm"));
            d.params.push_back(param("b" + std::to_string(i), "mm", 0.1, -5, 5, 0.0, 0.05, 0.2)
                                   .plausible(-1, 1, "a ripple over 1 mm", "a ripple over 1 mm"));
        }
        d.advice = advice;
        return d;
    }
    static std::string advice(const AdviceIn &a) {
        return " The drums ripple with a period of " + fixed(a.value[0], 2) + " +- " +
               fixed(a.std.empty() ? 0.0 : a.std[0], 2) + " mm of cable (one turn).";
    }
    static constexpr int kCableParams = 3;
    static void cable_params(int cable, int *idx) {
        idx[0] = 0;
        idx[1] = 1 + 2 * cable;
        idx[2] = 2 + 2 * cable;
    }
    template <class T> static void transfer(const T *q, int, const Sample<T> &, TransferState<T> &st) {
        const T ph = T(2 * M_PI) * st.length / q[0];
        T s, c;
        kernel_sincos(ph, s, c);
        st.reading = st.reading + q[1] * s + q[2] * c;
    }
};
} // namespace cdm
