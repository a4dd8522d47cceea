// The cables are tied to the holder's corners by hand: each attachment point
// is off the nominal square of side m. Typical: 0.1-0.5 mm.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct HolderGeometry : EffectBase {
    static constexpr Stage kStage = Stage::Geometry;
    static EffectDesc describe() {
        EffectDesc d{"holder_geometry",
                     "Offset of each cable's attachment point on the holder from the nominal square of side m, mm. "
                     "Typical: 0.1-0.5 mm. Their common translation is a gauge freedom when the jig transform or "
                     "the anchors are also fitted, and is then fixed to zero.",
                     kStage, -1, {}};
        for (int i = 1; i <= 4; ++i)
            for (const char *c : {"x", "y", "z"})
                // A cable tied by hand to a machined holder sits within a
                // millimetre or so of its corner.
                d.params.push_back(param("h" + std::to_string(i) + "_" + c, "mm", 0.3, -5, 5, 0.0, 0.1, 0.5)
                                       .plausible(-1.5, 1.5, "an attachment point more than 1.5 mm from its corner",
                                                  "an attachment point more than 1.5 mm from its corner"));
        d.points = {true, false};
        return d;
    }
    static constexpr int kCableParams = 3;
    static void cable_params(int cable, int *idx) {
        for (int k = 0; k < 3; ++k) idx[k] = 3 * cable + k;
    }
    template <class T> static void geometry(const T *q, int, const Sample<T> &, CableGeom<T> &g) {
        g.move_holder(q);
    }
    // The points' common translation is the jig's (or the anchors').
    static bool gauge(const GaugeContext &c, Eigen::MatrixXd &basis) {
        if (!c.has("jig_misalignment") && !c.has("anchor_position")) return false;
        Eigen::MatrixXd R(12, 3);
        for (int i = 0; i < 4; ++i) R.block<3, 3>(3 * i, 0) = Eigen::Matrix3d::Identity();
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullU);
        basis = svd.matrixU().rightCols(12 - 3);
        return true;
    }
};
} // namespace cdm
