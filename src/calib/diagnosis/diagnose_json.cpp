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
    double tmin = INFINITY, tmax = -INFINITY;
    for (auto &pp : pos) {
        tmin = std::min(tmin, pp.t_s);
        tmax = std::max(tmax, pp.t_s);
    }
    std::string s;
    for (size_t k = 0; k < m.effect_count(); ++k) {
        const EffectDesc &d = m.effect_desc(k);
        if (!d.advice) continue;
        static const std::vector<double> none;
        s += d.advice(AdviceIn{m.effect_params(k), k < rep.std.size() ? rep.std[k] : none, tmin / 3600, tmax / 3600});
    }
    return s;
}

} // namespace diag
} // namespace cdm
