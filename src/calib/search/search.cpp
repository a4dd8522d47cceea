// See search.h.
#include "calib/search/search.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "model/effect.h"

namespace cdm {
namespace diag {

namespace {

// A search step fits in full the candidates its screen puts first (by the
// BIC change of one Gauss-Newton step), this many at a time, until the best
// addition is one fitted in full (model_search).
constexpr size_t kFullFits = 3;

std::vector<std::string> sorted(std::vector<std::string> v) {
    std::sort(v.begin(), v.end());
    return v;
}

double x_rms(const Eval &E) {
    return E.err[0].n > 0 ? std::sqrt(E.err[0].ss / E.err[0].n) : 0.0;
}

// A swap whose bound (swap_bound) is this far above the model it leaves is
// fitted neither by the search (which needs it below -2) nor for the
// alternatives (which list models within 10 of the recommended): 10 and a
// margin of 5 for what the bound leaves out (the fits' weak prior; the
// recommended model's BIC under its own weights after a swap moved).
constexpr double kSwapBoundSkip = 15;

// A one-effect swap must lower the criterion by more than this: below 2 the
// evidence is "not worth more than a bare mention" (Kass and Raftery), and
// between inseparable equivalents (anchor_position and holder_geometry for a
// holder that only translates) the fits' round-off alone decided (seen: BIC
// -0.0, a whole step more). Such a model is listed among the alternatives
// instead.
constexpr double kSwapGain = 2;

// cur refitted once under its own weights. It was fitted under those of
// the model before it (the step that added it was weighed as that one),
// and the next step's fits, each under cur's weights from cur's values,
// would otherwise gain that refit as if it were theirs: a ripple whose
// period is near the span reads chi-square 3383.2 as fitted and 3346.6
// refitted, and exit_pulley, which the data do not hold, would then read
// delta chi2 38 and be added (with the readings weighed as blocks, whose
// weights follow the model closer).
// Kept when it lowers cur's own chi-square. cur_E is cur's evaluation
// afterwards (`evaluated`: it already is, and is kept when the refit
// moves nothing).
bool refit_own(const DiagContext &ctx, Model &cur, double &cur_chi2, Eval &cur_E, const std::string &stage,
               bool evaluated, std::string &err) {
    const Model w = cur;
    DiagContext pc = ctx;
    pc.fo.weigh_with = &w;
    pc.fo.statistics = false; // (kept or not by its chi-square; cur_rep stays the fit that chose cur)
    Model c2 = cur;
    FitReport r2;
    if (!pc.fit(c2, stage, r2)) {
        err = r2.message.empty() ? "fit cancelled" : r2.message;
        return false;
    }
    const double c2_chi2 = model_chi2(c2, ctx.pos, ctx.fo);
    if (c2_chi2 < cur_chi2) {
        cur = std::move(c2);
        cur_chi2 = c2_chi2;
        evaluated = false;
    }
    if (!evaluated) cur_E = evaluate_cached(ctx, cur, ctx.threads);
    return true;
}

// A step's best move of one kind: its BIC change d (the best found must be
// below the start value), the effect it removes (in_out for a removal) or
// adds (in_out for a swap, out_name the one it removes), the model fitted.
struct Move {
    Move(const DeviceGeometry &g, double d0) : d(d0), m(g) {}
    double d;
    std::string in_out, out_name;
    Model m;
    FitReport rep;
};

// The best removal from cur (the sets already stood on left out); every
// set fitted goes to out.visited.
bool best_removal(const DiagContext &ctx, const DiagContext &sc, const Model &cur, double cur_chi2, int cur_free,
                  const std::vector<std::string> &names, const std::set<std::vector<std::string>> &seen, int step,
                  SearchResult &out, Move &rm, std::string &err) {
    std::vector<FitJob> jobs;
    std::vector<std::vector<std::string>> keeps;
    std::vector<size_t> which;
    for (size_t k = 0; k < names.size(); ++k) {
        std::vector<std::string> keep = names;
        keep.erase(keep.begin() + long(k));
        if (seen.count(sorted(keep))) continue;
        jobs.emplace_back(model_with(cur, keep, ""), "search step " + std::to_string(step) + " without " + names[k]);
        keeps.push_back(keep);
        which.push_back(k);
    }
    if (!fit_all(sc, jobs, err)) return false;
    for (size_t q = 0; q < jobs.size(); ++q) {
        const FitReport &r = jobs[q].rep;
        const double d = ctx.bic(r.chi2, r.n_free) - ctx.bic(cur_chi2, cur_free);
        out.visited.push_back({keeps[q], ctx.bic(r.chi2, r.n_free)});
        if (d < rm.d) {
            rm.d = d;
            rm.in_out = names[which[q]];
            rm.m = jobs[q].m;
            rm.rep = r;
        }
    }
    return true;
}

// The candidates by their tests alone (what a step chooses by); the rest of
// the table only for the candidates on top of where the search stops.
// Every candidate is first screened by one Gauss-Newton step from its start
// (a seeded period: its held starts, one step each; the ripple's joint fits
// of the period, half of the search's fitting on data without a ripple when
// every step runs them, run only for a full fit; `python3
// scripts/progress_times.py build/src/cli/cdm calib diagnose X.csv` times
// each step). The best few by the screen that the step could take are
// fitted in full, more while a screened one still ranks first, and the step
// moves by full fits. Where the screen finds no move every candidate is
// fitted in full and the step decided again: the step the search stops on,
// whose candidates are the table shown, is always decided on full fits, so
// where the search stops no addition, removal or swap lowers the criterion
// by the full fits, as without the screen. The screen's one step is an
// estimate, not a bound (a full fit damps a step that gains less than it
// promised): a candidate whose full fit would have won a step may rank below
// the few fitted in full, and the search then takes another path.
// add: the best addition (null: none); removes: the step has a removal.
bool choose_addition(const DiagContext &sc, const Model &cur, int cur_free, double cur_chi2, const Eval &cur_E,
                     const std::string &stage, const std::set<std::vector<std::string>> &seen, bool removes,
                     const std::function<bool(const Eval &)> &restarts, std::vector<Candidate> &cands,
                     const Candidate *&add, SearchResult &out, std::string &err) {
    auto pick_add = [&]() -> const Candidate * {
        // Best addition: lowers the BIC and passes the likelihood-ratio test.
        for (auto &c : cands)
            if (c.bic < 0 && c.significant() && !seen.count(sorted(reading_effects(c.m))))
                return &c; // sorted by BIC
        return nullptr;
    };
    std::vector<std::string> in_full;
    for (;;) { // (the fits done before are the fit cache's)
        if (!score_candidates(sc, cur, cur_free, cur_chi2, cur_E, stage, cands, err, false, true, in_full))
            return false;
        add = pick_add();
        if (add && !add->screened) return true;
        if (!add && removes) return true; // the step removes
        if (!add && restarts && restarts(cur_E)) { // searched again from here: no full fits
            out.provisional = true;
            return true;
        }
        if (!add) { // nothing moves by the screen: every candidate in full
            if (!score_candidates(sc, cur, cur_free, cur_chi2, cur_E, stage, cands, err, false, false))
                return false;
            add = pick_add();
            return true;
        }
        // The best few by the screen in full.
        size_t more = 0;
        for (auto &c : cands) // (by the screen's BIC: a set already stood on cannot be the move)
            if (c.screened && c.bic < 0 && more < kFullFits && !seen.count(sorted(reading_effects(c.m)))) {
                in_full.push_back(c.name);
                ++more;
            }
    }
}

// The best one-effect swap of cur's effects for a catalogued one (those
// whose bound says they cannot gain enough, and the sets already stood on,
// left out); every set fitted and shown goes to out.visited.
bool best_swap(const DiagContext &ctx, const DiagContext &sc, const Model &cur, double cur_chi2, int cur_free,
               const std::vector<std::string> &names, const std::set<std::vector<std::string>> &seen,
               const std::vector<Candidate> &cands, int step, SearchResult &out, Move &sw, std::string &err) {
    // The starts depend on cur and the effect only, not on what
    // is swapped out: found once, for the swaps fitted.
    const auto cands_all = candidate_effects();
    std::vector<std::vector<ParamValues>> starts(cands_all.size());
    std::vector<char> have_start(cands_all.size(), 0);
    std::vector<FitJob> jobs;
    struct Swap {
        size_t k;
        std::string in;
        std::vector<std::string> set;
    };
    std::vector<Swap> swaps;
    for (size_t k = 0; k < names.size(); ++k)
        for (size_t i = 0; i < cands_all.size(); ++i) {
            const auto &d = cands_all[i];
            if (cur.has_effect(d->name)) continue;
            std::vector<std::string> keep = names;
            keep.erase(keep.begin() + long(k));
            auto s2 = keep;
            s2.push_back(d->name);
            if (seen.count(sorted(s2))) continue;
            if (swap_bound(ctx, cur, names[k], d->name, cands) >= kSwapBoundSkip) continue;
            if (!have_start[i]) {
                starts[i] = effect_starts(cur, d->name, ctx.pos);
                have_start[i] = 1;
            }
            FitJob j = start_job(cur, keep, d->name, starts[i], "search step " + std::to_string(step) + " swaps");
            if (!j.m.has_effect(d->name)) continue; // it could not be added: no swap
            jobs.push_back(std::move(j));
            swaps.push_back({k, d->name, s2});
        }
    if (!fit_all(sc, jobs, err)) return false;
    for (size_t q = 0; q < jobs.size(); ++q) {
        const FitReport &r = jobs[q].rep;
        if (!fit_shown(jobs[q].m, jobs[q].rep, swaps[q].in, ctx.pos)) continue;
        const double dd = ctx.bic(r.chi2, r.n_free) - ctx.bic(cur_chi2, cur_free);
        out.visited.push_back({swaps[q].set, ctx.bic(r.chi2, r.n_free)});
        if (dd < sw.d) {
            sw.d = dd;
            sw.out_name = names[swaps[q].k];
            sw.in_out = swaps[q].in;
            sw.m = jobs[q].m;
            sw.rep = r;
        }
    }
    return true;
}

} // namespace

bool model_search(const DiagContext &ctx, const Model &start, const FitReport &start_rep,
                  bool swaps, SearchResult &out, std::string &err,
                  const std::set<std::vector<std::string>> *seen_before,
                  const std::function<bool(const Eval &)> &restarts) {
    Model cur = model_with(start, reading_effects(start), "");
    int cur_free = start_rep.n_free;
    // The ellipsoid's three parameters are fitted in position space, not
    // in this chi-square.
    for (size_t k = 0; k < start.effect_count(); ++k)
        if (start.effect_desc(k).stage == Stage::Position) cur_free -= int(start.effect_desc(k).params.size());
    // Every chi-square a step compares is weighed as the model it stands
    // on weighs the data (the jig tolerance mapped through that model's
    // sensitivity to the position): a fit's weights otherwise come from its
    // own start, and an effect that changes that sensitivity (a gain, a
    // stretch) moves the chi-square by a percent or two, hundreds on a full
    // jig, with no better fit (it kept cable_stretch, which the data does
    // not need, beside cable_gain). cur_chi2 is cur's own.
    double cur_chi2 = model_chi2(cur, ctx.pos, ctx.fo);
    FitReport cur_rep = start_rep;
    cur_rep.n_free = cur_free;
    Eval cur_E = evaluate_cached(ctx, cur, ctx.threads);
    if (!refit_own(ctx, cur, cur_chi2, cur_E, "search (the start refitted under its own weights)", true, err))
        return false;
    std::set<std::vector<std::string>> seen{sorted(reading_effects(cur))};
    if (seen_before) seen.insert(seen_before->begin(), seen_before->end());
    out.visited.push_back({reading_effects(cur), ctx.bic(cur_chi2, cur_free)});
    // The search moves to model m, fitted as r (evaluated here: a step's
    // candidates are scored without their evaluations).
    auto move_to = [&](const Model &m, const FitReport &r, const std::string &stage) {
        cur = m;
        cur_rep = r;
        cur_free = r.n_free;
        cur_chi2 = model_chi2(cur, ctx.pos, ctx.fo);
        return refit_own(ctx, cur, cur_chi2, cur_E, stage, false, err);
    };
    std::vector<Candidate> cands;
    for (int step = 1; step <= 12; ++step) {
        DiagContext sc = ctx; // this step's fits, weighed as cur weighs
        sc.fo.weigh_with = &cur;
        const auto names = reading_effects(cur);
        // Best removal (it does not depend on the candidates).
        Move rm(ctx.g, 0);
        if (!best_removal(ctx, sc, cur, cur_chi2, cur_free, names, seen, step, out, rm, err)) return false;
        // The best addition, by the screen and then full fits (choose_addition).
        const Candidate *add = nullptr;
        if (!choose_addition(sc, cur, cur_free, cur_chi2, cur_E, "search step " + std::to_string(step), seen,
                             !rm.in_out.empty(), restarts, cands, add, out, err))
            return false;
        for (auto &c : cands) {
            if (c.screened) continue; // an estimate, not the model's criterion
            auto s = reading_effects(c.m);
            if (std::none_of(out.visited.begin(), out.visited.end(), [&](auto &v) { return sorted(v.first) == sorted(s); }))
                out.visited.push_back({s, ctx.bic(c.rep.chi2, c.rep.n_free)});
        }
        if (out.provisional) break;
        SearchStep st;
        st.step = step;
        if (add && add->bic <= rm.d) {
            st.added = add->name;
            st.bic_change = add->bic;
            if (!move_to(add->m, add->rep, "search step " + std::to_string(step) + " (refitted)")) return false;
        } else if (!rm.in_out.empty()) {
            st.removed = rm.in_out;
            st.bic_change = rm.d;
            if (!move_to(rm.m, rm.rep, "search step " + std::to_string(step) + " (refitted)")) return false;
        } else if (!swaps) {
            break; // cands are the candidates on top of cur
        } else {
            // Stuck on additions and removals: a one-effect swap can still
            // lower the criterion (greedy forward steps can take a flexible
            // effect that stands in for a specific one), by more than kSwapGain.
            Move sw(ctx.g, -kSwapGain);
            if (!best_swap(ctx, sc, cur, cur_chi2, cur_free, names, seen, cands, step, out, sw, err)) return false;
            if (sw.in_out.empty()) break; // no move lowers the criterion: cands are the candidates on top of cur
            st.added = sw.in_out;
            st.removed = sw.out_name;
            st.bic_change = sw.d;
            if (!move_to(sw.m, sw.rep, "search step " + std::to_string(step) + " (refitted)")) return false;
        }
        st.x_rms_mm = x_rms(cur_E);
        seen.insert(sorted(reading_effects(cur)));
        out.path.push_back(st);
        cands.clear();
    }
    out.effects = reading_effects(cur);
    out.model = cur;
    out.rep = cur_rep;
    out.rep.n_free = cur_free;
    out.chi2 = cur_chi2;
    out.bic = ctx.bic(cur_chi2, cur_free);
    out.E = std::move(cur_E);
    out.cands = std::move(cands);
    out.seen = std::move(seen);
    return true;
}

bool search_alternatives(const DiagContext &ctx, const SearchResult &r,
                         std::vector<std::pair<std::vector<std::string>, double>> &alts, std::string &err) {
    alts.clear();
    const auto rec = sorted(r.effects);
    std::set<std::vector<std::string>> listed{rec};
    auto superset = [&](const std::vector<std::string> &s) {
        return std::includes(s.begin(), s.end(), rec.begin(), rec.end());
    };
    for (auto &v : r.visited) {
        auto s = sorted(v.first);
        if (listed.count(s) || superset(s) || v.second - r.bic >= 10) continue;
        listed.insert(s);
        alts.push_back({v.first, v.second - r.bic});
    }
    // One-effect swaps, fitted as one batch.
    std::vector<FitJob> jobs;
    struct Alt {
        std::vector<std::string> set, key;
        size_t first, last;
    };
    std::vector<Alt> todo;
    for (const auto &out_name : r.effects)
        for (auto &d : candidate_effects()) {
            if (r.model.has_effect(d->name)) continue;
            std::vector<std::string> keep;
            for (auto &e : r.effects)
                if (e != out_name) keep.push_back(e);
            auto s = keep;
            s.push_back(d->name);
            s = sorted(s);
            if (listed.count(s)) continue;
            if (std::any_of(r.visited.begin(), r.visited.end(), [&](auto &v) { return sorted(v.first) == s; }))
                continue; // fitted by the search: judged above
            if (swap_bound(ctx, r.model, out_name, d->name, r.cands) >= kSwapBoundSkip)
                continue; // 10 above the recommended model and more: no alternative
            Alt a{keep, s, jobs.size(), 0};
            a.set.push_back(d->name);
            FitJob j = start_job(r.model, keep, d->name, effect_starts(r.model, d->name, ctx.pos), "alternatives");
            if (!j.m.has_effect(d->name)) continue; // it could not be added: no alternative
            jobs.push_back(std::move(j));
            a.last = jobs.size();
            todo.push_back(std::move(a));
        }
    DiagContext ac = ctx; // weighed as the recommended model weighs (r.bic: its own)
    ac.fo.weigh_with = &r.model;
    if (!fit_all(ac, jobs, err)) return false;
    for (auto &a : todo) {
        double best = INFINITY;
        const std::string &in = a.set.back();
        for (size_t q = a.first; q < a.last; ++q)
            if (fit_shown(jobs[q].m, jobs[q].rep, in, ctx.pos))
                best = std::min(best, ctx.bic(jobs[q].rep.chi2, jobs[q].rep.n_free) - r.bic);
        if (best < 10) {
            listed.insert(a.key);
            alts.push_back({a.set, best});
        }
    }
    std::sort(alts.begin(), alts.end(), [](auto &a, auto &b) { return a.second < b.second; });
    return true;
}

} // namespace diag
} // namespace cdm
