// The measurement kernel, generated from the effect list (effects/list.h):
// one cable's predicted reading at a sample, the jig map and the position
// correction, templated on the scalar so that the fit (AutoDiffScalar over
// the position and the cable's own parameters), the forward kinematics
// (AutoDiffScalar over the position) and the simulator (double) run the
// same code. Private to src/model.
#pragma once

#include <array>
#include <cmath>

#include "model/effects/list.h"

namespace cdm {

enum BuiltinIndex : int {
#define CDM_EFFECT_INDEX(E) kIdx_##E,
    CDM_BUILTIN_EFFECTS(CDM_EFFECT_INDEX)
#undef CDM_EFFECT_INDEX
    kBuiltinCount
};

template <class E> struct BuiltinIndexOf;
#define CDM_EFFECT_INDEX_OF(E)                                                                                       \
    template <> struct BuiltinIndexOf<E> {                                                                           \
        static constexpr int value = kIdx_##E;                                                                       \
    };
CDM_BUILTIN_EFFECTS(CDM_EFFECT_INDEX_OF)
#undef CDM_EFFECT_INDEX_OF

// Every cable parameter of every built-in, if all were on: the size of the
// per-cable parameter block (and of the fit's AD derivative vector, + 3).
constexpr int kMaxCableSlots = 0
#define CDM_EFFECT_SLOTS(E) +E::kCableParams
    CDM_BUILTIN_EFFECTS(CDM_EFFECT_SLOTS);
#undef CDM_EFFECT_SLOTS

// The list order is the order of application, so stages may not decrease.
constexpr bool stages_in_order() {
    const Stage s[] = {
#define CDM_EFFECT_STAGE(E) E::kStage,
        CDM_BUILTIN_EFFECTS(CDM_EFFECT_STAGE)
#undef CDM_EFFECT_STAGE
    };
    for (size_t k = 1; k < sizeof s / sizeof s[0]; ++k)
        if (s[k] < s[k - 1]) return false;
    return true;
}
static_assert(stages_in_order(), "effects/list.h: the list is the order of application; stages must not decrease");

// A Path-stage effect that replaces the length (kReplacesLength) would
// undo every Path-stage effect listed before it: only the first may.
constexpr bool paths_compose() {
    const bool path[] = {
#define CDM_EFFECT_PATH(E) E::kStage == Stage::Path,
        CDM_BUILTIN_EFFECTS(CDM_EFFECT_PATH)
#undef CDM_EFFECT_PATH
    };
    const bool replaces[] = {
#define CDM_EFFECT_REPLACES(E) E::kReplacesLength,
        CDM_BUILTIN_EFFECTS(CDM_EFFECT_REPLACES)
#undef CDM_EFFECT_REPLACES
    };
    bool seen = false;
    for (size_t k = 0; k < sizeof path / sizeof path[0]; ++k) {
        if (!path[k]) continue;
        if (replaces[k] && seen) return false;
        seen = true;
    }
    return true;
}
static_assert(paths_compose(), "effects/list.h: a Path-stage effect that replaces the length (kReplacesLength) must "
                               "come before every other Path-stage effect");

// Where each active reading-stage built-in's cable parameters sit in a
// cable's parameter block: slot[id] is the first, -1 when the effect is off.
// The same for the four cables (kCableParams is per effect).
struct CableLayout {
    std::array<int, kBuiltinCount> slot;
    int nslots = 0;
};

// Parameters of whole effects (Jig and Position stages): p[id], or nullptr.
template <class T> using EffectParams = std::array<const T *, kBuiltinCount>;

namespace detail {
template <class E, class T>
void geometry_step(const CableLayout &lay, const T *q, int i, const Sample<T> &s, CableGeom<T> &g) {
    if constexpr (E::kStage == Stage::Geometry) {
        const int o = lay.slot[BuiltinIndexOf<E>::value];
        if (o >= 0) E::geometry(q + o, i, s, g);
    }
}
template <class E, class T>
void path_step(const CableLayout &lay, const T *q, int i, const Sample<T> &s, const PathIn<T> &in, T &len) {
    if constexpr (E::kStage == Stage::Path) {
        const int o = lay.slot[BuiltinIndexOf<E>::value];
        if (o >= 0) E::path(q + o, i, s, in, len);
    }
}
template <class E, class T>
void transfer_step(const CableLayout &lay, const T *q, int i, const Sample<T> &s, TransferState<T> &st) {
    if constexpr (E::kStage == Stage::Transfer) {
        const int o = lay.slot[BuiltinIndexOf<E>::value];
        if (o >= 0) E::transfer(q + o, i, s, st);
    }
}
template <class E, class T> void jig_step(const EffectParams<T> &p, T x[3]) {
    if constexpr (E::kStage == Stage::Jig) {
        if (const T *pe = p[BuiltinIndexOf<E>::value]) E::jig(pe, x);
    }
}
template <class E, class T> void position_step(const EffectParams<T> &p, T x[3]) {
    if constexpr (E::kStage == Stage::Position) {
        if (const T *pe = p[BuiltinIndexOf<E>::value]) E::position(pe, x);
    }
}
} // namespace detail

// A scalar's value: the number itself, or an AutoDiffScalar's value.
inline double value_of(double v) { return v; }
template <class D> double value_of(const Eigen::AutoDiffScalar<D> &v) { return v.value(); }

// What a geometry-aware user effect sees of cable i (values only, device
// frame, mm): the anchor and the holder attachment point after the Geometry
// stage, the unit vector from one to the other and their distance.
struct CablePoints {
    double anchor[3], holder[3], unit[3], chord;
};

// Cable i through the Geometry and Path stages: the length the Transfer
// stage receives. q: the cable's parameter block laid out by `lay`. pts,
// when given, receives the cable's points (values only; the length and its
// derivatives do not depend on whether it is given).
template <class T>
T cable_path(const DeviceGeometry &g, int i, const Sample<T> &s, const CableLayout &lay, const T *q,
             CablePoints *pts = nullptr) {
    using std::sqrt;
    const auto A0 = g.anchor(i);
    const auto h0 = g.holder(i);
    CableGeom<T> geo;
#define CDM_STEP(E) detail::geometry_step<E, T>(lay, q, i, s, geo);
    CDM_BUILTIN_EFFECTS(CDM_STEP)
#undef CDM_STEP
    // d = P + h0 + dh - A0 - dA, in that order; a displacement no hook moved
    // is zero and left out, and the drawing's constants are added to the
    // value alone (their derivatives are zero): the same values (at most a
    // zero's sign differs), without the derivative vectors' arithmetic on
    // zeros.
    const T *dh = geo.holder_shift(), *dA = geo.anchor_shift();
    T d[3];
    for (int k = 0; k < 3; ++k) {
        d[k] = T(s.P[k] + h0[k]);
        if (dh) d[k] += dh[k];
        d[k] = T(d[k] - A0[k]);
        if (dA) d[k] -= dA[k];
    }
    T len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (pts) {
        pts->chord = value_of(len);
        for (int k = 0; k < 3; ++k) {
            pts->anchor[k] = A0[k] + (dA ? value_of(dA[k]) : 0.0);
            pts->holder[k] = value_of(s.P[k]) + h0[k] + (dh ? value_of(dh[k]) : 0.0);
            pts->unit[k] = value_of(d[k]) / pts->chord;
        }
    }
    const PathIn<T> in{g.exit_axis[i].data(), d};
#define CDM_STEP(E) detail::path_step<E, T>(lay, q, i, s, in, len);
    CDM_BUILTIN_EFFECTS(CDM_STEP)
#undef CDM_STEP
    return len;
}

// Cable i's reading from the length the Transfer stage receives.
template <class T> T cable_transfer(int i, const Sample<T> &s, const CableLayout &lay, const T *q, const T &len) {
    TransferState<T> st{len, len};
#define CDM_STEP(E) detail::transfer_step<E, T>(lay, q, i, s, st);
    CDM_BUILTIN_EFFECTS(CDM_STEP)
#undef CDM_STEP
    return st.reading;
}

// Cable i's reading from the built-in effects (user effects act between
// the two halves, on the path, or after, on the reading).
template <class T>
T cable_reading(const DeviceGeometry &g, int i, const Sample<T> &s, const CableLayout &lay, const T *q) {
    return cable_transfer<T>(i, s, lay, q, cable_path<T>(g, i, s, lay, q));
}

// Jig reference position -> device frame (Jig-stage effects, in order).
template <class T> void jig_map(const EffectParams<T> &p, T x[3]) {
#define CDM_STEP(E) detail::jig_step<E, T>(p, x);
    CDM_BUILTIN_EFFECTS(CDM_STEP)
#undef CDM_STEP
}

// Position-space corrections (Position-stage effects, in order).
template <class T> void position_map(const EffectParams<T> &p, T x[3]) {
#define CDM_STEP(E) detail::position_step<E, T>(p, x);
    CDM_BUILTIN_EFFECTS(CDM_STEP)
#undef CDM_STEP
}

} // namespace cdm
