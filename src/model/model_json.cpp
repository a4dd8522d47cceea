// See model_json.h.
#include "model/model_json.h"

#include <cmath>
#include <sstream>

#include "model/effect.h"

namespace cdm {

namespace {
bool get_positive(const nlohmann::json &j, const char *key, double &out, const std::string &source,
                  std::string &err, bool required) {
    auto it = j.find(key);
    if (it == j.end()) {
        if (required) {
            err = source + ": missing required field \"" + key + "\"";
            return false;
        }
        return true;
    }
    if (!it->is_number()) {
        err = source + ": field \"" + key + "\" must be a number, got " + it->dump();
        return false;
    }
    double v = it->get<double>();
    if (!std::isfinite(v) || v <= 0) {
        err = source + ": field \"" + key + "\" must be a positive finite number, got " + it->dump();
        return false;
    }
    out = v;
    return true;
}
} // namespace

bool parse_json_text(const std::string &text, const std::string &source, nlohmann::json &out, std::string &err) {
    try {
        out = nlohmann::json::parse(text);
        return true;
    } catch (const nlohmann::json::parse_error &e) {
        // byte offset -> line and column
        size_t line = 1, col = 1;
        for (size_t k = 0; k + 1 < e.byte && k < text.size(); ++k) {
            if (text[k] == '\n') {
                ++line;
                col = 1;
            } else {
                ++col;
            }
        }
        std::ostringstream os;
        os << source << ":" << line << ":" << col << ": JSON syntax error: " << e.what();
        err = os.str();
        return false;
    }
}

bool parse_device_json(const std::string &text, const std::string &source, DeviceGeometry &out,
                       std::string &err) {
    nlohmann::json j;
    if (!parse_json_text(text, source, j, err)) return false;
    if (!j.is_object()) {
        err = source + ": device description must be a JSON object";
        return false;
    }
    DeviceGeometry g;
    if (!get_positive(j, "a_mm", g.a_mm, source, err, true) ||
        !get_positive(j, "b_mm", g.b_mm, source, err, true) ||
        !get_positive(j, "m_mm", g.m_mm, source, err, true) ||
        !get_positive(j, "pulley_radius_mm", g.pulley_radius_mm, source, err, false))
        return false;
    if (g.m_mm >= 2 * g.a_mm || g.m_mm >= 2 * g.b_mm) {
        err = source + ": m_mm must be smaller than 2*a_mm and 2*b_mm (the holder is inside the frame)";
        return false;
    }
    if (auto it = j.find("exit_axis"); it != j.end()) {
        // One [x,y,z] for the four pots, or one per cable.
        const bool one = it->is_array() && it->size() == 3 && (*it)[0].is_number();
        if (!one && (!it->is_array() || it->size() != 4)) {
            err = source + ": \"exit_axis\" must be [x,y,z] (all cables) or an array of 4 [x,y,z] (cables 1..4)";
            return false;
        }
        for (int i = 0; i < 4; ++i) {
            const auto &v = one ? *it : (*it)[i];
            if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() ||
                !v[2].is_number()) {
                err = source + ": exit_axis[" + std::to_string(i) + "] must be [x,y,z] numbers";
                return false;
            }
            double x = v[0], y = v[1], z = v[2];
            double n = std::sqrt(x * x + y * y + z * z);
            if (!(n > 1e-9) || !std::isfinite(n)) {
                err = source + ": exit_axis[" + std::to_string(i) + "] must be a non-zero vector";
                return false;
            }
            g.exit_axis[i] = {x / n, y / n, z / n};
        }
    }
    out = g;
    return true;
}

nlohmann::json device_to_json(const DeviceGeometry &g) {
    nlohmann::json j;
    j["a_mm"] = g.a_mm;
    j["b_mm"] = g.b_mm;
    j["m_mm"] = g.m_mm;
    j["pulley_radius_mm"] = g.pulley_radius_mm;
    j["exit_axis"] = g.exit_axis;
    return j;
}

nlohmann::json model_to_json(const Model &m) {
    nlohmann::json j;
    j["format"] = "cdm-calibration";
    j["version"] = 1;
    j["device"] = device_to_json(m.geometry());
    j["effects"] = nlohmann::json::array();
    for (size_t e = 0; e < m.effect_count(); ++e) {
        const EffectDesc &d = m.effect_desc(e);
        const auto &p = m.effect_params(e);
        nlohmann::json ps = nlohmann::json::object();
        for (size_t k = 0; k < p.size(); ++k) ps[d.params[k].name] = p[k];
        j["effects"].push_back({{"name", d.name}, {"params", ps}});
    }
    return j;
}

bool model_from_json(const nlohmann::json &j, const std::string &source, Model &out, std::string &err) {
    if (!j.is_object() || j.value("format", "") != "cdm-calibration") {
        err = source + ": not a cdm calibration (expected {\"format\": \"cdm-calibration\", ...})";
        return false;
    }
    if (!j.contains("version") || !j["version"].is_number_integer() || j["version"].get<int>() != 1) {
        err = source + ": unsupported calibration version (this library reads version 1)";
        return false;
    }
    if (!j.contains("device")) {
        err = source + ": missing \"device\"";
        return false;
    }
    DeviceGeometry g;
    if (!parse_device_json(j["device"].dump(), source + ": device", g, err)) return false;
    Model m(g);
    if (j.contains("effects")) {
        const auto &ef = j["effects"];
        if (!ef.is_array()) {
            err = source + ": \"effects\" must be an array";
            return false;
        }
        for (size_t k = 0; k < ef.size(); ++k) {
            const auto &e = ef[k];
            const std::string where = source + ": effects[" + std::to_string(k) + "]";
            if (!e.is_object() || !e.contains("name") || !e["name"].is_string()) {
                err = where + " needs a \"name\"";
                return false;
            }
            const std::string name = e["name"].get<std::string>();
            ParamValues pv;
            if (e.contains("params") && !e["params"].is_null()) {
                const auto &ps = e["params"];
                if (!ps.is_object()) {
                    err = where + ": parameters of effect \"" + name + "\" must be an object {name: value}";
                    return false;
                }
                for (auto it = ps.begin(); it != ps.end(); ++it) {
                    if (!it->is_number()) {
                        err = where + ": parameter \"" + it.key() + "\" of effect \"" + name +
                              "\" must be a finite number";
                        return false;
                    }
                    pv.emplace_back(it.key(), it->get<double>());
                }
            }
            std::string e2;
            if (!m.add_effect(name, pv, e2)) {
                err = where + ": " + e2;
                return false;
            }
        }
    }
    out = m;
    return true;
}

} // namespace cdm
