// See candidates.h.
#include "calib/search/candidates.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <functional>
#include <thread>

#include "calib/evaluation/findings.h"
#include "calib/evaluation/stats.h"
#include "model/effect.h"
#include "model/evaluator.h"

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {
std::string fmt(double v, int prec = 3) {
    char b[64];
    std::snprintf(b, sizeof b, "%.*f", prec, v);
    return b;
}
} // namespace

FitJob start_job(const Model &from, const std::vector<std::string> &keep, const std::string &add,
                 const std::vector<ParamValues> &starts, std::string stage) {
    FitJob j(model_with(from, keep, add, starts.empty() ? ParamValues{} : starts.front()), std::move(stage));
    if (starts.size() > 1 && j.m.has_effect(add)) {
        j.seeded = add;
        for (size_t k = 1; k < starts.size(); ++k) {
            Model m = model_with(from, keep, add, starts[k]);
            if (!m.has_effect(add)) continue;
            j.more_starts.push_back(std::move(m));
        }
    }
    return j;
}

std::vector<ParamValues> effect_starts(const Model &base, const std::string &effect,
                                       const std::vector<PreparedPos> &pos) {
    auto d = find_effect(effect);
    if (!d) return {{}};
    for (auto &p : d->params) {
        if (p.role != ParamRole::LengthPeriod) continue;
        const PeriodPeak pk = length_period(length_view(base, pos));
        if (!pk.valid) return {{}};
        std::vector<ParamValues> v;
        for (double f : {1.0, 0.9, 1.1}) {
            const double per = std::min(std::max(pk.period_mm * f, p.lower), p.upper);
            v.push_back({{p.name, per}});
        }
        return v;
    }
    return {{}};
}

double length_span(const std::vector<PreparedPos> &pos) {
    double lo = INFINITY, hi = -INFINITY;
    for (auto &pp : pos)
        for (int c = 0; c < 4; ++c) {
            lo = std::min(lo, pp.mean(c));
            hi = std::max(hi, pp.mean(c));
        }
    return hi - lo;
}

bool period_shown(const Model &m, const std::string &effect, const std::vector<PreparedPos> &pos) {
    for (size_t k = 0; k < m.effect_count(); ++k) {
        if (m.effect_name(k) != effect) continue;
        const EffectDesc &d = m.effect_desc(k);
        for (size_t q = 0; q < d.params.size(); ++q) {
            if (d.params[q].role != ParamRole::LengthPeriod) continue;
            // One full period at least within the measured lengths, as the
            // periodogram searches (periods up to the span).
            return m.effect_params(k)[q] <= length_span(pos);
        }
    }
    return true;
}

// The independent periods searched for a candidate whose period starts from
// the periodogram (effect_starts), as length_period counts them; 1 otherwise.
static double searched_periods(const std::string &effect, const std::vector<PreparedPos> &pos) {
    auto d = find_effect(effect);
    if (!d) return 1;
    for (auto &p : d->params)
        if (p.role == ParamRole::LengthPeriod) return std::max(1.0, periods_searched(length_span(pos)));
    return 1;
}

// A candidate contains the model it extends (its effect at the neutral
// start), so its chi-square cannot honestly end above base_chi2. (A
// profile of the fixture offsets that leaves the fit's own constraints
// on them puts base_chi2 below any fit's reach, and rows then read down
// to delta chi2 -629485: calib/fit/problem.h, profile_fixture, keeps to them.)
// A fit that still ends
// above its base, in another basin, is fitted again from that very
// start, the fixture offsets profiled as base_chi2's are, and the
// better of the two is kept. Below one unit of chi-square the
// difference is the base fit's own convergence and moves no test: not
// refitted.
static bool refit_above_base(const DiagContext &ctx, const Model &base, double base_chi2,
                             const std::vector<EffectDescPtr> &list,
                             const std::vector<std::pair<size_t, size_t>> &span, std::vector<FitJob> &jobs,
                             std::string &err) {
    std::vector<FitJob> again;
    std::vector<size_t> of;
    std::vector<std::string> list_of;
    for (size_t i = 0; i < list.size(); ++i)
        for (size_t q = span[i].first; q < span[i].second; ++q)
            if (jobs[q].ok && !jobs[q].one_step && jobs[q].rep.chi2 > base_chi2 + 1) {
                again.push_back(start_job(base, reading_effects(base), list[i]->name,
                                          effect_starts(base, list[i]->name, ctx.pos), jobs[q].stage + " again"));
                of.push_back(q);
                list_of.push_back(list[i]->name);
            }
    if (!again.empty()) {
        DiagContext pc = ctx;
        pc.fo.profile_fixture_start = true;
        if (!fit_all(pc, again, err)) return false;
        for (size_t a = 0; a < again.size(); ++a)
            // (A period the first fit showed is not traded for one the
            // data do not show: that candidate would drop from the table.)
            if (again[a].ok && again[a].rep.chi2 < jobs[of[a]].rep.chi2 &&
                (fit_shown(again[a].m, again[a].rep, list_of[a], ctx.pos) ||
                 !fit_shown(jobs[of[a]].m, jobs[of[a]].rep, list_of[a], ctx.pos)))
                jobs[of[a]] = std::move(again[a]);
    }
    return true;
}

bool score_candidates(const DiagContext &ctx, const Model &base, int base_free, double base_chi2,
                      const Eval &base_eval, const std::string &stage, std::vector<Candidate> &out,
                      std::string &err, bool details, bool screen, const std::vector<std::string> &in_full) {
    out.clear();
    auto list = candidate_effects();
    // Every candidate from every start, fitted as one batch (independent
    // fits: on ctx.threads threads); then judged in the catalogue's order.
    std::vector<FitJob> jobs;
    std::vector<std::pair<size_t, size_t>> span(list.size(), {0, 0}); // jobs of list[i]
    for (size_t i = 0; i < list.size(); ++i) {
        const auto &d = list[i];
        span[i].first = jobs.size();
        if (!base.has_effect(d->name)) {
            FitJob j = start_job(base, reading_effects(base), d->name, effect_starts(base, d->name, ctx.pos),
                                 stage + " " + d->name);
            j.one_step = screen && std::find(in_full.begin(), in_full.end(), d->name) == in_full.end();
            if (j.m.has_effect(d->name)) jobs.push_back(std::move(j));
        }
        span[i].second = jobs.size();
    }
    if (!fit_all(ctx, jobs, err)) return false;
    if (!refit_above_base(ctx, base, base_chi2, list, span, jobs, err)) return false;
    // Each candidate's best start and its tests, in the catalogue's order;
    // with details, complete_candidates then adds what it overlaps in the
    // model, its position errors and its verdict (in the BIC order the
    // table is sorted in).
    std::vector<Candidate> picked;
    std::vector<size_t> picked_of(list.size(), SIZE_MAX);
    for (size_t i = 0; i < list.size(); ++i) {
        const auto &d = list[i];
        if (base.has_effect(d->name)) continue;
        Candidate c(base.geometry());
        c.name = d->name;
        // One job per candidate (a seeded period: its job chose the start).
        bool have = false;
        for (size_t q = span[i].first; q < span[i].second; ++q) {
            const Model &m = jobs[q].m;
            const FitReport &r = jobs[q].rep;
            if (!fit_shown(m, r, d->name, ctx.pos)) continue;
            if (!have || r.chi2 < c.rep.chi2) {
                c.m = m;
                c.rep = r;
                c.screened = jobs[q].one_step;
                have = true;
            }
        }
        if (!have) continue;
        c.k = c.rep.n_free - base_free;
        if (c.k <= 0) continue; // nothing left to fit after the gauge: indistinguishable from the model
        picked_of[i] = picked.size();
        picked.push_back(std::move(c));
    }
    size_t done = 0;
    for (size_t i = 0; i < list.size(); ++i) {
        ++done;
        if (picked_of[i] == SIZE_MAX) continue;
        Candidate &c = picked[picked_of[i]];
        c.dchi2 = base_chi2 - c.rep.chi2;
        c.bic = -c.dchi2 + c.k * std::log(ctx.n_obs);
        c.p = chi2_sf(std::max(0.0, c.dchi2), c.k);
        // A period started from the periodogram's peak was chosen among the
        // periods the data could show: under no ripple the likelihood ratio
        // is the largest of about M independent chi-square(k - 1)'s (the
        // amplitudes and phases at each period), not a chi-square(k) (the
        // period is no parameter when the amplitudes are zero: Davies'
        // problem). On 20 clean half jigs without jig errors
        // drum_eccentricity's delta chi2 averaged 19 for its 9 parameters.
        // Its p is then the false-alarm probability over the M independent
        // periods the periodogram searches (span / 8 mm - 1), never below
        // the chi-square(k) one.
        if (const double M = searched_periods(c.name, ctx.pos); M > 1)
            c.p = std::max(c.p, false_alarm(chi2_sf(std::max(0.0, c.dchi2), std::max(1, c.k - 1)), M));
        out.push_back(std::move(c));
        if (!ctx.report(stage, double(done) / double(list.size()))) {
            err = "fit cancelled";
            return false;
        }
    }
    for (auto &c : out) c.p_adj = std::min(1.0, c.p * double(out.size()));
    std::sort(out.begin(), out.end(), [](const Candidate &a, const Candidate &b) { return a.bic < b.bic; });
    if (details) complete_candidates(ctx, base, base_eval, out);
    return true;
}

void complete_candidates(const DiagContext &ctx, const Model &base, const Eval &base_eval,
                         std::vector<Candidate> &cands) {
    const size_t P = ctx.pos.size();
    const size_t n_base = reading_effects(base).size();
    // In parallel (independent, each writes its own): what each overlaps in
    // the model and its evaluation; then the rest in turn.
    for_each_parallel(
        ctx, cands.size(), [&](size_t q) { return has_user_effect(cands[q].m); },
        [&](size_t q) {
            Candidate &c = cands[q];
            // What the model already does that this effect would: an effect
            // the model's own effects reproduce cannot be told from them.
            if (n_base > 0) {
                Overlap ov = effect_overlap(c.m, ctx.pos, ctx.fo, c.name);
                for (auto &pe : ov.per_effect)
                    if (pe.second > 0.99) c.in_model.push_back(pe.first);
                if (c.in_model.empty() && ov.all > 0.99)
                    for (auto &pe : ov.per_effect) c.in_model.push_back(pe.first);
            }
            c.E = evaluate_cached(ctx, c.m);
        });
    for (Candidate &c : cands) {
        {
            const V3 oj = ctx.own_jig(c.E);
            c.v = judge(c.E, ctx.G, oj, c.rep.n_free, ctx.own_hole(c.E, oj));
        }
        c.fp.resize(P);
        double sxy = 0, sxx = 0, syy = 0, ss = 0;
        size_t nn = 0;
        for (size_t j = 0; j < P; ++j) {
            c.fp[j] = base_eval.res[j] - c.E.res[j];
            if (!base_eval.ok[j] || !c.E.ok[j]) {
                c.fp[j].setZero();
                continue;
            }
            ss += c.fp[j].squaredNorm();
            ++nn;
            for (int a = 0; a < 3; ++a) {
                const double s2 = base_eval.var_mean[j](a) + ctx.jig(a) * ctx.jig(a);
                sxy += c.fp[j](a) * base_eval.res[j](a) / s2;
                sxx += c.fp[j](a) * c.fp[j](a) / s2;
                syy += base_eval.res[j](a) * base_eval.res[j](a) / s2;
            }
        }
        c.shift_rms_mm = nn ? std::sqrt(ss / double(nn)) : 0;
        c.corr = (sxx > 0 && syy > 0) ? sxy / std::sqrt(sxx * syy) : 0;
    }
}

double swap_bound(const DiagContext &ctx, const Model &base, const std::string &out, const std::string &in,
                  const std::vector<Candidate> &cands) {
    const Candidate *c = nullptr;
    for (const auto &x : cands)
        if (x.name == in && !x.screened) c = &x;
    if (!c) return -INFINITY;
    size_t p_out = 0;
    bool builtin = false;
    for (size_t k = 0; k < base.effect_count(); ++k)
        if (base.effect_desc(k).name == out) {
            p_out = base.effect_desc(k).params.size();
            builtin = base.effect_desc(k).stage != Stage::User;
        }
    // A user effect need not have an identity within its bounds.
    if (!builtin) return -INFINITY;
    // Nested only when no other effect's gauge depends on out (with the jig
    // transform fitted, the anchors' common rigid motion is fixed; with a
    // gain, the stretch's constant term): the same free directions for
    // every other effect with out and without it.
    std::vector<std::string> keep;
    for (const auto &e : reading_effects(c->m))
        if (e != out) keep.push_back(e);
    const Model without = model_with(c->m, keep, "");
    for (size_t k = 0; k < c->m.effect_count(); ++k) {
        const EffectDesc &d = c->m.effect_desc(k);
        if (d.name == out || d.stage == Stage::Position) continue;
        for (size_t w = 0; w < without.effect_count(); ++w)
            if (without.effect_desc(w).name == d.name &&
                effect_gauge_basis(c->m, k).cols() != effect_gauge_basis(without, w).cols())
                return -INFINITY;
    }
    return c->bic - double(p_out) * std::log(ctx.n_obs);
}

void mark_confusions(const Eval &base_eval, const V3 &jig, std::vector<Candidate> &cands) {
    const size_t P = base_eval.res.size();
    auto fp_corr = [&](const Candidate &a, const Candidate &b) {
        double sab = 0, saa = 0, sbb = 0;
        for (size_t j = 0; j < P; ++j)
            for (int k = 0; k < 3; ++k) {
                const double s2 = base_eval.var_mean[j](k) + jig(k) * jig(k);
                sab += a.fp[j](k) * b.fp[j](k) / s2;
                saa += a.fp[j](k) * a.fp[j](k) / s2;
                sbb += b.fp[j](k) * b.fp[j](k) / s2;
            }
        return (saa > 0 && sbb > 0) ? sab / std::sqrt(saa * sbb) : 0.0;
    };
    for (auto &c : cands) c.confused = c.in_model;
    for (size_t a = 0; a < cands.size(); ++a)
        for (size_t b = 0; b < cands.size(); ++b) {
            if (a == b || cands[a].bic >= 0 || cands[b].bic >= 0) continue;
            // Equally good (BIC within 10: "very strong" evidence on
            // Kass-Raftery's scale is needed to prefer one) and explaining
            // the same pattern.
            if (std::fabs(cands[a].bic - cands[b].bic) < 10 && fp_corr(cands[a], cands[b]) > 0.9)
                cands[a].confused.push_back(cands[b].name);
        }
}

json candidates_json(const std::vector<Candidate> &cands) {
    json cj = json::array();
    for (auto &c : cands)
        cj.push_back({{"effect", c.name},
                      {"score", -c.bic},
                      {"delta_chi2", c.dchi2},
                      {"bic_change", c.bic},
                      {"n_params", c.k},
                      {"lr_p_value", c.p},
                      {"lr_p_adjusted", c.p_adj},
                      {"significant", c.significant()},
                      {"position_change_rms_mm", c.shift_rms_mm},
                      {"error_mm_after", stats3(c.E.err)},
                      {"explained_after", c.v.explained},
                      {"chi2_per_dof_after", c.v.chi2 / c.v.dof},
                      {"structure_after", c.v.moran_z},
                      {"confused_with", c.confused},
                      {"residual_correlation", c.corr}});
    return cj;
}

json inseparable_json(const std::vector<Candidate> &cands) {
    json insep = json::array();
    std::vector<char> seen(cands.size(), 0);
    for (size_t a = 0; a < cands.size(); ++a) {
        if (seen[a] || cands[a].confused.empty()) continue;
        json grp = json::array({cands[a].name});
        seen[a] = 1;
        std::string sep;
        for (auto &nm : cands[a].confused) {
            grp.push_back(nm);
            bool is_cand = false;
            for (size_t b = 0; b < cands.size(); ++b) {
                if (cands[b].name != nm) continue;
                is_cand = true;
                seen[b] = 1;
                // probe heights and radii beyond the measured ones
                double best = -1, bh = 0, by = 0, bz = 0;
                for (double hx = 10; hx <= 110; hx += 10)
                    for (double yy = -90; yy <= 90; yy += 15)
                        for (double zz = -90; zz <= 90; zz += 15) {
                            double pa[3] = {hx, yy, zz}, ra[4], rb[4], ta[3], tb[3];
                            cands[a].m.jig_to_device(pa, ta);
                            cands[b].m.jig_to_device(pa, tb);
                            cands[a].m.readings(ta, ra);
                            cands[b].m.readings(tb, rb);
                            double dmax = 0;
                            for (int c = 0; c < 4; ++c) dmax = std::max(dmax, std::fabs(ra[c] - rb[c]));
                            if (dmax > best) {
                                best = dmax;
                                bh = hx;
                                by = yy;
                                bz = zz;
                            }
                        }
                sep += (sep.empty() ? "" : "; ") + cands[a].name + " vs " + nm;
                // 0.01 mm: a position mean of 100 samples at 0.05 mm noise.
                if (best < 0.01)
                    sep += ": they predict the same readings everywhere (at most " + fmt(best, 4) +
                           " mm apart out to x = 10..110, y, z = +-90 mm): no jig measurement separates them; "
                           "they are one effect as far as the cable lengths can tell, keep either";
                else
                    sep += ": their readings differ most (" + fmt(best) + " mm) at x = " + fmt(bh, 0) + ", y = " +
                           fmt(by, 0) + ", z = " + fmt(bz, 0) +
                           " mm; measure positions toward there (other heights, further out) to separate them";
            }
            if (!is_cand)
                sep += (sep.empty() ? "" : "; ") + nm + " (already in the model) reproduces what " + cands[a].name +
                       " would do: adding it changes nothing the data can see";
        }
        insep.push_back({{"effects", grp}, {"separate_by", sep}});
    }
    return insep;
}

} // namespace diag
} // namespace cdm
