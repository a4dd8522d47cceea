// Nominal geometry and the seed's triangulation (eq. 1-3).
#include <cmath>

#include "model/model.h"
#include "model/triangulate.h"

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
    double q[3];
    if (!triangulate_t<double>(g, R, q)) return false;
    for (int k = 0; k < 3; ++k)
        if (!std::isfinite(q[k])) return false;
    for (int k = 0; k < 3; ++k) p[k] = q[k];
    return true;
}

} // namespace cdm
