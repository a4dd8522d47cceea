// See fit.h: the sub-models a fit is compared with.
#include "calib/fit/fit.h"

#include <algorithm>

#include "model/effect.h"

namespace cdm {

std::vector<std::string> reading_effects(const Model &m) {
    std::vector<std::string> v;
    for (size_t k = 0; k < m.effect_count(); ++k)
        if (m.effect_desc(k).stage != Stage::Position) v.push_back(m.effect_name(k));
    return v;
}

Model model_with(const Model &from, const std::vector<std::string> &keep, const std::string &add,
                 const ParamValues &add_init) {
    Model m2{from.geometry()};
    std::string e2;
    for (size_t k = 0; k < from.effect_count(); ++k) {
        const EffectDesc &d = from.effect_desc(k);
        if (d.stage == Stage::Position) continue;
        if (std::find(keep.begin(), keep.end(), d.name) == keep.end()) continue;
        ParamValues pv;
        for (size_t q = 0; q < d.params.size(); ++q) pv.push_back({d.params[q].name, from.effect_params(k)[q]});
        m2.add_effect(d.name, pv, e2);
    }
    if (!add.empty()) m2.add_effect(add, add_init, e2);
    return m2;
}

} // namespace cdm
