// The parameter layout of a model, computed once per change of its effects.
#include "model/evaluator.h"
#include "model/model_impl.h"

namespace cdm {

namespace {
// Per built-in: how many parameters one cable depends on, and which.
struct CableParamsFn {
    int count;
    void (*fill)(int cable, int *idx);
};
constexpr CableParamsFn kCableParamsFn[] = {
#define CDM_EFFECT_CP(E) {E::kCableParams, &E::cable_params},
    CDM_BUILTIN_EFFECTS(CDM_EFFECT_CP)
#undef CDM_EFFECT_CP
};
} // namespace

ModelLayout build_layout(const std::vector<const EffectDesc *> &descs) {
    ModelLayout L;
    L.idx.fill(-1);
    L.cable.slot.fill(-1);
    for (size_t k = 0; k < descs.size(); ++k) {
        const EffectDesc &d = *descs[k];
        if (d.builtin_id >= 0) L.idx[size_t(d.builtin_id)] = int(k);
        if (d.stage == Stage::User) {
            L.has_user = true;
            L.has_geom = L.has_geom || d.apply_geom;
            L.has_path_user = L.has_path_user || d.on_path;
        }
        if (d.stage != Stage::Jig && d.stage != Stage::Position) L.reading_effects = true;
    }
    // Slots in list order (the order of application).
    for (int id = 0; id < kBuiltinCount; ++id) {
        const int e = L.idx[size_t(id)];
        const CableParamsFn &f = kCableParamsFn[id];
        if (e < 0 || f.count == 0) continue;
        L.cable.slot[size_t(id)] = L.cable.nslots;
        for (int i = 0; i < 4; ++i) {
            int idx[kMaxCableSlots > 0 ? kMaxCableSlots : 1];
            f.fill(i, idx);
            for (int c = 0; c < f.count; ++c) {
                L.slot_effect[size_t(i)][size_t(L.cable.nslots + c)] = e;
                L.slot_param[size_t(i)][size_t(L.cable.nslots + c)] = idx[c];
            }
        }
        L.cable.nslots += f.count;
    }
    return L;
}

namespace {
bool has_effect_fn(const void *ctx, const char *name) { return static_cast<const Model *>(ctx)->has_effect(name); }
} // namespace

Eigen::MatrixXd effect_gauge_basis(const Model &m, size_t e) {
    using GaugeFn = bool (*)(const GaugeContext &, Eigen::MatrixXd &);
    static constexpr GaugeFn fn[] = {
#define CDM_EFFECT_GAUGE(E) &E::gauge,
        CDM_BUILTIN_EFFECTS(CDM_EFFECT_GAUGE)
#undef CDM_EFFECT_GAUGE
    };
    const int np = int(m.effect_params(e).size());
    const int id = m.effect_desc(e).builtin_id;
    Eigen::MatrixXd basis;
    const GaugeContext gc{m.geometry(), &has_effect_fn, &m};
    if (id < 0 || id >= kBuiltinCount || !fn[id](gc, basis)) return Eigen::MatrixXd::Identity(np, np);
    return basis;
}

} // namespace cdm
