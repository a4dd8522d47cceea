// The pots' readings drift over a session (the electronics and the plastic
// track warm up, the reference voltage settles): an offset that changes
// smoothly with time, linear per cable plus a curvature common to the four.
// t is the acquisition time since the session's start (a jig CSV's t_s
// column, or its row order at a nominal 0.01 s per row); the driver's live
// poses are computed at t = 0, the state at the start of the jig session.
// Typical: 0.1-0.5 mm over a cold start's first hour.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct PotDrift : EffectBase {
    static constexpr Stage kStage = Stage::Transfer;
    static EffectDesc describe() {
        EffectDesc d{"pot_drift",
                     "Readings drift over the session: reading += r_i*t + c*t^2, t the acquisition time in hours "
                     "since the session's start (jig CSV: the t_s column, or row order at 0.01 s per row); r_i per "
                     "cable, mm/h; c common, mm/h^2. Live poses use t = 0. Typical: 0.1-0.5 mm over the first hour "
                     "after a cold start.",
                     kStage, -1, {}};
        // A warming pot drifts by tenths of a mm per hour; several mm per
        // hour is a loose part or a stand-in.
        for (int i = 1; i <= 4; ++i)
            d.params.push_back(param("r" + std::to_string(i), "mm/h", 0.2, -50, 50, 0.0, 0.1, 0.5)
                                   .plausible(-5, 5, "a drift over 5 mm/h", "a drift over 5 mm/h"));
        d.params.push_back(param("c", "mm/h^2", 0.2, -50, 50, 0.0, 0.0, 0.0)
                               .plausible(-5, 5, "a drift accelerating by over 5 mm/h^2",
                                          "a drift accelerating by over 5 mm/h^2"));
        d.advice = advice;
        return d;
    }
    // The largest drift of a cable's reading over the session's span.
    static std::string advice(const AdviceIn &a) {
        double worst = 0;
        for (int c = 0; c < 4; ++c)
            worst = std::max(worst, std::fabs(a.value[size_t(c)] * (a.t1_h - a.t0_h) +
                                              a.value[4] * (a.t1_h * a.t1_h - a.t0_h * a.t0_h)));
        return " The readings drift by up to " + fixed(worst, 3) +
               " mm over the session: warm the device up before measuring, or re-measure a reference hole at "
               "intervals.";
    }
    static constexpr int kCableParams = 2;
    static void cable_params(int cable, int *idx) {
        idx[0] = cable;
        idx[1] = 4;
    }
    template <class T> static void transfer(const T *q, int, const Sample<T> &s, TransferState<T> &st) {
        const double h = s.t_s / 3600.0;
        st.reading = st.reading + q[0] * T(h) + q[1] * T(h * h);
    }
};
} // namespace cdm
