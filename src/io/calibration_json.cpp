#include "io/calibration_json.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "io/device_json.h"
#include "model/effect.h"

namespace cdm::io {

namespace {
// A length in a message: 4 significant digits (a shift of 2.9e10 mm reads as such).
std::string fmt_mm(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.4g", v);
    return b;
}

// An origin as the calibration gives it: a path the user must read whole
// (quote_field's 40 characters would cut it), capped against a hostile file.
std::string shown_origin(const std::string &o) {
    constexpr size_t kShown = 1024;
    return o.size() <= kShown ? o : o.substr(0, kShown) + "... (" + std::to_string(o.size() - kShown) + " more)";
}

// What to do to have a user effect registered, from the origin a
// calibration recorded for it.
std::string load_hint(const std::string &origin) {
    const std::string py = "python:", cs = "csharp:";
    if (origin.compare(0, py.size(), py) == 0)
        return "register it from Python first (import the module " + shown_origin(origin.substr(py.size())) +
               " in the process that loads the calibration, e.g. before cdm.open(uri, calibration=...))";
    if (origin.compare(0, cs.size(), cs) == 0)
        return "register it from C# first (Cdm.Effects.Register, in " + shown_origin(origin.substr(cs.size())) +
               ", in the process that loads the calibration)";
    return "load its plugin " + shown_origin(origin) +
           " first (--plugin with the cdm command, cdm_effect_load_plugin, cdm.load_plugin)";
}

// A user effect's entry may carry the fingerprint of the parameters it was
// fitted with (written since 1.2); the effect registered now must have the
// same, or its values would be read as other quantities.
bool fingerprint_matches(const JsonValue &e, const std::string &at, const std::string &source, const EffectDesc &d,
                         std::string &err) {
    const JsonValue *fp = e.find("fingerprint");
    if (!fp) return true;
    if (fp->type != JsonValue::String) {
        err = where(source, *fp) + at + " (\"" + d.name + "\"): \"fingerprint\" must be a string";
        return false;
    }
    const std::string now = d.is_user() ? d.fingerprint : effect_fingerprint(d);
    if (fp->str == now) return true;
    const JsonValue *origin = e.find("origin");
    const std::string was = origin && origin->type == JsonValue::String ? origin->str : "";
    err = where(source, *fp) + at + ": effect \"" + d.name + "\" was fitted with the parameter list whose " +
          "fingerprint is " + quote_field(fp->str) + (was.empty() ? "" : " (from " + shown_origin(was) + ")") +
          ", the registered one's is " + now + (d.origin.empty() ? "" : " (from " + d.origin + ")") +
          ": its parameter names, units or stage differ; load the version of the effect it was fitted with, "
          "or fit again";
    return false;
}

bool effect_from_json(const JsonValue &e, size_t k, const std::string &source, Model &m, std::string &err) {
    const std::string at = "effects[" + std::to_string(k) + "]";
    const JsonValue *name = e.find("name");
    if (e.type != JsonValue::Object || !name || name->type != JsonValue::String) {
        err = where(source, e) + at + " needs a \"name\" string";
        return false;
    }
    if (!only_keys(e, {"name", "params", "origin", "fingerprint"}, source, at + " (cdm-calibration version 1)", err))
        return false;
    const EffectDescPtr d = find_effect(name->str);
    const JsonValue *origin = e.find("origin");
    if (!d && origin && origin->type == JsonValue::String && !origin->str.empty()) {
        err = where(source, *name) + at + ": user effect \"" + quote_field(name->str) + "\" is not registered: " +
              load_hint(origin->str) + " before loading this calibration";
        return false;
    }
    if (!d) {
        std::string known;
        for (auto &x : all_effects()) known += (known.empty() ? "" : ", ") + x->name;
        err = where(source, *name) + at + ": unknown effect \"" + quote_field(name->str) + "\" (known: " + known + ")";
        return false;
    }
    if (!fingerprint_matches(e, at, source, *d, err)) return false;
    const JsonValue *ps = e.find("params");
    if (!ps || ps->type != JsonValue::Object) {
        err = where(source, ps ? *ps : e) + at + " (\"" + d->name +
              "\") needs \"params\": an object giving each of its parameters";
        return false;
    }
    for (const auto &kv : ps->members)
        if (std::none_of(d->params.begin(), d->params.end(), [&](const ParamDesc &p) { return p.name == kv.first; })) {
            err = where(source, kv.second) + "effect \"" + d->name + "\" has no parameter \"" + quote_field(kv.first) + "\"";
            return false;
        }
    ParamValues values;
    for (const auto &p : d->params) {
        const std::string unit = p.unit.empty() ? "" : p.unit;
        double v = 0;
        if (!get_number(*ps, p.name.c_str(), p.lower, p.upper, unit.c_str(), source, v, err, true,
                        "effect \"" + d->name + "\": "))
            return false;
        values.emplace_back(p.name, v);
    }
    std::string e2;
    if (!m.add_effect(d->name, values, e2)) {
        err = where(source, e) + at + ": " + e2;
        return false;
    }
    return true;
}
// The calibrated model against the nominal one over the holder's
// workspace: at each of 27 grid points p (x = 0.25, 0.5, 1 x min(a, b) out
// of the plane; y, z = -a/2, 0, +a/2 and -b/2, 0, +b/2) the nominal cable
// lengths at p are solved with the calibrated model; every position it
// gives must be finite and within kMaxShiftFraction x min(a, b) of p. An effect's
// parameter bounds cannot catch a combination that moves the workspace by
// metres (the ellipsoid's L = 1e9 with M = N = 1: x = 2.9e10 mm); this
// does, whatever the parameters.
constexpr double kMaxShiftFraction = 0.2;

bool workspace_plausible(const Model &m, const JsonValue &j, const std::string &source, std::string &err) {
    if (m.is_nominal()) return true;
    const DeviceGeometry &g = m.geometry();
    const double scale = std::min(g.a_mm, g.b_mm), bound = kMaxShiftFraction * scale;
    double worst = -1, worst_at[3] = {0, 0, 0};
    for (double fx : {0.25, 0.5, 1.0})
        for (double fy : {-0.5, 0.0, 0.5})
            for (double fz : {-0.5, 0.0, 0.5}) {
                const double p[3] = {fx * scale, fy * g.a_mm, fz * g.b_mm};
                double l[4], q[3];
                nominal_lengths(g, p, l);
                // No solution is no wrong pose (the driver flags the report
                // OUT_OF_WORKSPACE and holds the last one): a point is only
                // skipped. A solution must be finite and near.
                if (m.position(l, q) != 0) continue;
                const double d = std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2])
                                     ? std::hypot(q[0] - p[0], q[1] - p[1], q[2] - p[2])
                                     : HUGE_VAL;
                if (d > worst) {
                    worst = d;
                    std::copy(p, p + 3, worst_at);
                }
            }
    if (worst <= bound) return true;
    err = where(source, j) + "the calibration moves the holder by " + fmt_mm(worst) + " mm at the workspace point (" +
          fmt_mm(worst_at[0]) + ", " + fmt_mm(worst_at[1]) + ", " + fmt_mm(worst_at[2]) +
          ") mm; a calibration may move it by at most " + fmt_mm(bound) + " mm (" +
          std::to_string(int(kMaxShiftFraction * 100)) + " % of min(a_mm, b_mm)) whatever its parameters: refused";
    return false;
}
} // namespace

bool model_from_json(const JsonValue &j, const std::string &source, Model &out, std::string &err) {
    const JsonValue *fmt = j.find("format");
    if (j.type != JsonValue::Object || !fmt || fmt->type != JsonValue::String || fmt->str != "cdm-calibration") {
        err = where(source, j) + "not a cdm calibration (expected {\"format\": \"cdm-calibration\", ...})";
        return false;
    }
    const JsonValue *ver = j.find("version");
    if (!ver || ver->type != JsonValue::Number || ver->number != 1) {
        err = where(source, ver ? *ver : j) + "unsupported calibration version (this library reads version 1)";
        return false;
    }
    // Schema cdm-calibration version 1: these keys only ("fit": what the
    // fit wrote about itself, never read back).
    if (!only_keys(j, {"format", "version", "device", "effects", "fit"}, source, "a calibration (cdm-calibration version 1)",
                   err))
        return false;
    const JsonValue *dev = j.find("device");
    if (!dev) {
        err = where(source, j) + "missing \"device\"";
        return false;
    }
    DeviceGeometry g;
    if (!device_from_json(*dev, source, g, err)) return false;
    Model m(g);
    if (const JsonValue *ef = j.find("effects")) {
        if (ef->type != JsonValue::Array) {
            err = where(source, *ef) + "\"effects\" must be an array";
            return false;
        }
        for (size_t k = 0; k < ef->items.size(); ++k)
            if (!effect_from_json(ef->items[k], k, source, m, err)) return false;
    }
    if (!workspace_plausible(m, j, source, err)) return false;
    out = m;
    return true;
}

bool parse_calibration_json(const std::string &text, const std::string &source, Model &out, std::string &err) {
    JsonValue j;
    return parse_json(text, source, j, err) && model_from_json(j, source, out, err);
}

bool load_calibration(const std::string &path, Model &out, std::string &err) {
    JsonValue j;
    return load_json(path, j, err, "calibration") && model_from_json(j, path, out, err);
}

nlohmann::json model_to_json(const Model &m) {
    nlohmann::json j;
    j["format"] = "cdm-calibration";
    j["version"] = 1;
    j["device"] = io::device_to_json(m.geometry());
    j["effects"] = nlohmann::json::array();
    for (size_t i = 0; i < m.effect_count(); ++i) {
        const EffectDesc &d = m.effect_desc(i);
        const auto &p = m.effect_params(i);
        nlohmann::json ps = nlohmann::json::object();
        for (size_t k = 0; k < p.size(); ++k) ps[d.params[k].name] = p[k];
        nlohmann::json ej = {{"name", d.name}, {"params", ps}};
        // A user effect: where it comes from and what its values mean, so
        // that loading the calibration without it, or with another version
        // of it, says so (effect_from_json).
        if (d.is_user()) {
            if (!d.origin.empty()) ej["origin"] = d.origin;
            ej["fingerprint"] = d.fingerprint;
        }
        j["effects"].push_back(ej);
    }
    return j;
}

} // namespace cdm::io
