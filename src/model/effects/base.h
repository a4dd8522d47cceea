// What a built-in effect file sees: the states its stage hook works on, the
// defaults every effect inherits, and small templated maths the hooks share.
// An effect is a struct deriving from EffectBase (see docs/effects.md):
//   static EffectDesc describe();          name, doc, stage, parameters
//   static constexpr int kCableParams;      parameters one cable's reading depends on
//   static void cable_params(int cable, int idx[]);  which ones (indices into describe().params)
//   one hook for its stage, templated on the scalar T (double, or an
//   Eigen::AutoDiffScalar in the fit and the forward kinematics):
//     Jig:      template <class T> static void jig(const T *p, T x[3]);
//     Geometry: template <class T> static void geometry(const T *q, int cable, const Sample<T> &s, CableGeom<T> &g);
//     Path:     template <class T> static void path(const T *q, int cable, const Sample<T> &s, const PathIn<T> &in, T &length);
//     Transfer: template <class T> static void transfer(const T *q, int cable, const Sample<T> &s, TransferState<T> &st);
//     Position: template <class T> static void position(const T *p, T x[3]);
//   p: every parameter of the effect; q: the cable's own, in cable_params order.
//   static bool gauge(const GaugeContext &c, Eigen::MatrixXd &basis);  optional
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include <Eigen/Dense>
#include <unsupported/Eigen/AutoDiff>

#include "model/effect.h"
#include "model/model.h"

namespace cdm {

// A number in an effect's advice: `prec` fixed decimals, as the diagnosis
// prints its own numbers.
inline std::string fixed(double v, int prec) {
    char b[64];
    std::snprintf(b, sizeof b, "%.*f", prec, v);
    return b;
}

// What the kernel knows about one sample besides the effects' parameters:
// the holder centre (device frame, mm) and the acquisition time (s since the
// session's start; 0 when the source has none). Effects that drift in time
// read t_s.
template <class T> struct Sample {
    T P[3];
    double t_s = 0;
};

// Geometry stage: displacement of cable i's anchor (exit point) and holder
// attachment point from the drawing, mm. Zero on entry; hooks add to it with
// move_anchor / move_holder. A displacement no hook moved is left out of the
// sums (adding an exact zero changes no value), so the hot path neither
// zeroes nor adds derivative vectors that stay zero. The displacements are
// private: a hook cannot read one that was never written.
template <class T> class CableGeom {
  public:
    void move_anchor(const T *v) { add(dA_, moved_A_, v); }
    void move_holder(const T *v) { add(dh_, moved_h_, v); }
    // The displacement, or nullptr when no hook moved it (the kernel's).
    const T *anchor_shift() const { return moved_A_ ? dA_ : nullptr; }
    const T *holder_shift() const { return moved_h_ ? dh_ : nullptr; }

  private:
    static void add(T *to, bool &moved, const T *v) {
        if (moved)
            for (int k = 0; k < 3; ++k) to[k] += v[k];
        else
            for (int k = 0; k < 3; ++k) to[k] = v[k];
        moved = true;
    }
    T dA_[3];
    T dh_[3];
    bool moved_A_ = false, moved_h_ = false;
};

// Path stage: the vector from the (displaced) anchor to the (displaced)
// holder point, and the pot's exit axis (unit). The hook's `length` holds the
// straight-line length |d| on entry.
template <class T> struct PathIn {
    const double *u;
    const T *d;
};

// Transfer stage: `length` is the cable length the drum counts (mm),
// `reading` the pot's reading so far. Both are the path length on entry.
// A hook that changes what the drum counts scales both; one that acts on
// the pot adds to or scales `reading` only.
template <class T> struct TransferState {
    T length;
    T reading;
};

// Which other effects are in the model, for effects whose parameters lose a
// degree of freedom to another effect (a gauge).
struct GaugeContext {
    const DeviceGeometry &g;
    bool (*has_fn)(const void *ctx, const char *name);
    const void *ctx;
    bool has(const char *name) const { return has_fn(ctx, name); }
};

struct EffectBase {
    static constexpr int kCableParams = 0;
    // A Path-stage hook composes by adding to the length it is given; one
    // that sets it from the geometry instead declares it here, and the
    // kernel requires it to come before every other Path-stage effect
    // (model/kernel.h: paths_compose), so it cannot cancel one silently.
    static constexpr bool kReplacesLength = false;
    static void cable_params(int, int *) {}
    // basis: columns span the parameter combinations the fit may move
    // (full = start + basis * free); false: every parameter is free.
    static bool gauge(const GaugeContext &, Eigen::MatrixXd &) { return false; }
};

// Eigen's atan2 for AutoDiffScalar returns a dynamically sized derivative
// (a heap allocation on the driver's path); this one keeps the caller's type.
inline double kernel_atan2(double y, double x) { return std::atan2(y, x); }
template <class D>
Eigen::AutoDiffScalar<D> kernel_atan2(const Eigen::AutoDiffScalar<D> &y, const Eigen::AutoDiffScalar<D> &x) {
    const double yv = y.value(), xv = x.value();
    const double den = xv * xv + yv * yv;
    Eigen::internal::make_coherent(y.derivatives(), x.derivatives());
    return Eigen::AutoDiffScalar<D>(std::atan2(yv, xv), D((y.derivatives() * xv - x.derivatives() * yv) / den));
}

// sin and cos of one angle: for a differentiated angle each needs both of
// the value's sin and cos, so the pair shares them (std::sin and std::cos
// separately would evaluate them twice).
inline void kernel_sincos(double a, double &s, double &c) {
    s = std::sin(a);
    c = std::cos(a);
}
template <class D>
void kernel_sincos(const Eigen::AutoDiffScalar<D> &a, Eigen::AutoDiffScalar<D> &s, Eigen::AutoDiffScalar<D> &c) {
    const double sv = std::sin(a.value()), cv = std::cos(a.value());
    s = Eigen::AutoDiffScalar<D>(sv, D(a.derivatives() * cv));
    c = Eigen::AutoDiffScalar<D>(cv, D(a.derivatives() * -sv));
}

// Rotation by a rotation vector (Rodrigues).
template <class T> void rotvec_apply(const T w[3], const T x[3], T out[3]) {
    using std::cos;
    using std::sin;
    using std::sqrt;
    T th2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    // Series below 1e-12 rad^2 keeps derivatives exact at zero.
    T a, b;
    if (th2 < T(1e-12)) {
        a = T(1) - th2 / T(6);
        b = T(0.5) - th2 / T(24);
    } else {
        T th = sqrt(th2);
        a = sin(th) / th;
        b = (T(1) - cos(th)) / th2;
    }
    T c[3] = {w[1] * x[2] - w[2] * x[1], w[2] * x[0] - w[0] * x[2], w[0] * x[1] - w[1] * x[0]};
    T cc[3] = {w[1] * c[2] - w[2] * c[1], w[2] * c[0] - w[0] * c[2], w[0] * c[1] - w[1] * c[0]};
    for (int k = 0; k < 3; ++k) out[k] = x[k] + a * c[k] + b * cc[k];
}

inline ParamDesc param(std::string name, std::string unit, double scale, double lower, double upper,
                       double init, double rand_lo, double rand_hi, bool signed_random = true) {
    return ParamDesc{std::move(name), std::move(unit), scale, lower, upper, init, rand_lo, rand_hi, signed_random};
}

} // namespace cdm
