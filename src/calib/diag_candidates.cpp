// See diag_candidates.h.
#include "calib/diag_candidates.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <functional>
#include <thread>

#include "calib/diag_findings.h"
#include "calib/diag_stats.h"
#include "model/effect.h"

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

namespace {
std::string fit_key(const DiagContext &ctx, const Model &m) {
    std::string k;
    auto bytes = [&](const void *p, size_t n) { k.append(static_cast<const char *>(p), n); };
    for (size_t e = 0; e < m.effect_count(); ++e) {
        k += m.effect_name(e);
        k += '\0';
        const auto &v = m.effect_params(e);
        bytes(v.data(), v.size() * sizeof(double));
        k += '\1';
    }
    bytes(ctx.fo.jig_sigma.data(), 3 * sizeof(double));
    if (const Model *w = ctx.fo.weigh_with) { // the weights' model, bit for bit
        k += "\4weighed ";
        for (size_t e = 0; e < w->effect_count(); ++e) {
            k += w->effect_name(e);
            k += '\0';
            const auto &v = w->effect_params(e);
            bytes(v.data(), v.size() * sizeof(double));
            k += '\1';
        }
    }
    bytes(&ctx.fo.max_evals, sizeof ctx.fo.max_evals);
    k.append(ctx.fo.use.begin(), ctx.fo.use.end());
    return k;
}
} // namespace

namespace {
// The "period" parameters (mm) of effect `name` in m: {effect, parameter}.
std::vector<std::pair<size_t, size_t>> period_params(const Model &m, const std::string &name) {
    std::vector<std::pair<size_t, size_t>> v;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (m.effect_name(e) != name) continue;
        const auto &ps = m.effect_desc(e).params;
        for (size_t q = 0; q < ps.size(); ++q)
            if (ps[q].name == "period" && (ps[q].unit == "mm" || ps[q].unit.empty())) v.push_back({e, q});
    }
    return v;
}

// A job: one fit, or a seeded one (FitJob): every start with its period
// held, then one joint fit from the best (and from the next when the
// period it lands on is not shown in the data).
bool run_job(const DiagContext &ctx, FitJob &j, const FitOptions &f) {
    if (j.more_starts.empty() || j.seeded.empty()) return fit_model(j.m, ctx.pos, f, j.rep);
    std::vector<Model> starts;
    starts.push_back(j.m);
    for (auto &m : j.more_starts) starts.push_back(m);
    int evals = 0;
    double seconds = 0;
    std::vector<double> chi2(starts.size());
    std::vector<char> shown(starts.size());
    std::vector<Model> held = starts;
    for (size_t k = 0; k < held.size(); ++k) {
        FitOptions fh = f;
        fh.hold = period_params(held[k], j.seeded);
        FitReport r;
        if (!fit_model(held[k], ctx.pos, fh, r)) {
            j.rep = r;
            return false;
        }
        evals += r.evals;
        seconds += r.seconds;
        chi2[k] = std::isnan(r.chi2) ? INFINITY : r.chi2; // a strict weak order for the sort below
        shown[k] = period_shown(held[k], j.seeded, ctx.pos);
    }
    // Shown periods first, then by chi-square; the earlier start on a tie.
    std::vector<size_t> order(starts.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
        if (shown[a] != shown[b]) return shown[a] > shown[b];
        return chi2[a] < chi2[b];
    });
    bool have = false;
    for (size_t k : order) {
        Model m = held[k];
        FitReport r;
        FitOptions fj = f;
        // Weighed as at the start (amplitudes zero), as a fit from there
        // is: the chi-squares stay comparable with the other models'.
        if (!fj.weigh_with) fj.weigh_with = &starts[k];
        if (!fit_model(m, ctx.pos, fj, r)) {
            j.rep = r;
            return false;
        }
        evals += r.evals;
        seconds += r.seconds;
        const bool ok = period_shown(m, j.seeded, ctx.pos);
        if (!have || ok) {
            j.m = std::move(m);
            j.rep = r;
            have = true;
        }
        if (ok) break;
    }
    j.rep.evals = evals;
    j.rep.seconds = seconds;
    return true;
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

bool has_user_effect(const Model &m) {
    for (size_t k = 0; k < m.effect_count(); ++k)
        if (m.effect_desc(k).stage == Stage::User) return true;
    return false;
}

bool fit_all(const DiagContext &ctx, std::vector<FitJob> &jobs, std::string &err) {
    // Fits done before (bit-identical start and noise model): their result.
    std::vector<std::string> keys(jobs.size());
    std::vector<char> cached(jobs.size(), 0);
    if (ctx.cache) {
        std::lock_guard<std::mutex> lk(ctx.cache->mu);
        for (size_t k = 0; k < jobs.size(); ++k) {
            keys[k] = fit_key(ctx, jobs[k].m);
            if (!jobs[k].seeded.empty()) {
                keys[k] += "\2seeded " + jobs[k].seeded + '\0';
                for (auto &m : jobs[k].more_starts) keys[k] += fit_key(ctx, m) + '\3';
            }
            auto it = ctx.cache->done.find(keys[k]);
            if (it == ctx.cache->done.end()) continue;
            std::string e2;
            bool ok = true;
            for (size_t e = 0; e < jobs[k].m.effect_count() && ok; ++e)
                ok = jobs[k].m.set_effect_params(e, it->second.first[e], e2);
            if (!ok) continue; // fitted below as usual
            jobs[k].rep = it->second.second;
            jobs[k].ok = true;
            cached[k] = 1;
        }
    }
    // Jobs with a user effect: on the calling thread, before the others.
    // (A fit also evaluates the model it is weighed with: when that one
    // holds a user effect, every job calls the user's callback.)
    const bool weigh_user = ctx.fo.weigh_with && has_user_effect(*ctx.fo.weigh_with);
    std::vector<size_t> serial, shared;
    for (size_t k = 0; k < jobs.size(); ++k)
        if (!cached[k]) (weigh_user || has_user_effect(jobs[k].m) ? serial : shared).push_back(k);
    // The seeded jobs (several fits each) taken first, so that the batch
    // does not wait for one started last; which thread fits a job changes
    // nothing in its result.
    std::stable_partition(shared.begin(), shared.end(), [&](size_t k) { return !jobs[k].more_starts.empty(); });
    std::atomic<bool> cancelled{false};
    auto run = [&](FitJob &j, bool main) {
        FitOptions f = ctx.fo;
        if (main)
            f.progress = [&](double fr) {
                if (ctx.report(j.stage, fr)) return !cancelled.load();
                cancelled = true;
                return false;
            };
        else
            f.progress = [&](double) { return !cancelled.load(); };
        j.ok = run_job(ctx, j, f);
        if (!j.ok) cancelled = true; // the batch fails: stop the others early
    };
    for (size_t k : serial) {
        run(jobs[k], true);
        if (!jobs[k].ok) break;
    }
    if (!cancelled) {
        std::atomic<size_t> next{0};
        std::exception_ptr failure;
        std::atomic<bool> failed{false};
        auto work = [&](bool main) {
            for (size_t i; !cancelled && (i = next++) < shared.size();) {
                try {
                    run(jobs[shared[i]], main);
                } catch (...) {
                    if (!failed.exchange(true)) failure = std::current_exception();
                    cancelled = true;
                }
            }
        };
        const size_t nt = std::min<size_t>(size_t(std::max(1, ctx.threads)), shared.size());
        std::vector<std::thread> pool;
        for (size_t t = 1; t < nt; ++t) pool.emplace_back(work, false);
        work(true);
        for (auto &t : pool) t.join();
        if (failure) std::rethrow_exception(failure);
    }
    for (auto &j : jobs)
        if (!j.ok) {
            err = j.rep.message.empty() ? "fit cancelled" : j.rep.message;
            return false;
        }
    if (ctx.cache) {
        std::lock_guard<std::mutex> lk(ctx.cache->mu);
        for (size_t k = 0; k < jobs.size(); ++k) {
            if (cached[k]) continue;
            std::vector<std::vector<double>> v;
            for (size_t e = 0; e < jobs[k].m.effect_count(); ++e) v.push_back(jobs[k].m.effect_params(e));
            ctx.cache->done.emplace(keys[k], std::make_pair(std::move(v), jobs[k].rep));
        }
    }
    return true;
}

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

std::vector<ParamValues> effect_starts(const Model &base, const std::string &effect,
                                       const std::vector<PreparedPos> &pos) {
    auto d = find_effect(effect);
    if (!d) return {{}};
    for (auto &p : d->params) {
        if (p.name != "period" || (p.unit != "mm" && !p.unit.empty())) continue;
        const PeriodPeak pk = length_period(length_view(base, pos));
        if (!pk.valid) return {{}};
        std::vector<ParamValues> v;
        for (double f : {1.0, 0.9, 1.1}) {
            const double per = std::min(std::max(pk.period_mm * f, p.lower), p.upper);
            v.push_back({{"period", per}});
        }
        return v;
    }
    return {{}};
}

bool period_shown(const Model &m, const std::string &effect, const std::vector<PreparedPos> &pos) {
    for (size_t k = 0; k < m.effect_count(); ++k) {
        if (m.effect_name(k) != effect) continue;
        const EffectDesc &d = m.effect_desc(k);
        for (size_t q = 0; q < d.params.size(); ++q) {
            if (d.params[q].name != "period") continue;
            double lo = INFINITY, hi = -INFINITY;
            for (auto &pp : pos)
                for (int c = 0; c < 4; ++c) {
                    lo = std::min(lo, pp.mean(c));
                    hi = std::max(hi, pp.mean(c));
                }
            // One full period at least within the measured lengths, as the
            // periodogram searches (periods up to the span).
            return m.effect_params(k)[q] <= hi - lo;
        }
    }
    return true;
}

void for_each_parallel(const DiagContext &ctx, size_t n, const std::function<bool(size_t)> &serial,
                       const std::function<void(size_t)> &work) {
    // Work that fits or weighs evaluates ctx.fo.weigh_with too: a user
    // effect there keeps everything on the calling thread.
    const bool weigh_user = ctx.fo.weigh_with && has_user_effect(*ctx.fo.weigh_with);
    std::vector<size_t> shared;
    for (size_t k = 0; k < n; ++k)
        if (weigh_user || serial(k)) work(k);
        else shared.push_back(k);
    std::atomic<size_t> next{0};
    std::atomic<bool> failed{false};
    std::exception_ptr failure;
    auto run = [&] {
        for (size_t i; !failed && (i = next++) < shared.size();) {
            try {
                work(shared[i]);
            } catch (...) {
                if (!failed.exchange(true)) failure = std::current_exception();
            }
        }
    };
    const size_t nt = std::min<size_t>(size_t(std::max(1, ctx.threads)), shared.size());
    std::vector<std::thread> pool;
    for (size_t t = 1; t < nt; ++t) pool.emplace_back(run);
    run();
    for (auto &t : pool) t.join();
    if (failure) std::rethrow_exception(failure);
}

bool score_candidates(const DiagContext &ctx, const Model &base, int base_free, double base_chi2,
                      const Eval &base_eval, const std::string &stage, std::vector<Candidate> &out,
                      std::string &err) {
    out.clear();
    const size_t P = ctx.pos.size();
    auto list = candidate_effects();
    const size_t n_base = reading_effects(base).size();
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
            if (j.m.has_effect(d->name)) jobs.push_back(std::move(j));
        }
        span[i].second = jobs.size();
    }
    if (!fit_all(ctx, jobs, err)) return false;
    // Each candidate's best start, then (in parallel: independent, each
    // writes its own) what it overlaps in the model and its position
    // errors; then judged in the catalogue's order.
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
            if (!period_shown(m, d->name, ctx.pos)) continue;
            if (!have || r.chi2 < c.rep.chi2) {
                c.m = m;
                c.rep = r;
                have = true;
            }
        }
        if (!have) continue;
        c.k = c.rep.n_free - base_free;
        if (c.k <= 0) continue; // nothing left to fit after the gauge: indistinguishable from the model
        picked_of[i] = picked.size();
        picked.push_back(std::move(c));
    }
    for_each_parallel(
        ctx, picked.size(), [&](size_t q) { return has_user_effect(picked[q].m); },
        [&](size_t q) {
            Candidate &c = picked[q];
            // What the model already does that this effect would: an effect
            // the model's own effects reproduce cannot be told from them.
            if (n_base > 0) {
                Overlap ov = effect_overlap(c.m, ctx.pos, ctx.fo, c.name);
                for (auto &pe : ov.per_effect)
                    if (pe.second > 0.99) c.in_model.push_back(pe.first);
                if (c.in_model.empty() && ov.all > 0.99)
                    for (auto &pe : ov.per_effect) c.in_model.push_back(pe.first);
            }
            c.E = evaluate(c.m, ctx.pos);
        });
    size_t done = 0;
    for (size_t i = 0; i < list.size(); ++i) {
        ++done;
        if (picked_of[i] == SIZE_MAX) continue;
        Candidate &c = picked[picked_of[i]];
        c.dchi2 = base_chi2 - c.rep.chi2;
        c.bic = -c.dchi2 + c.k * std::log(ctx.n_obs);
        c.p = chi2_sf(std::max(0.0, c.dchi2), c.k);
        c.v = judge(c.E, ctx.G, ctx.own_jig(c.E), c.rep.n_free);
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
        out.push_back(std::move(c));
        if (!ctx.report(stage, double(done) / double(list.size()))) {
            err = "fit cancelled";
            return false;
        }
    }
    for (auto &c : out) c.p_adj = std::min(1.0, c.p * double(out.size()));
    std::sort(out.begin(), out.end(), [](const Candidate &a, const Candidate &b) { return a.bic < b.bic; });
    return true;
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
