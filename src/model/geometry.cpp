// Nominal geometry and the seed's triangulation (eq. 1-3).
#include <cmath>
#include <sstream>

#include "model/model.h"

namespace cdm {

constexpr double DeviceGeometry::sy[4];
constexpr double DeviceGeometry::sz[4];

std::array<double, 3> DeviceGeometry::anchor(int i) const {
    return {0.0, sy[i] * a_mm, sz[i] * b_mm};
}

std::array<double, 3> DeviceGeometry::holder(int i) const {
    return {0.0, sy[i] * m_mm / 2, sz[i] * m_mm / 2};
}

void nominal_lengths(const DeviceGeometry &g, const double p[3], double lengths[4]) {
    for (int i = 0; i < 4; ++i) {
        auto A = g.anchor(i);
        auto h = g.holder(i);
        double d0 = p[0] + h[0] - A[0], d1 = p[1] + h[1] - A[1], d2 = p[2] + h[2] - A[2];
        lengths[i] = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    }
}

bool triangulate(const DeviceGeometry &g, const double R[4], double p[3]) {
    for (int i = 0; i < 4; ++i)
        if (!std::isfinite(R[i]) || R[i] < 0) return false;
    const double a = g.a_mm, b = g.b_mm, m = g.m_mm;
    const double R1 = R[0] * R[0], R2 = R[1] * R[1], R3 = R[2] * R[2], R4 = R[3] * R[3];
    // eq. (1), (2)
    const double ye = ((R3 - R1) + (R4 - R2)) / (4.0 * (2.0 * a - m));
    const double ze = ((R1 - R2) + (R3 - R4)) / (4.0 * (2.0 * b - m));
    // eq. (3) in the digest's geometric form: mean of the four heights.
    double xs = 0.0;
    for (int i = 0; i < 4; ++i) {
        const double dy = ye - DeviceGeometry::sy[i] * (a - m / 2);
        const double dz = ze - DeviceGeometry::sz[i] * (b - m / 2);
        const double h2 = R[i] * R[i] - dy * dy - dz * dz;
        if (!(h2 >= 0.0)) return false; // the four spheres do not meet
        xs += std::sqrt(h2);
    }
    const double xe = xs / 4.0;
    if (!std::isfinite(xe) || !std::isfinite(ye) || !std::isfinite(ze)) return false;
    p[0] = xe;
    p[1] = ye;
    p[2] = ze;
    return true;
}

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

} // namespace cdm
