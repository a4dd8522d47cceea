// The seed's triangulation (eq. 1-3), templated so that the forward
// kinematics can differentiate it. Private to src/model.
#pragma once

#include <cmath>

#include "model/model.h"

namespace cdm {

template <class T> bool triangulate_t(const DeviceGeometry &g, const T R[4], T p[3]) {
    using std::sqrt;
    const double a = g.a_mm, b = g.b_mm, m = g.m_mm;
    const T R1 = R[0] * R[0], R2 = R[1] * R[1], R3 = R[2] * R[2], R4 = R[3] * R[3];
    // eq. (1), (2)
    const T ye = ((R3 - R1) + (R4 - R2)) / (4.0 * (2.0 * a - m));
    const T ze = ((R1 - R2) + (R3 - R4)) / (4.0 * (2.0 * b - m));
    // eq. (3) in the digest's geometric form: mean of the four heights.
    T xs = T(0.0);
    for (int i = 0; i < 4; ++i) {
        const T dy = ye - DeviceGeometry::sy[i] * (a - m / 2);
        const T dz = ze - DeviceGeometry::sz[i] * (b - m / 2);
        const T h2 = R[i] * R[i] - dy * dy - dz * dz;
        if (!(h2 >= 0.0)) return false; // the four spheres do not meet
        xs += sqrt(h2);
    }
    const T xe = xs / 4.0;
    p[0] = xe;
    p[1] = ye;
    p[2] = ze;
    return true;
}

} // namespace cdm
