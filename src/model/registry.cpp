// The registry: the built-ins from the one list (effects/list.h), then the
// effects users register at run time.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <mutex>

#include "model/kernel.h"

namespace cdm {
namespace {

std::vector<EffectDescPtr> make_builtins() {
    std::vector<EffectDescPtr> v;
#define CDM_EFFECT_DESC(E)                                                                                           \
    {                                                                                                                \
        EffectDesc d = E::describe();                                                                                \
        d.builtin_id = BuiltinIndexOf<E>::value;                                                                     \
        v.push_back(std::make_shared<const EffectDesc>(std::move(d)));                                               \
    }
    CDM_BUILTIN_EFFECTS(CDM_EFFECT_DESC)
#undef CDM_EFFECT_DESC
    return v;
}

struct Registry {
    std::mutex mu;
    std::vector<EffectDescPtr> builtins = make_builtins();
    std::vector<EffectDescPtr> user;
};

Registry &registry() {
    static Registry r;
    return r;
}

} // namespace

EffectDescPtr find_effect(const std::string &name) {
    auto &r = registry();
    std::lock_guard<std::mutex> lk(r.mu);
    for (auto &e : r.builtins)
        if (e->name == name) return e;
    for (auto &e : r.user)
        if (e->name == name) return e;
    return nullptr;
}

std::vector<EffectDescPtr> all_effects() {
    auto &r = registry();
    std::lock_guard<std::mutex> lk(r.mu);
    auto v = r.builtins;
    v.insert(v.end(), r.user.begin(), r.user.end());
    return v;
}

std::vector<EffectDescPtr> candidate_effects() {
    std::vector<EffectDescPtr> v;
    for (auto &e : all_effects())
        if (e->stage != Stage::Position) v.push_back(e);
    return v;
}

int register_user_effect(const cdm_effect_def *def, std::string &err) {
    if (!def || def->struct_size < offsetof(cdm_effect_def, initial)) {
        err = "cdm_effect_register: NULL definition or struct_size smaller than the 1.0 cdm_effect_def";
        return CDM_ERR_INVALID_ARG;
    }
    auto valid_name = [](const char *n) {
        if (!n || !*n) return false;
        for (const char *c = n; *c; ++c)
            if (!((*c >= 'a' && *c <= 'z') || (*c >= '0' && *c <= '9') || *c == '_')) return false;
        return true;
    };
    if (!valid_name(def->name)) {
        err = std::string("cdm_effect_register: name must match [a-z0-9_]+, got \"") +
              (def->name ? def->name : "(null)") + "\"";
        return CDM_ERR_INVALID_ARG;
    }
    // since 1.1: a caller built against 1.0 has a smaller struct and no
    // `apply_batch` field at all.
    const cdm_effect_apply_batch_fn batch =
        def->struct_size >= offsetof(cdm_effect_def, apply_batch) + sizeof(def->apply_batch) ? def->apply_batch
                                                                                             : nullptr;
    if (!def->apply && !batch) {
        err = std::string("cdm_effect_register: effect \"") + def->name + "\" has neither apply nor apply_batch";
        return CDM_ERR_INVALID_ARG;
    }
    if (def->n_params > uint32_t(kMaxUserParams) ||
        (def->n_params > 0 && (!def->param_names || !def->param_scale))) {
        err = std::string("cdm_effect_register: effect \"") + def->name +
              "\" needs param_names and param_scale for its n_params (at most " + std::to_string(kMaxUserParams) +
              ")";
        return CDM_ERR_INVALID_ARG;
    }
    auto d = std::make_shared<EffectDesc>();
    d->name = def->name;
    d->doc = def->doc ? def->doc : "";
    d->stage = Stage::User;
    d->builtin_id = -1;
    d->apply = def->apply;
    d->apply_batch = batch;
    d->user = def->user;
    for (uint32_t k = 0; k < def->n_params; ++k) {
        ParamDesc p;
        p.name = def->param_names[k] ? def->param_names[k] : ("p" + std::to_string(k));
        p.unit = "";
        p.scale = def->param_scale[k];
        if (!(p.scale > 0) || !std::isfinite(p.scale)) {
            err = "cdm_effect_register: effect \"" + d->name + "\" parameter \"" + p.name +
                  "\" needs a positive finite param_scale";
            return CDM_ERR_INVALID_ARG;
        }
        p.lower = def->lower ? def->lower[k] : -1e3 * p.scale;
        p.upper = def->upper ? def->upper[k] : 1e3 * p.scale;
        if (!(p.lower <= 0 && 0 <= p.upper) && !(p.lower < p.upper)) {
            err = "cdm_effect_register: effect \"" + d->name + "\" parameter \"" + p.name + "\" has lower > upper";
            return CDM_ERR_INVALID_ARG;
        }
        p.init = std::min(std::max(0.0, p.lower), p.upper);
        // since 1.1: a caller built against 1.0 has a smaller struct and no
        // `initial` field at all.
        const bool has_initial = def->struct_size >= offsetof(cdm_effect_def, initial) + sizeof(def->initial);
        if (has_initial && def->initial) {
            const double v = def->initial[k];
            if (!std::isfinite(v) || v < p.lower || v > p.upper) {
                err = "cdm_effect_register: effect \"" + d->name + "\" parameter \"" + p.name +
                      "\": initial value outside [lower, upper] or not finite";
                return CDM_ERR_INVALID_ARG;
            }
            p.init = v;
        }
        p.rand_lo = 0.5 * p.scale;
        p.rand_hi = 2 * p.scale;
        d->params.push_back(p);
    }
    auto &r = registry();
    std::lock_guard<std::mutex> lk(r.mu);
    for (auto &e : r.builtins)
        if (e->name == d->name) {
            err = "cdm_effect_register: \"" + d->name + "\" is a built-in effect's name";
            return CDM_ERR_INVALID_ARG;
        }
    for (auto &e : r.user)
        if (e->name == d->name) {
            e = d; // re-registration replaces (a reloaded plugin, a re-run notebook cell)
            return CDM_OK;
        }
    r.user.push_back(d);
    return CDM_OK;
}

int unregister_user_effect(const std::string &name, std::string &err) {
    auto &r = registry();
    std::lock_guard<std::mutex> lk(r.mu);
    auto it = std::find_if(r.user.begin(), r.user.end(), [&](auto &e) { return e->name == name; });
    if (it == r.user.end()) {
        err = "cdm_effect_unregister: no user effect named \"" + name + "\"";
        return CDM_ERR_INVALID_ARG;
    }
    r.user.erase(it);
    return CDM_OK;
}

} // namespace cdm
