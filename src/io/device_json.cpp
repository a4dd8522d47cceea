#include "io/device_json.h"

#include <cmath>
#include <sstream>

#include "io/file.h"

namespace cdm::io {

namespace {
std::string num(double v) {
    std::ostringstream os;
    os.precision(6);
    os << v;
    return os.str();
}

bool axis_from_json(const JsonValue &v, int i, const std::string &source, std::array<double, 3> &out,
                    std::string &err) {
    const std::string name = "exit_axis[" + std::to_string(i) + "]";
    if (v.type != JsonValue::Array || v.items.size() != 3) {
        err = where(source, v) + name + " must be [x,y,z] numbers, got " + v.type_name();
        return false;
    }
    double x[3];
    for (int k = 0; k < 3; ++k) {
        if (v.items[size_t(k)].type != JsonValue::Number) {
            err = where(source, v.items[size_t(k)]) + name + " must be [x,y,z] numbers";
            return false;
        }
        x[k] = v.items[size_t(k)].number;
    }
    const double n = std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    if (!std::isfinite(n) || n < kAxisNormMin || n > kAxisNormMax) {
        err = where(source, v) + name + " has length " + num(n) + ", expected a unit vector (0.5 to 2 accepted)";
        return false;
    }
    out = {x[0] / n, x[1] / n, x[2] / n};
    return true;
}
} // namespace

bool get_number(const JsonValue &j, const char *key, double lo, double hi, const char *unit,
                const std::string &source, double &out, std::string &err, bool required, const std::string &context) {
    const JsonValue *v = j.find(key);
    if (!v) {
        if (required) err = where(source, j) + context + "missing required field \"" + key + "\"";
        return !required;
    }
    if (v->type != JsonValue::Number) {
        err = where(source, *v) + context + "field \"" + key + "\" must be a number, got " + v->type_name();
        return false;
    }
    if (!std::isfinite(v->number) || v->number < lo || v->number > hi) {
        err = where(source, *v) + context + "field \"" + key + "\" = " + num(v->number) + " " + unit + " is outside the sane range " +
              num(lo) + " to " + num(hi) + " " + unit;
        return false;
    }
    out = v->number;
    return true;
}

bool device_from_json(const JsonValue &j, const std::string &source, DeviceGeometry &out, std::string &err) {
    if (j.type != JsonValue::Object) {
        err = where(source, j) + "a device description must be a JSON object, got " + j.type_name();
        return false;
    }
    // Schema of a device description (a file of its own, or a calibration's
    // "device"), version 1: these keys only. "format" and "version" are
    // optional and, when given, must say "cdm-device" and 1.
    if (!only_keys(j, {"format", "version", "a_mm", "b_mm", "m_mm", "pulley_radius_mm", "exit_axis"}, source,
                   "a device description (cdm-device version 1)", err))
        return false;
    if (const JsonValue *f = j.find("format"); f && (f->type != JsonValue::String || f->str != "cdm-device")) {
        err = where(source, *f) + "\"format\" of a device description must be \"cdm-device\"";
        return false;
    }
    if (const JsonValue *v = j.find("version"); v && (v->type != JsonValue::Number || v->number != 1)) {
        err = where(source, *v) + "unsupported device description version (this library reads version 1)";
        return false;
    }
    DeviceGeometry g;
    // "pulley_radius_mm": files written by cdm 1.0 and 1.1 carry it; the
    // pulley's radius is exit_pulley's own parameter, so the key is checked
    // and its value not used.
    double pulley_radius_mm = 0;
    if (!get_number(j, "a_mm", kFrameMinMm, kFrameMaxMm, "mm", source, g.a_mm, err, true) ||
        !get_number(j, "b_mm", kFrameMinMm, kFrameMaxMm, "mm", source, g.b_mm, err, true) ||
        !get_number(j, "m_mm", kHolderMinMm, kFrameMaxMm, "mm", source, g.m_mm, err, true) ||
        !get_number(j, "pulley_radius_mm", 0.0, kPulleyMaxMm, "mm", source, pulley_radius_mm, err, false))
        return false;
    if (g.m_mm >= 2 * g.a_mm || g.m_mm >= 2 * g.b_mm) {
        err = where(source, *j.find("m_mm")) + "m_mm must be smaller than 2*a_mm and 2*b_mm (the holder is inside the frame)";
        return false;
    }
    if (const JsonValue *ax = j.find("exit_axis")) {
        // One [x,y,z] for the four pots, or one per cable.
        const bool one = ax->type == JsonValue::Array && ax->items.size() == 3 &&
                         ax->items[0].type == JsonValue::Number;
        if (!one && (ax->type != JsonValue::Array || ax->items.size() != 4)) {
            err = where(source, *ax) + "\"exit_axis\" must be [x,y,z] (all cables) or an array of 4 [x,y,z] (cables 1..4)";
            return false;
        }
        for (int i = 0; i < 4; ++i)
            if (!axis_from_json(one ? *ax : ax->items[size_t(i)], i, source, g.exit_axis[size_t(i)], err)) return false;
    }
    out = g;
    return true;
}

bool parse_device_json(const std::string &text, const std::string &source, DeviceGeometry &out, std::string &err) {
    JsonValue j;
    return parse_json(text, source, j, err) && device_from_json(j, source, out, err);
}

bool load_device_json(const std::string &path, DeviceGeometry &out, std::string &err) {
    JsonValue j;
    return load_json(path, j, err, "device description") && device_from_json(j, path, out, err);
}

nlohmann::json device_to_json(const DeviceGeometry &g) {
    nlohmann::json j;
    j["a_mm"] = g.a_mm;
    j["b_mm"] = g.b_mm;
    j["m_mm"] = g.m_mm;
    j["exit_axis"] = g.exit_axis;
    return j;
}

} // namespace cdm::io
