// See stages.h: the stages before the verdict.
#include "calib/diagnosis/stages.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "model/effect.h"

namespace cdm {
namespace diag {

bool fit_user_model(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, UserModel &u,
                    std::string &err) {
    FitCalibrationOptions fopt;
    fopt.effects = opt.effects;
    fopt.jig_tolerance_mm = opt.jig_tolerance_mm;
    fopt.reading_noise = opt.reading_noise;
    fopt.progress = opt.progress;
    fopt.fitted_maxima = false; // one pass over the rows (per_sample_stage) serves every evaluation
    fopt.threads = opt.threads;
    // The nominal triangulation's pass over the rows runs on beside the
    // candidates and the search (it fills the cores' gaps between a batch's
    // fits): waited for at the pass at the end, which needs its ellipsoid.
    fopt.nominal_pending = &u.nominal_pending;
    fopt.nominal_err = &u.nominal_err;
    if (!fit_calibration(data, g, fopt, u.cf, err)) return false;
    u.user_jig = opt.jig_tolerance_mm >= 0;
    // (repeats: whether the candidates' own jig tolerance is capped, diagnose.cpp's kJigCapMm)
    u.repeats = std::any_of(u.cf.pos.begin(), u.cf.pos.end(), [](const PreparedPos &p) { return p.n > 1; });
    return true;
}

namespace {

// The thresholds of the search's noise model and of the readings' own
// error, each with its reason.
// A re-estimated jig tolerance or hole share within 5 % (relative) of the
// one in use has settled: each further re-estimation costs a whole search.
constexpr double kNoiseSettled = 0.05;
// At most three re-estimations: the search is bounded whatever the data.
constexpr int kNoiseRounds = 3;
// One search pass per re-estimation, and a swap search after each and
// after the first search.
constexpr int kSearchPasses = 4 + kNoiseRounds;
// The readings' own error is kept when its variance is more than three
// standard errors above zero (one-sided, 0.13 % under no such error), and
// the diagnosis runs again with it when the kept one differs from the one
// used by as many standard errors...
constexpr double kReadingSe = 3;
// ...and by more than a fifth of the variance used: a second diagnosis is
// the cost, not paid for a smaller change of the weights.
constexpr double kReadingChange = 0.2;

// The search's steps appended to s.sr's path; the sets `next` fitted
// replace s.sr's, or join them when fitted under the same noise model
// (their BICs compare: the alternatives read them).
void take_search(SearchStage &s, SearchResult &next, bool same_noise) {
    for (auto &st : next.path) {
        st.step += int(s.sr.path.size());
        s.sr.path.push_back(st);
    }
    next.path = s.sr.path;
    if (same_noise) next.visited.insert(next.visited.begin(), s.sr.visited.begin(), s.sr.visited.end());
    s.sr = std::move(next);
}

// The search's candidates completed and its alternatives found.
bool finish_search(SearchStage &s, std::string &err) {
    // The table shown is of full fits (not the screen's estimates).
    if (s.sr.provisional ||
        std::any_of(s.sr.cands.begin(), s.sr.cands.end(), [](const Candidate &c) { return c.screened; })) {
        err = "internal error: the search's last candidates are the screen's, not full fits";
        return false;
    }
    {
        DiagContext rc = s.sctx; // as the search's last step weighed them
        rc.fo.weigh_with = &s.sr.model;
        complete_candidates(rc, s.sr.model, s.sr.E, s.sr.cands);
    }
    mark_confusions(s.sr.E, s.sctx.jig, s.sr.cands);
    return search_alternatives(s.sctx, s.sr, s.alts, err);
}

} // namespace

bool search_stage(const Model &model, const FitReport &rep, bool user_jig, SearchStage &s, std::string &err) {
    DiagContext &sctx = s.sctx; // the search's noise model, re-estimated below
    const DeviceGeometry &g = sctx.g;
    int rounds = 0; // noise-model re-estimations (below)
    // Whether the search goes on from a model with E under the noise model
    // re-estimated from E (below): its estimate (j2, h2) differs by more
    // than 5 %.
    auto new_noise = [&](const Eval &E, V3 &j2, V3 &h2) {
        if (user_jig || rounds >= kNoiseRounds) return false;
        j2 = sctx.own_jig(E);
        h2 = sctx.own_hole(E, j2);
        const auto tol = kNoiseSettled * sctx.jig.array().abs().max(1e-6);
        return !((j2 - sctx.jig).array().abs() <= tol).all() ||
               !((h2 - sctx.fo.hole_sigma).array().abs() <= tol).all();
    };
    const std::function<bool(const Eval &)> renoise = [&](const Eval &E) {
        V3 j2, h2;
        return new_noise(E, j2, h2);
    };
    if (!model_search(sctx, model, rep, false, s.sr, err, nullptr, renoise)) return false;
    // The jig tolerance was estimated from the user's model's residual;
    // a model far from the data biases that estimate (its smooth error
    // leaks into the white scatter), and with it every chi-square. When
    // the recommended model's own estimate differs by more than 5 %,
    // the search goes on from there with that noise model, until the
    // estimate settles (at most three re-estimations). Once it has
    // settled, the search goes on with the one-effect swaps (its first
    // step's fits are the cache's: the same start, the same noise
    // model); a swap that moves the model sends its estimate to the
    // same check.
    // Bounded: three re-estimations, and a swap search after each
    // and after the first search, at most. A search that ended
    // provisionally (model_search's `restarts`) is searched again: under
    // the new noise model, or by the swap search, or after the loop.
    for (int pass = 0; pass < kSearchPasses; ++pass) {
        V3 j2, h2;
        if (new_noise(s.sr.E, j2, h2)) {
            ++rounds;
            sctx.jig = j2;
            set_jig_noise(sctx.fo, j2, h2);
            Model start = s.sr.model;
            FitReport r0;
            if (!sctx.fit(start, "search (noise model re-estimated)", r0)) {
                err = r0.message.empty() ? "fit cancelled" : r0.message;
                return false;
            }
            SearchResult next(g);
            if (!model_search(sctx, start, r0, false, next, err, nullptr, renoise)) return false;
            take_search(s, next, false);
            continue;
        }
        SearchResult next(g);
        if (!model_search(sctx, s.sr.model, s.sr.rep, true, next, err, &s.sr.seen)) return false;
        const bool moved = !next.path.empty();
        take_search(s, next, true);
        if (!moved || user_jig || rounds >= kNoiseRounds) break;
    }
    if (s.sr.provisional) { // the passes ran out on a provisional end: searched once more, in full
        SearchResult next(g);
        if (!model_search(sctx, s.sr.model, s.sr.rep, true, next, err, &s.sr.seen)) return false;
        take_search(s, next, true);
    }
    return finish_search(s, err);
}

bool residual_stage(const DiagContext &ctx, const DiagContext &uc, const UserModel &u,
                    const std::vector<Candidate> &cands, const SearchStage &s, const DiagnoseOptions &opt,
                    size_t already, size_t read, std::vector<Outlier> &outliers, Declined &declined, Residuals &r,
                    std::string &err) {
    const CalibrationFit &cf = u.cf;
    const auto &pos = cf.pos;
    const bool search = s.on;
    ctx.report("residual analysis", 0.0);
    r.use_top = !search && !u.v.explained && !cands.empty() && cands[0].bic < 0 && !cands[0].v.explained;
    const Model &basis = search ? s.sr.model : r.use_top ? cands[0].m : cf.model;
    const Eval &bE = search ? s.sr.E : r.use_top ? cands[0].E : cf.fitted;
    r.lv = length_view(basis, pos);
    // The jig's own errors first (calib/evaluation/jig.h): the fixture's
    // per-height offsets leave the residual before the trends are looked
    // for, and a repeat at every hole is named as the plate's or the
    // device's.
    r.jig = search ? s.sctx.jig : cf.jig;
    FixtureLR flr;
    {
        FitOptions bfo = search ? s.sctx.fo : r.use_top ? uc.fo : ctx.fo;
        bfo.progress = [&](double f) { return ctx.report("residual analysis", f); };
        bfo.threads = ctx.threads; // (its two fits run alone)
        if (!fixture_lr(basis, pos, bfo, flr, err)) return false;
    }
    r.ja = jig_analysis(bE, cf.grid, pos, r.jig, noise_floor(bE, r.jig), &flr);
    const nlohmann::json &jig_report = r.ja.report;
    Eval bJ = bE;
    for (size_t j = 0; j < pos.size(); ++j) bJ.res[j] -= r.ja.offset[j];
    r.findings = residual_findings(pos, shifted(r.lv, r.ja.offset), bJ, r.jig, r.lv);
    if (opt.outliers) outliers = find_outliers(bJ, cf.grid, r.jig, already, read, &declined);
    if (!jig_report["finding"].is_null()) r.findings.push_back(jig_report["finding"]);
    // Stand-ins, the term the catalogue lacks, the jig's errors in doubt.
    const FitReport &brep = search ? s.sr.rep : r.use_top ? cands[0].rep : cf.report;
    const Verdict vb = judge(bE, cf.grid, r.jig, brep.n_free, search ? s.sctx.fo.hole_sigma : cf.fit_options.hole_sigma);
    return beyond_catalogue(search ? s.sctx : ctx, cf.model, cf.report, basis, brep, bE,
                            vb.explained && r.findings.empty(), jig_report, noise_floor(bE, r.jig), r.bey, err);
}

bool per_sample_stage(const Dataset &data, const DiagContext &ctx, UserModel &u, std::vector<Candidate> &cands,
                      SearchStage &s, Seed &seed, std::string &err) {
    std::vector<Eval *> linear{&u.cf.fitted};
    for (auto &c : cands) linear.push_back(&c.E);
    if (s.on) {
        linear.push_back(&s.sr.E);
        for (auto &c : s.sr.cands) linear.push_back(&c.E);
    }
    ctx.report("per-sample statistics", 0.0);
    if (u.nominal_pending.valid() && !u.nominal_pending.get()) {
        err = u.nominal_err;
        return false;
    }
    seed.ell = ellipsoid_on(u.cf.nominal, u.cf.pos);
    return sample_pass(data, u.cf.pos, linear, {{&ctx.g, &seed.ell, &seed.E}}, err, ctx.threads > 1);
}

// The readings' own error again, from the recommended model's
// misclosure: estimated first from the user's model, whose error leaks
// into it where it is not smooth across the plate (a short ripple, a
// worn spot: 0.0037 mm from a 0.15 mm ripple on the nominal model).
// The misclosure's noise already holds the variance used, so the
// estimate is what is beyond it (or short of it, below zero).
// The total is kept by the first estimate's rule (more than three
// standard errors above zero), and diagnose() runs the diagnosis again
// with it when what is kept differs from the variance used by more than
// three standard errors and a fifth of that variance (never when both
// are none).
ReadingAgain reading_noise_again(const UserModel &u, const SearchStage &s) {
    ReadingAgain out;
    if (!s.on) return out;
    out.on = true;
    const ReadingNoise again = estimate_reading_noise(s.sr.E, u.cf.grid);
    const double used = u.cf.reading.sigma * u.cf.reading.sigma;
    ReadingNoise r = again;
    r.variance = used + again.variance;
    r.sigma = again.tested && r.variance > kReadingSe * again.se ? std::sqrt(r.variance) : 0.0;
    const double keep = r.sigma * r.sigma;
    out.again = again;
    out.r = r;
    out.retry = again.tested && keep != used && std::fabs(keep - used) > kReadingSe * again.se &&
                std::fabs(keep - used) > kReadingChange * used;
    return out;
}

} // namespace diag
} // namespace cdm
