// See diag_validation.h.
#include "calib/diag_validation.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {
json rms3(const Acc a[3]) {
    return {{"x", a[0].to_json()["rms"]}, {"y", a[1].to_json()["rms"]}, {"z", a[2].to_json()["rms"]}};
}
} // namespace

bool validate_heights(const DiagContext &ctx, const Model &model, const Eval &in_sample, json &out, std::string &err) {
    out = nullptr;
    const size_t P = ctx.pos.size();
    const auto &heights = ctx.data.heights;
    if (!ctx.G.layered || heights.size() <= 1 || heights.size() > 20) return true;
    Acc held[3];
    json folds = json::array();
    for (size_t h = 0; h < heights.size(); ++h) {
        Model mv = model;
        DiagContext c2 = ctx;
        c2.fo.use.assign(P, 0);
        for (size_t j = 0; j < P; ++j) c2.fo.use[j] = ctx.G.height_index[j] != int(h);
        FitReport rv;
        if (!c2.fit(mv, "validation", rv)) {
            err = rv.message.empty() ? "fit cancelled" : rv.message;
            return false;
        }
        Eval ev = evaluate(mv, ctx.pos);
        Acc f[3];
        for (size_t j = 0; j < P; ++j)
            if (!c2.fo.use[j] && ev.ok[j])
                for (int a = 0; a < 3; ++a) {
                    f[a].add(ev.res[j](a));
                    held[a].add(ev.res[j](a));
                }
        folds.push_back({{"height", heights[h]}, {"rms_mm", rms3(f)}});
    }
    Acc ins[3];
    for (size_t j = 0; j < P; ++j)
        if (in_sample.ok[j])
            for (int a = 0; a < 3; ++a) ins[a].add(in_sample.res[j](a));
    out = {{"method", "leave-one-height-out"}, {"folds", folds}, {"rms_mm", rms3(held)}, {"in_sample_rms_mm", rms3(ins)}};
    return true;
}

} // namespace diag
} // namespace cdm
