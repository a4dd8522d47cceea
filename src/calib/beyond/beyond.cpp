// See beyond.h.
#include "calib/beyond/beyond.h"
#include "model/effect.h"

#include <algorithm>

#include "calib/evaluation/stats.h"

namespace cdm {
namespace diag {

namespace {

// The recommended model is beaten by a term outside the catalogue when the
// user's model plus that term has a BIC lower by more than this: very
// strong evidence on Kass and Raftery's scale, the margin the search's
// alternatives use. (A term that is a catalogued effect's special case
// saves at most its spare parameters' ln n each, 9.4 per parameter on the
// seed's jig: one spare parameter does not reach it.)
constexpr double kBeatenBic = 10.0;
// ... unless the terms are a special case of the recommended model's own
// effects (a drift common to the four cables is pot_drift's; a common scale
// is cable_stretch's): its Jacobian makes all but this share of them. Such
// an effect is the right physics with parameters to spare, not a stand-in.
// A special case leaves round-off and the readings' noise (2e-9 for a
// drift common to the cables under pot_drift; 1e-29 or less for L^2 under
// cable_stretch and for the sag's term under a user effect of the same
// shape); a stand-in mimics a term to within the noise, not exactly, and
// leaves 5e-5 to 1e-2 of it (the hidden effects of
// tests/cli/test_beyond_catalogue.py on the seed's jig and a half jig: the
// discovery's share_outside_compared). The bound sits between, a factor of
// 50 from the nearest of each.
constexpr double kContainedShare = 1e-6;

// The effects of `target` that `base` lacks, as stand-ins for the
// discovered term that beat them.
void beaten_stand_ins(const Model &target, const Model &base, const Discovery &d, std::vector<StandIn> &out) {
    const std::vector<std::string> have = reading_effects(base);
    std::string terms;
    for (size_t k = 0; k < d.terms.size(); ++k) terms += (k ? " + " : "") + d.terms[k];
    for (auto &e : reading_effects(target)) {
        if (std::find(have.begin(), have.end(), e) != have.end()) continue;
        out.push_back({e, "beaten",
                       e + " is beaten by a term outside the catalogue (" + terms + ", fitted with " +
                           (have.empty() ? std::string("the nominal model") : "the user's model") + ": BIC " +
                           fmt_num(d.bic_vs_other, 0, true) + " against the recommended model): it stands in for it",
                       {{"terms", d.terms}, {"bic_change", d.bic_vs_other},
                        {"test", "BIC of the user's model plus the discovered terms against the recommended model, "
                                 "lower by more than 10"}}});
    }
}

} // namespace

bool beyond_catalogue(const DiagContext &ctx, const Model &user, const FitReport &user_rep, const Model &target,
                      const FitReport &target_rep, const Eval &target_E, bool target_explained,
                      const nlohmann::json &jig_report, const V3 &noise, Beyond &out, std::string &err) {
    out.user = find_stand_ins(user, user_rep);
    out.recommended = find_stand_ins(target, target_rep);
    const std::vector<StandIn> &si = out.recommended;
    // Which residual to search, and what to compare the term with:
    //  - stand-ins named: the model without them (refitted), against it;
    //  - the model leaves structure: its own residual;
    //  - it explains the data: the user's model's residual, against it, so
    //    that generic effects doing a simple term's work are caught by the
    //    BIC (a 12-parameter geometry standing in for one term);
    //  - it is the user's model and explains the data: nothing to look for.
    const bool differs = reading_effects(user) != reading_effects(target);
    if (si.empty() && target_explained && !differs) {
        out.attribution = jig_attribution(target_E, nullptr, "", ctx.G, ctx.jig, noise, jig_report);
        return true;
    }
    ctx.report("beyond the catalogue", 0.0);
    Model base = target;
    FitReport base_rep = target_rep;
    const bool compare = !si.empty() || target_explained;
    if (!si.empty()) {
        const std::vector<std::string> drop = stand_in_effects(si);
        std::vector<std::string> keep;
        for (auto &e : reading_effects(target))
            if (std::find(drop.begin(), drop.end(), e) == drop.end()) keep.push_back(e);
        base = model_with(target, keep, "");
        if (!ctx.fit(base, "beyond the catalogue", base_rep)) {
            err = base_rep.message.empty() ? "fit cancelled" : base_rep.message;
            return false;
        }
    } else if (target_explained) {
        base = model_with(user, reading_effects(user), "");
        base_rep = user_rep;
    }
    const std::string other_name = !si.empty() ? "the stand-ins" : "the recommended model";
    if (!discover_terms(ctx, base, base_rep, compare ? &target : nullptr, compare ? &target_rep : nullptr, other_name,
                        out.discovery, err))
        return false;
    if (si.empty() && target_explained && out.discovery.found && out.discovery.bic_vs_other < -kBeatenBic &&
        out.discovery.outside_other > kContainedShare)
        beaten_stand_ins(target, base, out.discovery, out.recommended);
    out.attribution = jig_attribution(target_E, out.discovery.competitive() ? &out.discovery.E : nullptr,
                                      "the discovered term", ctx.G, ctx.jig, noise, jig_report);
    return true;
}

} // namespace diag
} // namespace cdm
