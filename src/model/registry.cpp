// The registry: the built-ins from the one list (effects/list.h), then the
// effects users register at run time.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
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

namespace {

// Whether the caller's struct_size covers field f (a caller built against
// an older header has a smaller struct, and the later fields are not there).
#define CDM_DEF_HAS(def, f) ((def)->struct_size >= offsetof(cdm_effect_def, f) + sizeof((def)->f))

thread_local const char *t_registering_origin = nullptr;

bool valid_effect_name(const char *n) {
    if (!n || !*n) return false;
    for (const char *c = n; *c; ++c)
        if (!((*c >= 'a' && *c <= 'z') || (*c >= '0' && *c <= '9') || *c == '_')) return false;
    return true;
}

// since 1.2: a parameter name is an identifier (it is a JSON key, a Python
// attribute, a column of the report) and a unit is printable text without
// quotes or backslashes (it is written into JSON and the docs as is).
bool valid_param_name(const std::string &n) {
    if (n.empty() || !(std::isalpha((unsigned char)n[0]) || n[0] == '_')) return false;
    for (char c : n)
        if (!(std::isalnum((unsigned char)c) || c == '_')) return false;
    return true;
}
// Well-formed UTF-8 (no overlong form, no surrogate, nothing past
// U+10FFFF): a name or unit is written into JSON, which must be UTF-8.
bool valid_utf8(const std::string &s) {
    size_t i = 0;
    while (i < s.size()) {
        const unsigned char c = (unsigned char)s[i];
        size_t n;
        uint32_t cp;
        if (c < 0x80) {
            ++i;
            continue;
        } else if (c >= 0xc2 && c <= 0xdf) {
            n = 1;
            cp = c & 0x1fu;
        } else if (c >= 0xe0 && c <= 0xef) {
            n = 2;
            cp = c & 0x0fu;
        } else if (c >= 0xf0 && c <= 0xf4) {
            n = 3;
            cp = c & 0x07u;
        } else {
            return false;
        }
        if (i + n >= s.size()) return false; // cut short
        for (size_t k = 1; k <= n; ++k) {
            const unsigned char d = (unsigned char)s[i + k];
            if ((d & 0xc0u) != 0x80u) return false;
            cp = (cp << 6) | (d & 0x3fu);
        }
        if ((n == 2 && cp < 0x800) || (n == 3 && (cp < 0x10000 || cp > 0x10ffff)) || (cp >= 0xd800 && cp <= 0xdfff))
            return false;
        i += n + 1;
    }
    return true;
}
bool valid_unit(const std::string &u) {
    for (char c : u)
        if ((unsigned char)c < 0x20 || c == '"' || c == '\\' || c == 0x7f) return false;
    return true;
}

// Parameter k of def: name, unit, scale, bounds, start. v12: the caller's
// struct is 1.2's (names and units checked, positive random draws where the
// lower bound is >= 0).
bool user_param(const cdm_effect_def *def, uint32_t k, bool v12, const std::string &effect, ParamDesc &p,
                std::string &err) {
    const std::string at = "cdm_effect_register: effect \"" + effect + "\" parameter ";
    p.name = def->param_names[k] ? def->param_names[k] : ("p" + std::to_string(k));
    const char *const *units = v12 ? def->param_units : nullptr;
    p.unit = units && units[k] ? units[k] : "";
    if (v12 && (!def->param_names[k] || !valid_param_name(p.name))) {
        err = at + std::to_string(k) + ": name must be an identifier ([A-Za-z_][A-Za-z0-9_]*), got \"" +
              (def->param_names[k] ? p.name : "(null)") + "\"";
        return false;
    }
    if (!valid_utf8(p.name) || !valid_utf8(p.unit)) {
        err = at + std::to_string(k) + ": name or unit is not valid UTF-8";
        return false;
    }
    if (v12 && !valid_unit(p.unit)) {
        err = at + "\"" + p.name + "\": unit has a control character, a quote or a backslash";
        return false;
    }
    p.scale = def->param_scale[k];
    if (!(p.scale > 0) || !std::isfinite(p.scale)) {
        err = at + "\"" + p.name + "\" needs a positive finite param_scale";
        return false;
    }
    p.lower = def->lower ? def->lower[k] : -1e3 * p.scale;
    p.upper = def->upper ? def->upper[k] : 1e3 * p.scale;
    if (!(p.lower <= 0 && 0 <= p.upper) && !(p.lower < p.upper)) {
        err = at + "\"" + p.name + "\" has lower > upper";
        return false;
    }
    p.init = std::min(std::max(0.0, p.lower), p.upper);
    if (CDM_DEF_HAS(def, initial) && def->initial) {
        const double v = def->initial[k];
        if (!std::isfinite(v) || v < p.lower || v > p.upper) {
            err = at + "\"" + p.name + "\": initial value outside [lower, upper] or not finite";
            return false;
        }
        p.init = v;
    }
    p.rand_lo = 0.5 * p.scale;
    p.rand_hi = 2 * p.scale;
    if (v12 && p.lower >= 0) p.signed_random = false;
    // The C ABI's declaration of a period in cable length (cdm.h,
    // cdm_effect_def.param_names): a parameter named "period" in mm.
    if (p.name == "period" && (p.unit == "mm" || p.unit.empty())) p.role = ParamRole::LengthPeriod;
    return true;
}

// The callbacks and the stage (since 1.1: apply_batch; since 1.2:
// apply_geom, stage, origin).
bool user_callbacks(const cdm_effect_def *def, EffectDesc &d, std::string &err) {
    d.apply = def->apply;
    d.apply_batch = CDM_DEF_HAS(def, apply_batch) ? def->apply_batch : nullptr;
    d.apply_geom = CDM_DEF_HAS(def, apply_geom) ? def->apply_geom : nullptr;
    const uint32_t stage = CDM_DEF_HAS(def, stage) ? def->stage : uint32_t(CDM_EFFECT_STAGE_READING);
    if (!d.apply && !d.apply_batch && !d.apply_geom) {
        err = "cdm_effect_register: effect \"" + d.name + "\" has none of apply, apply_batch and apply_geom";
        return false;
    }
    if (stage != CDM_EFFECT_STAGE_READING && stage != CDM_EFFECT_STAGE_PATH) {
        err = "cdm_effect_register: effect \"" + d.name + "\": stage " + std::to_string(stage) +
              " is neither CDM_EFFECT_STAGE_READING (0) nor CDM_EFFECT_STAGE_PATH (1)";
        return false;
    }
    if (stage == CDM_EFFECT_STAGE_PATH && !d.apply_geom) {
        err = "cdm_effect_register: effect \"" + d.name + "\": CDM_EFFECT_STAGE_PATH needs apply_geom";
        return false;
    }
    d.on_path = stage == CDM_EFFECT_STAGE_PATH;
    const char *origin = CDM_DEF_HAS(def, origin) ? def->origin : nullptr;
    if (t_registering_origin) origin = t_registering_origin;
    d.origin = origin ? origin : "";
    return true;
}

} // namespace

void set_registering_origin(const char *origin) { t_registering_origin = origin; }

std::string effect_fingerprint(const EffectDesc &d) {
    uint64_t h = 14695981039346656037ull; // FNV-1a 64: offset basis, then per byte xor and multiply
    auto feed = [&h](const std::string &s) {
        for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
        h = (h ^ 0x1f) * 1099511628211ull; // a separator no name or unit holds
    };
    feed(d.on_path ? "path" : "reading");
    for (const auto &p : d.params) {
        feed(p.name);
        feed(p.unit);
    }
    char b[17];
    std::snprintf(b, sizeof b, "%016llx", (unsigned long long)h);
    return b;
}

int register_user_effect(const cdm_effect_def *def, std::string &err) {
    if (!def || def->struct_size < offsetof(cdm_effect_def, initial)) {
        err = "cdm_effect_register: NULL definition or struct_size smaller than the 1.0 cdm_effect_def";
        return CDM_ERR_INVALID_ARG;
    }
    if (!valid_effect_name(def->name)) {
        err = std::string("cdm_effect_register: name must match [a-z0-9_]+, got \"") +
              (def->name ? def->name : "(null)") + "\"";
        return CDM_ERR_INVALID_ARG;
    }
    auto d = std::make_shared<EffectDesc>();
    d->name = def->name;
    d->doc = def->doc ? def->doc : "";
    d->stage = Stage::User;
    d->builtin_id = -1;
    d->user = def->user;
    if (!user_callbacks(def, *d, err)) return CDM_ERR_INVALID_ARG;
    if (def->n_params > uint32_t(kMaxUserParams) ||
        (def->n_params > 0 && (!def->param_names || !def->param_scale))) {
        err = std::string("cdm_effect_register: effect \"") + def->name +
              "\" needs param_names and param_scale for its n_params (at most " + std::to_string(kMaxUserParams) +
              ")";
        return CDM_ERR_INVALID_ARG;
    }
    const bool v12 = CDM_DEF_HAS(def, stage);
    for (uint32_t k = 0; k < def->n_params; ++k) {
        ParamDesc p;
        if (!user_param(def, k, v12, d->name, p, err)) return CDM_ERR_INVALID_ARG;
        for (const auto &q : d->params)
            if (q.name == p.name) { // a calibration's "params" object could not hold both
                err = "cdm_effect_register: effect \"" + d->name + "\" has two parameters named \"" + p.name + "\"";
                return CDM_ERR_INVALID_ARG;
            }
        d->params.push_back(p);
    }
    d->fingerprint = effect_fingerprint(*d);
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
