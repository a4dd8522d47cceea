// See diagnose_json.h.
#include "calib/diagnosis/diagnose_json.h"

#include <algorithm>
#include <cmath>

#include "calib/evaluation/stats.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

using nlohmann::json;

nlohmann::json vec3(const V3 &v) { return json::array({v(0), v(1), v(2)}); }

std::string join(const std::vector<std::string> &v, const char *sep, const std::string &none) {
    if (v.empty()) return none;
    std::string s;
    for (size_t k = 0; k < v.size(); ++k) s += (k ? sep : "") + v[k];
    return s;
}

nlohmann::json params_json(const Model &model, const FitReport &rep) {
    json params = json::object();
    for (size_t k = 0; k < model.effect_count(); ++k) {
        const EffectDesc &d = model.effect_desc(k);
        const auto &pv = model.effect_params(k);
        json pj = json::object();
        for (size_t q = 0; q < pv.size(); ++q) {
            double sd = (k < rep.std.size() && q < rep.std[k].size()) ? rep.std[k][q] : 0.0;
            pj[d.params[q].name] = {{"value", pv[q]}, {"std", sd}, {"unit", d.params[q].unit}};
        }
        params[model.effect_name(k)] = pj;
    }
    return params;
}

std::string effect_advice(const Model &m, const FitReport &rep, const std::vector<PreparedPos> &pos) {
    std::string s;
    for (size_t k = 0; k < m.effect_count(); ++k) {
        const EffectDesc &d = m.effect_desc(k);
        const auto &p = m.effect_params(k);
        if (d.name == "pot_drift") {
            double tmin = INFINITY, tmax = -INFINITY;
            for (auto &pp : pos) {
                tmin = std::min(tmin, pp.t_s);
                tmax = std::max(tmax, pp.t_s);
            }
            const double h0 = tmin / 3600, h1 = tmax / 3600;
            double worst = 0;
            for (int c = 0; c < 4; ++c)
                worst = std::max(worst, std::fabs(p[size_t(c)] * (h1 - h0) + p[4] * (h1 * h1 - h0 * h0)));
            s += " The readings drift by up to " + fmt_num(worst, 3) +
                 " mm over the session: warm the device up before measuring, or re-measure a reference hole at "
                 "intervals.";
        } else if (d.name == "drum_eccentricity") {
            const double sd = (k < rep.std.size() && !rep.std[k].empty()) ? rep.std[k][0] : 0.0;
            s += " The drums ripple with a period of " + fmt_num(p[0], 2) + " +- " + fmt_num(sd, 2) +
                 " mm of cable (one turn).";
        }
    }
    return s;
}

} // namespace diag
} // namespace cdm
