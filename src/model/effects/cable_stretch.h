// The torsion spring pulls the cable with a tension that rises with the
// extension, T = T0 + K*L; the cable stretches by the strain T/EA, and the
// drum counts only the unstretched cable: reading = L * (1 - s0 - s1*L) with
// s0 = T0/EA and s1 = K/EA, the same for the four cables (same cable, same
// springs). Typical for a braided polymer cord: s0 2e-4..2e-3, s1 1e-6..5e-6
// /mm (0.05-0.4 mm at 150 mm); negligible for steel cable.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct CableStretch : EffectBase {
    static constexpr Stage kStage = Stage::Transfer;
    static EffectDesc describe() {
        EffectDesc d{"cable_stretch",
                     "Elastic elongation under the spring's tension, T = T0 + K*L: reading = L*(1 - s0 - s1*L), "
                     "s0 = T0/EA (1), s1 = K/EA (1/mm), common to the four cables. Typical: s0 2e-4..2e-3, "
                     "s1 1e-6..5e-6 /mm. s0 is the common part of cable_gain and s1 that of pot_nonlinearity: with "
                     "those on, the shared parameter is fixed (gauge).",
                     kStage, -1, {}};
        // A tensioned cable only lengthens (s0 >= 0), and a drum spring's
        // tension rises as cable is paid out (s1 >= 0); a strain above 1 %
        // is not a cable's elastic range.
        d.params.push_back(param("s0", "1", 1e-3, -0.05, 0.05, 0.0, 2e-4, 2e-3, false)
                               .plausible(0, 1e-2, "a compression: something lengthens the reading as the cable lengthens",
                                          "a strain over 1 %: a scale of the readings larger than a cable's stretch"));
        d.params.push_back(param("s1_per_mm", "1/mm", 3e-6, -1e-3, 1e-3, 0.0, 1e-6, 5e-6, false)
                               .plausible(0, 3e-5, "a tension falling as cable is paid out: something lengthens the "
                                                   "reading faster than the length grows",
                                          "a strain growing faster than a drum spring's tension can make it"));
        return d;
    }
    static constexpr int kCableParams = 2;
    static void cable_params(int, int *idx) {
        idx[0] = 0;
        idx[1] = 1;
    }
    // The drum counts the unstretched cable: both the counted length and the
    // reading so far shrink by the same factor.
    template <class T> static void transfer(const T *q, int, const Sample<T> &, TransferState<T> &st) {
        const T f = T(1) - q[0] - q[1] * st.length;
        st.length = st.length * f;
        st.reading = st.reading * f;
    }
    static bool gauge(const GaugeContext &c, Eigen::MatrixXd &basis) {
        const bool keep0 = !c.has("cable_gain"), keep1 = !c.has("pot_nonlinearity");
        basis = Eigen::MatrixXd::Zero(2, int(keep0) + int(keep1));
        int col = 0;
        if (keep0) basis(0, col++) = 1;
        if (keep1) basis(1, col++) = 1;
        return true;
    }
};
} // namespace cdm
