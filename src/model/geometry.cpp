// Nominal geometry and the seed's triangulation (eq. 1-3).
#include <cmath>

#include "model/model.h"

namespace cdm {

constexpr double DeviceGeometry::sy[4];
constexpr double DeviceGeometry::sz[4];

std::array<double, 3> DeviceGeometry::anchor(int i) const {
    return {0.0, sy[i] * a_mm, sz[i] * b_mm};
}

std::array<double, 3> DeviceGeometry::holder(int i) const {
    return {0.0, sy[i] * m_mm / 2, sz[i] * m_mm / 2};
}

void nominal_lengths(const DeviceGeometry &g, const double p[3], double lengths[4]) {
    for (int i = 0; i < 4; ++i) {
        auto A = g.anchor(i);
        auto h = g.holder(i);
        double d0 = p[0] + h[0] - A[0], d1 = p[1] + h[1] - A[1], d2 = p[2] + h[2] - A[2];
        lengths[i] = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    }
}

bool triangulate(const DeviceGeometry &g, const double R[4], double p[3]) {
    for (int i = 0; i < 4; ++i)
        if (!std::isfinite(R[i]) || R[i] < 0) return false;
    const double a = g.a_mm, b = g.b_mm, m = g.m_mm;
    const double R1 = R[0] * R[0], R2 = R[1] * R[1], R3 = R[2] * R[2], R4 = R[3] * R[3];
    // eq. (1), (2)
    const double ye = ((R3 - R1) + (R4 - R2)) / (4.0 * (2.0 * a - m));
    const double ze = ((R1 - R2) + (R3 - R4)) / (4.0 * (2.0 * b - m));
    // eq. (3) in the digest's geometric form: mean of the four heights.
    double xs = 0.0;
    for (int i = 0; i < 4; ++i) {
        const double dy = ye - DeviceGeometry::sy[i] * (a - m / 2);
        const double dz = ze - DeviceGeometry::sz[i] * (b - m / 2);
        const double h2 = R[i] * R[i] - dy * dy - dz * dz;
        if (!(h2 >= 0.0)) return false; // the four spheres do not meet
        xs += std::sqrt(h2);
    }
    const double xe = xs / 4.0;
    if (!std::isfinite(xe) || !std::isfinite(ye) || !std::isfinite(ze)) return false;
    p[0] = xe;
    p[1] = ye;
    p[2] = ze;
    return true;
}

} // namespace cdm
