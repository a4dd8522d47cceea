// What every stage of the diagnosis shares: the data prepared once, the
// noise model the fit weighs readings with, and how to fit a model with
// progress and cancellation. The search's and the diagnosis's stages share it.
#pragma once

#include <cmath>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "calib/dataset/dataset.h"
#include "calib/evaluation/eval.h"
#include "calib/evaluation/noise.h"
#include "calib/evaluation/spatial.h"
#include "calib/fit/fit.h"
#include "model/model.h"

namespace cdm {
namespace diag {

// Fits already done, by everything that determines their result (the
// effects and their starting values, bit for bit, and the noise model): a
// fit is deterministic, so one asked for again (the search and its
// alternatives reach the same set from the same start; a noise-model round
// repeats a step) is taken from here, with the same numbers.
//
// The same for evaluations (evaluate_cached): a fit taken from the cache
// gives the same model, whose evaluation (a forward-kinematics solve per
// position) was made too: 20 of the 49 evaluations of a diagnosis on
// `exit_pulley` were repeats. The kEvals most recent are kept (about half a
// megabyte each on a full jig); every context sharing a cache has the same
// positions.
struct FitCache {
    std::mutex mu;
    std::map<std::string, std::pair<std::vector<std::vector<double>>, FitReport>> done;
    static constexpr size_t kEvals = 16;
    std::map<std::string, Eval> evals;
    std::deque<std::string> eval_order; // oldest first
};

struct DiagContext {
    const Dataset &data;
    const DeviceGeometry &g;
    const std::vector<PreparedPos> &pos;
    const Grid &G;
    V3 jig;              // jig tolerance per axis (mm): fo's jig_sigma and hole_sigma together
    bool user_jig;       // given by the user (else estimated)
    double jig_cap;      // cap on a model's own white-scatter estimate
    FitOptions fo;       // the fit's noise model; every comparison uses it
    double n_obs;        // readings: 4 per position
    std::function<bool(const std::string &, double)> progress;
    // Fits that do not depend on each other (a search step's candidates,
    // removals, swaps) run on this many threads (fit_all); 1: in turn.
    int threads = 1;
    // Shared by the copies of a context (the search's re-estimated noise
    // model is part of each key).
    std::shared_ptr<FitCache> cache = std::make_shared<FitCache>();

    bool report(const std::string &stage, double f) const { return !progress || progress(stage, f); }
    // Fits m's reading-space effects from their current values.
    // A fit alone: its positions evaluated on `threads` threads.
    bool fit(Model &m, const std::string &stage, FitReport &r) const {
        FitOptions f = fo;
        f.threads = threads;
        f.progress = [&](double fr) { return report(stage, fr); };
        return fit_model(m, pos, f, r);
    }
    double bic(double chi2, int k) const { return chi2 + k * std::log(n_obs); }
    // The white scatter a model's own residual shows (a large smooth
    // residual biases the nugget): how each explanation is judged.
    V3 own_jig(const Eval &E) const {
        if (user_jig) return jig;
        V3 est = estimate_nugget(E, G), j;
        for (int a = 0; a < 3; ++a) j(a) = std::min(est(a), jig_cap);
        return j;
    }
    // The part of own_jig(E) = j that the plate's holes share at every
    // height (zero with the user's tolerance: that is taken as independent).
    V3 own_hole(const Eval &E, const V3 &j) const {
        if (user_jig) return V3::Zero();
        return estimate_hole_std(E, G).cwiseMin(j);
    }
};

// One fit of a batch: the model is fitted in place from its current values.
// With `seeded` and `more_starts` (start_job): the effect `seeded` has a
// period seeded from the data and m is its first start, more_starts the
// others (the same model, another period). Each start is fitted with its
// period held (the rest: near-linear, a few evaluations), and one joint
// fit (period free) is run from the best of them by chi-square; m and rep
// are that fit's, rep.evals and rep.seconds count the held fits and the
// joint fits this order needed (not those a second thread tried ahead and
// were not needed: batch.cpp). (Three joint fits, one per start, would
// be half of a diagnosis's evaluation work, evaluations times parameters,
// with exit_pulley hidden; docs/performance.md, "The whole diagnosis", "A
// seeded period", says what runs instead.) A joint fit
// whose period is not shown in the data (period_shown; one given up past
// twice the span ends there, FitReport::abandoned) is followed by one from
// the next-best start; when none is shown, m and rep are the first's, and
// every reader sets them aside by period_shown.
struct FitJob {
    FitJob(Model m_, std::string stage_) : m(std::move(m_)), stage(std::move(stage_)) {}
    Model m;
    std::string stage;
    FitReport rep;
    bool ok = false;
    std::string seeded;
    std::vector<Model> more_starts;
    // A screen's job (score_candidates with `screen`, a search step:
    // search.cpp): one Gauss-Newton step from the start
    // (FitOptions::single_step, without the standard errors); a seeded job
    // runs its held fits only, each one step, and rep is the one its held
    // order puts first, the period counted among rep.n_free as the joint
    // fit counts it. Its chi-square is an estimate for ranking, usually
    // above the full fit's, not a bound: a full fit damps a step that gains
    // less than a quarter of its promise and may end elsewhere.
    bool one_step = false;
};

// The cores this process may run on (its affinity mask: taskset, cgroup
// cpusets), at most 8: the diagnosis's default ctx.threads.
int usable_cores();

// Fits every job, on ctx.threads threads, each job exactly as ctx.fit would
// (the same start, the same noise model: the results do not depend on the
// number of threads or on which thread took a job). Only the calling
// thread reports progress; the others stop when it is cancelled. Models
// with a user effect are fitted in turn on the calling thread (a user's
// callback need not be reentrant), and so is every job when the model the
// fits are weighed with (ctx.fo.weigh_with) holds one. A seeded job's fits
// are separate tasks (batch.cpp), with the result of fitting them in
// turn. False + err (the message of the fit that failed first; the others
// are then stopped) when a fit fails or is cancelled.
bool fit_all(const DiagContext &ctx, std::vector<FitJob> &jobs, std::string &err);

// evaluate(m, ctx.pos, threads), or the same evaluation made before
// (FitCache). Models with a user effect are evaluated every time. threads:
// ctx.threads for an evaluation alone; 1 within a batch already parallel.
Eval evaluate_cached(const DiagContext &ctx, const Model &m, int threads = 1);
// Stores E as evaluate(m, ctx.pos), which it must be (bit for bit).
void remember_evaluation(const DiagContext &ctx, const Model &m, const Eval &E);

// True when the model holds a user effect (its callback need not be
// reentrant: such a model is fitted and evaluated on the calling thread).
bool has_user_effect(const Model &m);

// work(k) for k < n on ctx.threads threads; the k whose serial(k) is true
// on the calling thread first (all of them when ctx.fo.weigh_with holds a
// user effect: a fit or an overlap evaluates that model too). Each k must write only its own results (then
// which thread runs it changes nothing). An exception from any is rethrown
// here, after the others have stopped taking work.
void for_each_parallel(const DiagContext &ctx, size_t n, const std::function<bool(size_t)> &serial,
                       const std::function<void(size_t)> &work);

// Starting values for an effect whose parameters enter non-linearly and
// that the data can seed: a period in cable length (ParamRole::LengthPeriod:
// drum eccentricity, or a user effect's "period" in mm) starts at the peak of the cable-length
// periodogram of `base`'s residual and at 0.9 and 1.1 times it. One
// ParamValues per start; a single empty one when nothing is seeded.
// False when `effect` in m has a period in cable length longer than the
// span of the measured cable lengths: such a "period" does not repeat in
// the data and is a smooth trend in disguise (a flexible stand-in for gain or
// non-linearity), so that fit is not taken.
bool period_shown(const Model &m, const std::string &effect, const std::vector<PreparedPos> &pos);
// The span of the measured cable lengths (mm): the longest period shown.
double length_span(const std::vector<PreparedPos> &pos);
// A fit's period shown: period_shown, and the fit not abandoned (a period
// profile that falls to the span ends on the span itself, which
// period_shown alone would take; a joint fit given up past twice the span).
inline bool fit_shown(const Model &m, const FitReport &r, const std::string &effect,
                      const std::vector<PreparedPos> &pos) {
    return !r.abandoned && period_shown(m, effect, pos);
}

// The joint fit of a seeded period from m, fitted with the period held at
// its start (chi-square start_chi2): a search over the period of the
// profile chi-square (each point a fit with the period held), then one fit
// with everything free from its minimum (period.cpp). `period`: the
// {effect, parameter} of the period in m (with more than one, the plain
// joint fit). f's weights must be fixed (weigh_with) so that the points
// compare. A search that leaves the span of the measured lengths stops
// there: m is that point's held fit and rep.abandoned is set (its period
// is not shown). `known`: other held fits of the same model at other
// periods and their chi-squares (the job's other starts), used as points
// where they fall. rep counts every fit's evaluations and seconds.
bool fit_seeded_period(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &f,
                       const std::vector<std::pair<size_t, size_t>> &period, double start_chi2,
                       const std::vector<std::pair<const Model *, double>> &known, FitReport &rep);

std::vector<ParamValues> effect_starts(const Model &base, const std::string &effect,
                                       const std::vector<PreparedPos> &pos);

// The job fitting `keep` of `from` plus `add` from `starts` (effect_starts:
// one model per start; with several, a seeded job, see FitJob). The job's
// m lacks `add` when the effect could not be added.
FitJob start_job(const Model &from, const std::vector<std::string> &keep, const std::string &add,
                 const std::vector<ParamValues> &starts, std::string stage);

} // namespace diag
} // namespace cdm
