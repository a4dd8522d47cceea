// Each cable's exit point sits off the drawing by machining and assembly
// tolerance: A_i = A_i,nominal + (dx, dy, dz). Since the cables run nearly
// parallel to the cable plane, an in-plane error of a few tenths of a mm
// moves the x estimate by several times that. Typical: 0.2-1 mm.
#pragma once
#include "model/effects/base.h"

namespace cdm {
struct AnchorPosition : EffectBase {
    static constexpr Stage kStage = Stage::Geometry;
    static EffectDesc describe() {
        EffectDesc d{"anchor_position",
                     "3-D displacement of each cable's exit point (anchor) from the drawing, mm. "
                     "Typical: 0.2-1 mm per coordinate. With jig_misalignment on, the anchors' common rigid motion "
                     "is a gauge freedom and is fixed to zero (the jig transform carries it).",
                     kStage, -1, {}};
        for (int i = 1; i <= 4; ++i)
            for (const char *c : {"x", "y", "z"})
                // A frame's assembly puts an exit point within a few mm of
                // its drawing; more is another frame, or a stand-in.
                d.params.push_back(param("a" + std::to_string(i) + "_" + c, "mm", 0.5, -10, 10, 0.0, 0.2, 1.0)
                                       .plausible(-3, 3, "an exit point more than 3 mm from its drawing",
                                                  "an exit point more than 3 mm from its drawing"));
        d.points = {true, true};
        return d;
    }
    static constexpr int kCableParams = 3;
    static void cable_params(int cable, int *idx) {
        for (int k = 0; k < 3; ++k) idx[k] = 3 * cable + k;
    }
    template <class T> static void geometry(const T *q, int, const Sample<T> &, CableGeom<T> &g) {
        g.move_anchor(q);
    }
    // With the jig transform fitted, a common rigid motion of the four
    // anchors (3 translations, 3 small rotations about their centroid) is the
    // jig's: projected out.
    static bool gauge(const GaugeContext &c, Eigen::MatrixXd &basis) {
        if (!c.has("jig_misalignment")) return false;
        Eigen::MatrixXd R(12, 6);
        for (int i = 0; i < 4; ++i) {
            auto A = c.g.anchor(i);
            Eigen::Vector3d a(A[0], A[1], A[2]);
            for (int k = 0; k < 3; ++k) {
                Eigen::Vector3d ek = Eigen::Vector3d::Unit(k);
                R.block<3, 1>(3 * i, k) = ek;
                R.block<3, 1>(3 * i, 3 + k) = ek.cross(a) / 100.0;
            }
        }
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullU);
        basis = svd.matrixU().rightCols(12 - 6);
        return true;
    }
};
} // namespace cdm
