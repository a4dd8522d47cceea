// fit_all and for_each_parallel (context.h): batches of independent
// fits and other per-item work on ctx.threads threads.
//
// A batch is a list of tasks, not of jobs. A plain job is one task (one
// fit). A seeded job (a period seeded from the data: drum_eccentricity) is
// several: one fit per start with the period held, then the joint fits in
// the order of those fits' chi-squares, of which the first whose period is
// shown in the data is the job's result (context.h, FitJob). Run as one
// task, such a job was the critical path of the diagnosis's first batch:
// 0.47 s of wall time where every other candidate together took 0.12 s on
// the other core, on data with no ripple, where all three joint fits run
// (their periods wander out of the measured span). As tasks, the held fits
// are taken first, on every thread; the joint fit from the best start is
// queued before everything else when the last held fit ends; the joint fits
// from the other starts are queued last, speculatively: a thread with
// nothing else to do fits them, and one whose result is no longer needed
// (an earlier start's period was shown) is skipped or stopped. The job's
// result is what fitting them in turn would give, bit for bit: the same
// fits from the same starts, the same choice, evaluations and seconds
// summed over the fits that choice needed.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <thread>

#include <sched.h>

#include "calib/fit/parallel.h"
#include "calib/search/context.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

namespace {

// The model's effects and their values, bit for bit, appended to k.
void model_key(std::string &k, const Model &m) {
    for (size_t e = 0; e < m.effect_count(); ++e) {
        k += m.effect_name(e);
        k += '\0';
        const auto &v = m.effect_params(e);
        k.append(reinterpret_cast<const char *>(v.data()), v.size() * sizeof(double));
        k += '\1';
    }
}

std::string fit_key(const DiagContext &ctx, const Model &m) {
    std::string k;
    auto bytes = [&](const void *p, size_t n) { k.append(static_cast<const char *>(p), n); };
    model_key(k, m);
    bytes(ctx.fo.jig_sigma.data(), 3 * sizeof(double));
    bytes(ctx.fo.hole_sigma.data(), 3 * sizeof(double));
    if (const Model *w = ctx.fo.weigh_with) { // the weights' model, bit for bit
        k += "\4weighed ";
        model_key(k, *w);
    }
    bytes(&ctx.fo.max_evals, sizeof ctx.fo.max_evals);
    k += ctx.fo.profile_fixture_start ? '\5' : '\6';
    k.append(ctx.fo.use.begin(), ctx.fo.use.end());
    return k;
}

// The periods in cable length (ParamRole::LengthPeriod) of effect `name` in
// m: {effect, parameter}.
std::vector<std::pair<size_t, size_t>> period_params(const Model &m, const std::string &name) {
    std::vector<std::pair<size_t, size_t>> v;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (m.effect_name(e) != name) continue;
        const auto &ps = m.effect_desc(e).params;
        for (size_t q = 0; q < ps.size(); ++q)
            if (ps[q].role == ParamRole::LengthPeriod) v.push_back({e, q});
    }
    return v;
}

// One fit of a batch. Held and Joint: fit `start` of a seeded job.
enum class Kind { Plain, Held, Joint };
struct Task {
    size_t job;
    Kind kind;
    size_t start;
};

// A seeded job's fits: start k's model before (starts[k]) and after its
// held fit (held[k]), then the joint fit from there (joint[k]).
struct Seeded {
    std::vector<Model> starts, held, joint;
    std::vector<FitReport> held_rep, joint_rep;
    std::vector<char> held_ok, joint_ok, joint_done, shown_held, shown_joint;
    std::unique_ptr<std::atomic<bool>[]> stop; // per start: its joint fit is no longer needed
    size_t held_left = 0;
    std::vector<size_t> order; // starts by held chi-square (shown periods first)
    bool decided = false;
};

class Batch {
public:
    Batch(const DiagContext &ctx, std::vector<FitJob> &jobs, std::atomic<bool> &cancelled)
        : ctx_(ctx), jobs_(jobs), cancelled_(cancelled), seeded_(jobs.size()) {}

    // Fits jobs[k] for k in ks on `threads` threads (the calling thread
    // reports progress).
    void run(const std::vector<size_t> &ks, size_t threads) {
        std::deque<Task> held, plain;
        for (size_t k : ks) {
            FitJob &j = jobs_[k];
            if (j.more_starts.empty() || j.seeded.empty()) {
                plain.push_back({k, Kind::Plain, 0});
                continue;
            }
            Seeded &s = seeded_[k];
            s.starts.push_back(j.m);
            for (auto &m : j.more_starts) s.starts.push_back(m);
            const size_t n = s.starts.size();
            s.held = s.starts;
            s.joint.assign(n, Model{j.m.geometry()});
            s.held_rep.resize(n);
            s.joint_rep.resize(n);
            s.held_ok.assign(n, 0);
            s.joint_ok.assign(n, 0);
            s.joint_done.assign(n, 0);
            s.shown_held.assign(n, 0);
            s.shown_joint.assign(n, 0);
            s.stop.reset(new std::atomic<bool>[n]);
            for (size_t q = 0; q < n; ++q) s.stop[q] = false;
            s.held_left = n;
            for (size_t q = 0; q < n; ++q) held.push_back({k, Kind::Held, q});
        }
        queue_ = std::move(held);
        for (auto &t : plain) queue_.push_back(t);
        const size_t nt = std::max<size_t>(1, std::min(threads, queue_.size()));
        // One fit alone: its positions on the threads (FitOptions::threads).
        solo_threads_ = queue_.size() == 1 ? int(threads) : 1;
        // work(true) is this thread's: the one whose fits may show progress.
        const std::thread::id here = std::this_thread::get_id();
        on_threads(nt, [&] { work(std::this_thread::get_id() == here); });
        if (failure_) std::rethrow_exception(failure_);
    }

private:
    void work(bool main) {
        std::unique_lock<std::mutex> lk(mu_);
        for (;;) {
            cv_.wait(lk, [&] { return !queue_.empty() || in_flight_ == 0 || cancelled_; });
            if (cancelled_ || queue_.empty()) break;
            const Task t = queue_.front();
            queue_.pop_front();
            if (t.kind == Kind::Joint && seeded_[t.job].decided) continue; // not needed
            ++in_flight_;
            lk.unlock();
            try {
                fit(t, main);
            } catch (...) {
                lk.lock();
                if (!failure_) failure_ = std::current_exception();
                cancelled_ = true;
                --in_flight_;
                cv_.notify_all();
                break;
            }
            lk.lock();
            --in_flight_;
            try {
                done(t);
            } catch (...) { // (an allocation): the batch fails with it
                if (!failure_) failure_ = std::current_exception();
                cancelled_ = true;
            }
            cv_.notify_all();
        }
    }

    // Runs task t's fit (outside the lock: it writes only t's own slots).
    void fit(const Task &t, bool main) {
        FitJob &j = jobs_[t.job];
        FitOptions f = ctx_.fo;
        f.threads = solo_threads_;
        std::atomic<bool> *stop = t.kind == Kind::Joint ? &seeded_[t.job].stop[t.start] : nullptr;
        if (main)
            f.progress = [&](double fr) {
                if (!ctx_.report(j.stage, fr)) cancelled_ = true;
                return !cancelled_.load() && !(stop && *stop);
            };
        else
            f.progress = [&](double) { return !cancelled_.load() && !(stop && *stop); };
        if (j.one_step) { // (a screen's fit: its chi-square alone is read)
            f.single_step = true;
            f.statistics = false;
        }
        if (t.kind == Kind::Plain) {
            j.ok = fit_model(j.m, ctx_.pos, f, j.rep);
            return;
        }
        Seeded &s = seeded_[t.job];
        const size_t q = t.start;
        if (t.kind == Kind::Held) {
            f.hold = period_params(s.held[q], j.seeded);
            s.held_ok[q] = fit_model(s.held[q], ctx_.pos, f, s.held_rep[q]);
            s.shown_held[q] = period_shown(s.held[q], j.seeded, ctx_.pos);
            return;
        }
        s.joint[q] = s.held[q];
        // Weighed as at the start (amplitudes zero), as a fit from there
        // is: the chi-squares stay comparable with the other models'.
        if (!f.weigh_with) f.weigh_with = &s.starts[q];
        // A period whose best fit so far lies past twice the measured span
        // has left the ripple for a smooth trend (less than half a cycle
        // over the data): the final free fit is given up there and ends on
        // that point, whose period is not shown, as where it was heading.
        // (The profile search before it stops at the span itself.)
        const double span = length_span(ctx_.pos);
        const auto at = period_params(s.joint[q], j.seeded);
        for (auto a : at) f.abandon_above.push_back({a, 2 * span});
        // The other starts' held fits are points of the same profile when
        // they were weighed alike: by the context's model, or each by its
        // own start when those differ in the period alone and the ripple
        // starts at zero amplitude (a built-in), so that the readings'
        // sensitivity to the position, and the weights, are the same.
        std::vector<std::pair<const Model *, double>> known;
        const bool alike = ctx_.fo.weigh_with || (!at.empty() && s.starts[q].effect_desc(at[0].first).stage != Stage::User);
        for (size_t r = 0; alike && r < s.starts.size(); ++r)
            if (r != q && s.held_ok[r]) known.push_back({&s.held[r], s.held_rep[r].chi2});
        s.joint_ok[q] = fit_seeded_period(s.joint[q], ctx_.pos, f, at, s.held_rep[q].chi2, known, s.joint_rep[q]);
        s.shown_joint[q] = fit_shown(s.joint[q], s.joint_rep[q], j.seeded, ctx_.pos);
    }

    // Under the lock: task t has ended; what follows from it.
    void done(const Task &t) {
        FitJob &j = jobs_[t.job];
        if (t.kind == Kind::Plain) {
            if (!j.ok) fail(t.job);
            return;
        }
        Seeded &s = seeded_[t.job];
        if (t.kind == Kind::Held) {
            if (--s.held_left > 0) return;
            for (size_t q = 0; q < s.starts.size(); ++q)
                if (!s.held_ok[q]) { // the first failed start, as in turn
                    j.rep = s.held_rep[q];
                    s.decided = true;
                    return fail(t.job);
                }
            // Shown periods first, then by chi-square; the earlier start on a tie.
            const size_t n = s.starts.size();
            std::vector<double> chi2(n);
            for (size_t q = 0; q < n; ++q) // (NaN: a strict weak order for the sort)
                chi2[q] = std::isnan(s.held_rep[q].chi2) ? INFINITY : s.held_rep[q].chi2;
            s.order.resize(n);
            for (size_t q = 0; q < n; ++q) s.order[q] = q;
            std::stable_sort(s.order.begin(), s.order.end(), [&](size_t a, size_t b) {
                if (s.shown_held[a] != s.shown_held[b]) return s.shown_held[a] > s.shown_held[b];
                return chi2[a] < chi2[b];
            });
            if (j.one_step) { // screened: the held fit put first is the result
                const size_t pick = s.order[0];
                int evals = 0;
                double seconds = 0;
                for (size_t q = 0; q < n; ++q) {
                    evals += s.held_rep[q].evals;
                    seconds += s.held_rep[q].seconds;
                }
                j.m = s.held[pick];
                j.rep = s.held_rep[pick];
                j.rep.n_free += int(period_params(j.m, j.seeded).size());
                j.rep.evals = evals;
                j.rep.seconds = seconds;
                j.ok = true;
                s.decided = true;
                return;
            }
            queue_.push_front({t.job, Kind::Joint, s.order[0]});
            for (size_t r = 1; r < n; ++r) queue_.push_back({t.job, Kind::Joint, s.order[r]});
            return;
        }
        s.joint_done[t.start] = 1;
        decide(t.job);
    }

    // Under the lock: the job's result once the joint fits in order say it:
    // the first whose period is shown, or the first when none is.
    void decide(size_t job) {
        FitJob &j = jobs_[job];
        Seeded &s = seeded_[job];
        if (s.decided) return;
        size_t pick = SIZE_MAX, used = 0;
        for (size_t r = 0; r < s.order.size(); ++r) {
            const size_t q = s.order[r];
            if (!s.joint_done[q]) return; // in turn, this one would come next
            used = r + 1;
            if (!s.joint_ok[q]) { // in turn, the job would have failed here
                j.rep = s.joint_rep[q];
                s.decided = true;
                return fail(job);
            }
            if (s.shown_joint[q]) {
                pick = q;
                break;
            }
        }
        if (pick == SIZE_MAX) pick = s.order[0];
        int evals = 0;
        double seconds = 0;
        for (size_t q = 0; q < s.starts.size(); ++q) {
            evals += s.held_rep[q].evals;
            seconds += s.held_rep[q].seconds;
        }
        for (size_t r = 0; r < used; ++r) {
            evals += s.joint_rep[s.order[r]].evals;
            seconds += s.joint_rep[s.order[r]].seconds;
        }
        j.m = s.joint[pick];
        j.rep = s.joint_rep[pick];
        j.rep.evals = evals;
        j.rep.seconds = seconds;
        j.ok = true;
        s.decided = true;
        for (size_t q = 0; q < s.starts.size(); ++q) s.stop[q] = true; // the rest are not needed
    }

    // Under the lock: the job has failed; the batch fails with it (the
    // others are stopped early). The first to fail is the one reported:
    // the others' "fit cancelled" follows from it.
    void fail(size_t job) {
        jobs_[job].ok = false;
        if (first_failed_ == SIZE_MAX) first_failed_ = job;
        cancelled_ = true;
    }

    const DiagContext &ctx_;
    std::vector<FitJob> &jobs_;
    std::atomic<bool> &cancelled_;
    std::vector<Seeded> seeded_;
    std::mutex mu_;
    std::condition_variable cv_;
    std::deque<Task> queue_;
    size_t in_flight_ = 0;
    int solo_threads_ = 1;
    std::exception_ptr failure_;

public:
    size_t first_failed_ = SIZE_MAX; // the job whose failure ended the batch
};

} // namespace

bool has_user_effect(const Model &m) {
    for (size_t k = 0; k < m.effect_count(); ++k)
        if (m.effect_desc(k).stage == Stage::User) return true;
    return false;
}

Eval evaluate_cached(const DiagContext &ctx, const Model &m, int threads) {
    if (!ctx.cache || has_user_effect(m)) return evaluate(m, ctx.pos); // (a user's callback may not be pure)
    std::string k;
    model_key(k, m);
    {
        std::lock_guard<std::mutex> lk(ctx.cache->mu);
        auto it = ctx.cache->evals.find(k);
        if (it != ctx.cache->evals.end()) return it->second;
    }
    Eval E = evaluate(m, ctx.pos, threads);
    remember_evaluation(ctx, m, E);
    return E;
}

void remember_evaluation(const DiagContext &ctx, const Model &m, const Eval &E) {
    if (!ctx.cache || has_user_effect(m)) return;
    std::string k;
    model_key(k, m);
    std::lock_guard<std::mutex> lk(ctx.cache->mu);
    FitCache &c = *ctx.cache;
    if (!c.evals.emplace(k, E).second) return;
    c.eval_order.push_back(std::move(k));
    if (c.eval_order.size() > FitCache::kEvals) {
        c.evals.erase(c.eval_order.front());
        c.eval_order.pop_front();
    }
}

// The cores this process may run on (its affinity mask: taskset, cgroup
// cpusets), at most 8.
int usable_cores() {
    cpu_set_t set;
    int n = 0;
    if (sched_getaffinity(0, sizeof set, &set) == 0) n = CPU_COUNT(&set);
    if (n <= 0) n = int(std::thread::hardware_concurrency());
    return std::clamp(n, 1, 8);
}

bool fit_all(const DiagContext &ctx, std::vector<FitJob> &jobs, std::string &err) {
    // Fits done before (bit-identical start and noise model): their result.
    std::vector<std::string> keys(jobs.size());
    std::vector<char> cached(jobs.size(), 0);
    if (ctx.cache) {
        std::lock_guard<std::mutex> lk(ctx.cache->mu);
        for (size_t k = 0; k < jobs.size(); ++k) {
            keys[k] = fit_key(ctx, jobs[k].m);
            if (jobs[k].one_step) keys[k] += "\2one step";
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
    // Every fit of the batch weighed by one model: its whitening once, not
    // per fit (each would evaluate that model at every position).
    DiagContext bc = ctx;
    if (bc.fo.weigh_with && !bc.fo.weights && serial.size() + shared.size() > 1)
        bc.fo.weights = fit_weights(*bc.fo.weigh_with, bc.pos, bc.fo);
    std::atomic<bool> cancelled{false};
    size_t failed = SIZE_MAX;
    {
        Batch b(bc, jobs, cancelled);
        b.run(serial, 1);
        failed = b.first_failed_;
    }
    if (!cancelled) {
        Batch b(bc, jobs, cancelled);
        b.run(shared, size_t(std::max(1, ctx.threads)));
        failed = b.first_failed_;
    }
    if (cancelled) { // (a user's cancel: no fit failed on its own)
        err = failed < jobs.size() && !jobs[failed].rep.message.empty() ? jobs[failed].rep.message : "fit cancelled";
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
    const size_t nt = std::min<size_t>(size_t(std::max(1, ctx.threads)), shared.size());
    // A failure stops every worker at its next job; on_threads rethrows it.
    on_threads(nt, [&] {
        for (size_t i; !failed && (i = next++) < shared.size();) {
            try {
                work(shared[i]);
            } catch (...) {
                failed = true;
                throw;
            }
        }
    });
}

} // namespace diag
} // namespace cdm
