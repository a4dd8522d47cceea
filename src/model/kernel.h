// The measurement kernel: one cable's predicted reading at a holder position,
// templated on the scalar so that the fit (Eigen's AutoDiffScalar over the
// cable's local variables) and the driver (double) run the same code.
#pragma once

#include <cmath>

#include <unsupported/Eigen/AutoDiff>

#include "model/model.h"

namespace cdm {

// Eigen's atan2 for AutoDiffScalar returns a dynamically sized derivative
// (a heap allocation on the driver's path); this one keeps the caller's type.
inline double kernel_atan2(double y, double x) { return std::atan2(y, x); }
template <class D>
Eigen::AutoDiffScalar<D> kernel_atan2(const Eigen::AutoDiffScalar<D> &y, const Eigen::AutoDiffScalar<D> &x) {
    const double yv = y.value(), xv = x.value();
    const double den = xv * xv + yv * yv;
    return Eigen::AutoDiffScalar<D>(std::atan2(yv, xv),
                                    D((y.derivatives() * xv - x.derivatives() * yv) / den));
}

// Everything one cable's reading depends on besides the holder position.
// Zero for every effect that is off.
template <class T> struct CableVars {
    T dA[3]; // anchor_position
    T dh[3]; // holder_geometry
    T r;     // exit_pulley radius (mm); the straight line when the effect is off
    T s0, s1; // cable_stretch
    T g;     // cable_gain
    T k2;    // pot_nonlinearity
    T off;   // cable_offset
};
constexpr int kCableVarCount = 12; // the fields above, in that order
constexpr int kLocalCount = 15;    // 3 position + 12 cable variables

// Pulley kinematics. The cable arrives along the pot axis u at the anchor A,
// wraps over a guide of radius r whose centre is A + r n (n: the unit vector
// from the axis toward the holder, in the plane of u and the holder) and
// leaves tangentially to H. In that plane (s along u, t along n) the centre
// is (0, r), H is (hs, ht); the cable goes round counter-clockwise from the
// angle -pi/2 to the tangent point at phi - acos(r/D), phi = atan2(ht - r, hs),
// D = |H - C|. Wrap beta = phi + pi/2 - acos(r/D); free length sqrt(D^2-r^2).
// At r = 0 this is |H - A|.
template <class T>
T cable_path_length(const double u[3], const T d[3], const T &r, bool pulley) {
    using std::acos;
    using std::sqrt;
    if (!pulley) return sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    T hs = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
    T p0 = d[0] - hs * u[0], p1 = d[1] - hs * u[1], p2 = d[2] - hs * u[2];
    T ht = sqrt(p0 * p0 + p1 * p1 + p2 * p2);
    T dt = ht - r;
    T D2 = hs * hs + dt * dt;
    T D = sqrt(D2);
    T beta = kernel_atan2(dt, hs) + T(M_PI / 2) - acos(r / D);
    return r * beta + sqrt(D2 - r * r);
}

template <class T>
T cable_reading(const DeviceGeometry &g, int i, const T P[3], const CableVars<T> &v, bool pulley) {
    const auto A0 = g.anchor(i);
    const auto h0 = g.holder(i);
    T d[3];
    for (int k = 0; k < 3; ++k) d[k] = P[k] + T(h0[k]) + v.dh[k] - T(A0[k]) - v.dA[k];
    T L = cable_path_length(g.exit_axis[i].data(), d, v.r, pulley);
    T Lu = L * (T(1) - v.s0 - v.s1 * L);
    return v.off + (T(1) + v.g) * Lu + v.k2 * Lu * Lu;
}

} // namespace cdm
