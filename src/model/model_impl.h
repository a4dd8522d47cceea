// Model internals, shared with the fit (calib/). Not part of any API.
#pragma once

#include <array>
#include <vector>

#include "model/effect.h"
#include "model/kernel.h"
#include "model/model.h"

namespace cdm {

struct EffectInst {
    EffectDescPtr desc;
    std::vector<double> p;
};

struct Model::Impl {
    DeviceGeometry g;
    std::vector<EffectInst> effects; // ordered by stage
    std::array<int, E_BUILTIN_COUNT> idx{};
    bool has_user = false;
    bool reading_effects = false; // anything besides jig and ellipsoid

    void refresh();
    const double *params(int builtin) const {
        return idx[builtin] >= 0 ? effects[idx[builtin]].p.data() : nullptr;
    }
    // Cable i's variables from the current parameters (double).
    CableVars<double> cable_vars(int i) const;
    bool pulley() const { return idx[E_PULLEY] >= 0; }
    // Readings of the built-in stages only (before user effects).
    void builtin_readings(const double p[3], double out[4]) const;
    void apply_user(const double p[3], double readings[4]) const;
    void ellipsoid_correct(double p[3]) const;
};

// Rotation matrix of a rotation vector (Rodrigues), templated for the fit.
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

} // namespace cdm
