// See review.h.
#include "calib/search/review.h"

#include <string>
#include <vector>

#include "calib/search/candidates.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

using nlohmann::json;

bool review_model(const DiagContext &ctx, const Model &model, int n_free, double chi2, json &out, std::string &err,
                  const std::vector<Candidate> *cands_fitted) {
    out = json::array();
    const double bic_cur = ctx.bic(chi2, n_free);
    const auto names = reading_effects(model);
    // Each effect's removal, and its swap for every catalogued effect not
    // in the model (not only the ranked candidates: one that adds no free
    // parameter to the model, like the jig transform beside the anchors,
    // can still replace one): independent fits, fitted as one batch on
    // ctx.threads threads, then read in the model's and the catalogue's
    // order (fit_all: nothing depends on the threads).
    struct Swap {
        size_t job;
        std::string name;
    };
    // A swap's start depends on the model and the effect only (a period
    // from the model's residual): once per effect, not once per removal.
    const auto cands = candidate_effects();
    std::vector<std::vector<ParamValues>> starts(cands.size());
    std::vector<char> have_start(cands.size(), 0);
    std::vector<FitJob> jobs;
    std::vector<size_t> removal(names.size());
    std::vector<std::vector<Swap>> swaps(names.size());
    for (size_t i = 0; i < names.size(); ++i) {
        const std::string &name = names[i];
        std::vector<std::string> keep;
        for (auto &e : names)
            if (e != name) keep.push_back(e);
        removal[i] = jobs.size();
        jobs.emplace_back(model_with(model, keep, ""), "reviewing " + name);
        for (size_t c = 0; c < cands.size(); ++c) {
            const std::string &cn = cands[c]->name;
            if (model.has_effect(cn)) continue;
            // (better_swap needs a change below -10; 5 of margin, as the search's)
            if (cands_fitted && swap_bound(ctx, model, name, cn, *cands_fitted) >= -5) continue;
            if (!have_start[c]) {
                starts[c] = effect_starts(model, cn, ctx.pos);
                have_start[c] = 1;
            }
            FitJob j = start_job(model, keep, cn, starts[c], "reviewing " + name);
            if (!j.m.has_effect(cn)) continue; // it could not be added: no swap
            swaps[i].push_back({jobs.size(), cn});
            jobs.push_back(std::move(j));
        }
    }
    if (!fit_all(ctx, jobs, err)) return false;
    for (size_t i = 0; i < names.size(); ++i) {
        const FitReport &rw = jobs[removal[i]].rep;
        const double d_rm = ctx.bic(rw.chi2, rw.n_free) - bic_cur;
        json item = {{"effect", names[i]}, {"bic_change_if_removed", d_rm}, {"redundant", d_rm < 10}};
        double best = 0;
        std::string best_name;
        for (const Swap &sw : swaps[i]) {
            const FitJob &j = jobs[sw.job];
            const double d = ctx.bic(j.rep.chi2, j.rep.n_free) - bic_cur;
            if (fit_shown(j.m, j.rep, sw.name, ctx.pos) && d < best) {
                best = d;
                best_name = sw.name;
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
