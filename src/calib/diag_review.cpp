// See diag_review.h.
#include "calib/diag_review.h"

#include "calib/diag_candidates.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

using nlohmann::json;

bool review_model(const DiagContext &ctx, const Model &model, int n_free, double chi2, json &out, std::string &err) {
    out = json::array();
    const double bic_cur = ctx.bic(chi2, n_free);
    const auto names = reading_effects(model);
    for (const std::string &name : names) {
        std::vector<std::string> keep;
        for (auto &e : names)
            if (e != name) keep.push_back(e);
        Model without = model_with(model, keep, "");
        FitReport rw;
        if (!ctx.fit(without, "reviewing " + name, rw)) {
            err = rw.message.empty() ? "fit cancelled" : rw.message;
            return false;
        }
        const double d_rm = ctx.bic(rw.chi2, rw.n_free) - bic_cur;
        json item = {{"effect", name}, {"bic_change_if_removed", d_rm}, {"redundant", d_rm < 10}};
        double best = 0;
        std::string best_name;
        // Every catalogued effect not in the model (not only the ranked
        // candidates: one that adds no free parameter to the model, like
        // the jig transform beside the anchors, can still replace one).
        for (auto &cd : candidate_effects()) {
            if (model.has_effect(cd->name)) continue;
            std::vector<FitJob> job;
            job.push_back(start_job(model, keep, cd->name, effect_starts(model, cd->name, ctx.pos),
                                    "reviewing " + name));
            if (!job[0].m.has_effect(cd->name)) continue; // it could not be added: no swap
            if (!fit_all(ctx, job, err)) return false;
            const double d = ctx.bic(job[0].rep.chi2, job[0].rep.n_free) - bic_cur;
            if (period_shown(job[0].m, cd->name, ctx.pos) && d < best) {
                best = d;
                best_name = cd->name;
            }
        }
        // Removing it outright is the simpler fix when it is as good: a
        // swap is offered only when it beats the removal by 10 as well.
        if (best < -10 && best < d_rm - 10) item["better_swap"] = {{"effect", best_name}, {"bic_change", best}};
        out.push_back(item);
    }
    return true;
}

} // namespace diag
} // namespace cdm
