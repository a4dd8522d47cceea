// See diag_beyond.h.
#include "calib/diag_beyond.h"
#include "model/effect.h"

#include <algorithm>

namespace cdm {
namespace diag {

bool beyond_catalogue(const DiagContext &ctx, const Model &user, const FitReport &user_rep, const Model &target,
                      const FitReport &target_rep, const Eval &target_E, bool target_explained,
                      const nlohmann::json &jig_report, const V3 &noise, Beyond &out, std::string &err) {
    out = Beyond{};
    out.user = find_stand_ins(user, user_rep);
    out.recommended = find_stand_ins(target, target_rep);
    const std::vector<StandIn> &si = out.recommended;
    // Nothing to look for past a model that explains the data with its
    // physics intact.
    if (!si.empty() || !target_explained) {
        ctx.report("beyond the catalogue", 0.0);
        // The residual the stand-ins were taking: the model without them,
        // refitted (a search without stand-ins: the model itself).
        const std::vector<std::string> drop = stand_in_effects(si);
        Model base = target;
        FitReport base_rep = target_rep;
        if (!si.empty()) {
            std::vector<std::string> keep;
            for (auto &e : reading_effects(target))
                if (std::find(drop.begin(), drop.end(), e) == drop.end()) keep.push_back(e);
            base = model_with(target, keep, "");
            if (!ctx.fit(base, "beyond the catalogue", base_rep)) {
                err = base_rep.message.empty() ? "fit cancelled" : base_rep.message;
                return false;
            }
        }
        if (!discover_terms(ctx, base, base_rep, si.empty() ? nullptr : &target, si.empty() ? nullptr : &target_rep,
                            out.discovery, err))
            return false;
    }
    out.attribution = jig_attribution(target_E, out.discovery.found ? &out.discovery.E : nullptr,
                                      "the discovered term", ctx.G, ctx.jig, noise, jig_report);
    return true;
}

} // namespace diag
} // namespace cdm
