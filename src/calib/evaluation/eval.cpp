// See eval.h.
#include "calib/evaluation/eval.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <mutex>
#include <system_error>
#include <thread>

#include "calib/fit/parallel.h"
#include "model/effect.h"

namespace cdm {
namespace diag {

namespace {
// The rows handed on in chunks (position index, readings), in file order.
struct SampleChunk {
    std::vector<size_t> j;
    std::vector<std::array<double, 4>> l;
};
using ChunkVisit = std::function<void(const SampleChunk &)>;
constexpr size_t kChunk = 4096;

// for_each_sample, the rows handed to visit in chunks of kChunk, in file
// order, on this thread.
bool for_each_sample_chunk(const Dataset &d, const ChunkVisit &visit, std::string &err) {
    SampleChunk c;
    c.j.reserve(kChunk);
    c.l.reserve(kChunk);
    const bool ok = for_each_sample(
        d,
        [&](size_t j, const double *l) {
            c.j.push_back(j);
            c.l.push_back({l[0], l[1], l[2], l[3]});
            if (c.j.size() == kChunk) {
                visit(c);
                c.j.clear();
                c.l.clear();
            }
        },
        err);
    if (ok && !c.j.empty()) visit(c);
    return ok;
}

// The same with visit run on a second thread: each chunk is visited there
// while the next is read here (two buffers). The chunks are the same, in
// the same order, so what the visits compute is the same bit for bit; the
// pass takes about the longer of the reading and the visits instead of
// their sum. In turn on this thread when no thread can be started.
bool for_each_sample_piped(const Dataset &d, const ChunkVisit &visit, std::string &err) {
    SampleChunk buf[2];
    for (auto &b : buf) {
        b.j.reserve(kChunk);
        b.l.reserve(kChunk);
    }
    std::mutex mu;
    std::condition_variable cv;
    int ready = -1;    // the chunk handed over, not yet taken
    bool busy = false; // the visiting thread is in a chunk
    bool end = false;
    std::exception_ptr thrown;
    auto consume = [&] {
        for (;;) {
            int b;
            {
                std::unique_lock<std::mutex> lk(mu);
                cv.wait(lk, [&] { return ready >= 0 || end; });
                if (ready < 0) return;
                b = ready;
                ready = -1;
                busy = true;
            }
            cv.notify_all();
            try {
                visit(buf[b]);
            } catch (...) {
                std::lock_guard<std::mutex> lk(mu);
                if (!thrown) thrown = std::current_exception();
            }
            {
                std::lock_guard<std::mutex> lk(mu);
                busy = false;
            }
            cv.notify_all();
        }
    };
    std::thread worker;
    try {
        worker = std::thread(consume);
    } catch (const std::system_error &) {
        return for_each_sample_chunk(d, visit, err);
    }
    int fill = 0;
    // Hands buf[fill] over once the other buffer is visited; fills that one next.
    auto hand = [&] {
        {
            std::unique_lock<std::mutex> lk(mu);
            cv.wait(lk, [&] { return ready < 0 && !busy; });
            if (thrown) std::rethrow_exception(thrown); // a visit threw: the pass ends here
            ready = fill;
        }
        cv.notify_all();
        fill = 1 - fill;
        buf[fill].j.clear();
        buf[fill].l.clear();
    };
    // The visiting thread ends once every chunk handed over is visited.
    auto finish = [&] {
        {
            std::unique_lock<std::mutex> lk(mu);
            cv.wait(lk, [&] { return ready < 0 && !busy; });
            end = true;
        }
        cv.notify_all();
        worker.join();
    };
    bool ok = false;
    try {
        ok = for_each_sample(
            d,
            [&](size_t j, const double *l) {
                buf[fill].j.push_back(j);
                buf[fill].l.push_back({l[0], l[1], l[2], l[3]});
                if (buf[fill].j.size() == kChunk) hand();
            },
            err);
        if (ok && !buf[fill].j.empty()) hand();
    } catch (...) {
        finish();
        throw;
    }
    finish();
    if (thrown) std::rethrow_exception(thrown);
    return ok;
}

// The direction the columns of a reading Jacobian J leave out: the four
// signed 3 x 3 minors of J (the cross product's four-dimensional kin), unit
// length; none when the columns are not independent.
Eigen::Vector4d left_out_direction(const Eigen::Matrix<double, 4, 3, Eigen::RowMajor> &J) {
    Eigen::Vector4d dir;
    for (int i = 0; i < 4; ++i) {
        Eigen::Matrix3d M;
        for (int r = 0, k = 0; r < 4; ++r)
            if (r != i) M.row(k++) = J.row(r);
        dir(i) = (i % 2 ? -1.0 : 1.0) * M.determinant();
    }
    const double nd = dir.norm();
    dir = nd > 0 ? Eigen::Vector4d(dir / nd) : Eigen::Vector4d::Zero();
    return dir;
}

Eval init_eval(size_t P) {
    Eval E;
    E.res.assign(P, V3::Zero());
    E.Jp.assign(P, Eigen::Matrix<double, 3, 4>::Zero());
    E.var_mean.assign(P, V3::Constant(1e-6));
    E.ok.assign(P, 0);
    E.est.assign(P, V3::Zero());
    E.mis.assign(P, 0.0);
    E.mis_var.assign(P, 0.0);
    E.mis_dir.assign(P, Eigen::Vector4d::Zero());
    return E;
}
} // namespace

// Per-position residuals by FK of the mean readings; per-sample statistics
// through the local linearisation e_s = res + Jp (l_s - mean), exact to
// second order in the noise (1e-4 mm at 0.05 mm noise). Over a position's
// samples sum(l_s - mean) = 0 and sum (Jp_a (l_s - mean))^2 = Jp_a M Jp_a'
// with M the co-moment matrix (n - 1) cov: the moments need no sample.
Eval evaluate(const Model &m, const std::vector<PreparedPos> &pos, int threads) {
    const size_t P = pos.size();
    Eval E = init_eval(P);
    // Every position's FK of its mean readings, at its acquisition time
    // (effects that drift in time, pot_drift, are undone as of when it was
    // measured), then the reading Jacobians at the estimates: position()
    // and readings_jacobian() at each, or over all positions at once where
    // a user effect works on arrays (Model::positions).
    std::vector<double> l(4 * P), ts(P), est(3 * P), y(4 * P), dr(12 * P);
    std::vector<int> st(P), stj(P);
    for (size_t j = 0; j < P; ++j) {
        for (int c = 0; c < 4; ++c) l[4 * j + size_t(c)] = pos[j].mean(c);
        ts[j] = pos[j].t_s;
    }
    // Each position's alone: on `threads` threads in contiguous ranges when
    // no user effect's callback is called (it need not be reentrant).
    size_t T = threads > 1 ? size_t(threads) : 1;
    for (size_t k = 0; k < m.effect_count(); ++k)
        if (m.effect_desc(k).stage == Stage::User) T = 1;
    constexpr size_t kPositionsPerThread = 256;
    in_ranges(P, T, kPositionsPerThread, [&](size_t a, size_t b) {
        m.positions(b - a, l.data() + 4 * a, ts.data() + a, est.data() + 3 * a, st.data() + a);
        return true;
    });
    // Only the converged ones need a Jacobian: pack them.
    std::vector<size_t> conv;
    std::vector<double> pc, tc;
    for (size_t j = 0; j < P; ++j)
        if (st[j] == 0) {
            conv.push_back(j);
            pc.insert(pc.end(), {est[3 * j], est[3 * j + 1], est[3 * j + 2]});
            tc.push_back(ts[j]);
        }
    in_ranges(conv.size(), T, kPositionsPerThread, [&](size_t a, size_t b) {
        m.readings_jacobians(b - a, pc.data() + 3 * a, tc.data() + a, y.data() + 4 * a, dr.data() + 12 * a, stj.data() + a);
        return true;
    });
    std::vector<size_t> slot(P, 0);
    size_t n_reading = 0;
    for (size_t c = 0; c < conv.size(); ++c) slot[conv[c]] = c;
    for (size_t j = 0; j < P; ++j) {
        if (st[j] != 0) {
            E.bad_samples += size_t(pos[j].n);
            continue;
        }
        const double *p = &est[3 * j];
        double t[3];
        m.jig_to_device(pos[j].ref.data(), t);
        E.est[j] = V3(p[0], p[1], p[2]);
        E.res[j] = E.est[j] - V3(t[0], t[1], t[2]);
        // The model's own derivative (automatic differentiation through the
        // built-ins); NaN when a user effect fails, so nothing downstream
        // mistakes it for a number.
        Eigen::Matrix<double, 4, 3, Eigen::RowMajor> J = Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>(&dr[12 * slot[j]]);
        if (stj[slot[j]] != 0) J.setConstant(std::numeric_limits<double>::quiet_NaN());
        Eigen::Matrix3d H = J.transpose() * J;
        E.Jp[j] = H.inverse() * J.transpose();
        // Covariance of the mean readings (cross-cable terms included), as
        // prepare() shrank it toward the pooled one and added quantisation.
        // Not the larger of it and the position's own: with few samples that
        // maximum is biased up, and weights from it inflate the chi-square.
        // The diagonal is var_mean, the fit's own weights, however the
        // position was built.
        Eigen::Matrix4d Cl = pos[j].cov_mean;
        Cl.diagonal() = pos[j].var_mean;
        const Eigen::Matrix3d C = E.Jp[j] * Cl * E.Jp[j].transpose();
        for (int a = 0; a < 3; ++a) E.var_mean[j](a) = std::max(C(a, a), 1e-10);
        if (J.allFinite()) {
            const Eigen::Vector4d dir = left_out_direction(J);
            const Eigen::Vector4d r = pos[j].mean - Eigen::Map<const Eigen::Vector4d>(&y[4 * slot[j]]);
            E.mis[j] = dir.dot(r);
            E.mis_var[j] = dir.dot(Cl * dir);
            E.mis_dir[j] = dir;
        }
        if (pos[j].reading_var > 0) {
            const Eigen::Matrix3d R = pos[j].reading_var * E.Jp[j] * E.Jp[j].transpose();
            for (int a = 0; a < 3; ++a) E.reading_var(a) += R(a, a);
            ++n_reading;
        }
        E.ok[j] = 1;
        const double n = pos[j].n;
        const Eigen::Matrix3d S = E.Jp[j] * (pos[j].cov * (n - 1)) * E.Jp[j].transpose();
        for (int a = 0; a < 3; ++a) {
            const double r = E.res[j](a);
            E.err[a].add_moments(n, n * r, n * r * r + S(a, a));
            E.within[a].add_moments(n, 0.0, S(a, a));
        }
    }
    for (int a = 0; a < 3; ++a) E.err[a].mx = E.within[a].mx = std::numeric_limits<double>::quiet_NaN();
    if (n_reading > 0) E.reading_var /= double(n_reading);
    return E;
}

// The seed's procedure is per sample (eq. 1-3 on each sample's readings,
// optionally the ellipsoid of eq. 4 subtracted from x), and so is a maximum:
// both read the rows again.
bool sample_pass(const Dataset &d, const std::vector<PreparedPos> &pos, const std::vector<Eval *> &linear,
                 const std::vector<SeedRequest> &seeds, std::string &err, bool piped) {
    const size_t P = pos.size();
    for (Eval *E : linear)
        for (int a = 0; a < 3; ++a) E->err[a].mx = E->within[a].mx = 0;
    // An evaluation the same as one before it in what the maxima read (which
    // positions, their residuals and linearisations, bit for bit: the
    // recommended model's candidates are the user's model's when the search
    // stays there) is not visited again; its maxima are copied after.
    auto bits = [](const auto &a, const auto &b) {
        return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof a[0]) == 0;
    };
    std::vector<Eval *> visited;
    std::vector<std::pair<Eval *, const Eval *>> copies; // (to, from)
    for (Eval *E : linear) {
        auto same = std::find_if(visited.begin(), visited.end(), [&](const Eval *U) {
            return U == E || (bits(U->ok, E->ok) && bits(U->res, E->res) && bits(U->Jp, E->Jp));
        });
        if (same == visited.end()) visited.push_back(E);
        else if (*same != E) copies.emplace_back(E, *same);
    }
    std::vector<Eval> sv(seeds.size(), init_eval(P));
    std::vector<std::vector<V3>> sum(seeds.size(), std::vector<V3>(P, V3::Zero()));
    std::vector<std::vector<int>> cnt(seeds.size(), std::vector<int>(P, 0));
    // A chunk at a time: each evaluation's maxima over the chunk's samples
    // (a maximum is the same in any order), then the seeds' sums sample by
    // sample, in file order.
    std::vector<Eigen::Vector4d> dl;
    auto visit = [&](const SampleChunk &c) {
        const size_t n = c.j.size();
        dl.resize(n);
        for (size_t s = 0; s < n; ++s) {
            const size_t j = c.j[s];
            if (j >= P) continue; // for_each_sample checked the positions; pos comes from the same dataset
            for (int k = 0; k < 4; ++k) dl[s](k) = c.l[s][size_t(k)] - pos[j].mean(k);
        }
        for (Eval *E : visited) {
            double me[3] = {0, 0, 0}, mw[3] = {0, 0, 0};
            for (size_t s = 0; s < n; ++s) {
                const size_t j = c.j[s];
                if (j >= P || !E->ok[j]) continue;
                const V3 dev = E->Jp[j] * dl[s];
                for (int a = 0; a < 3; ++a) {
                    me[a] = std::max(me[a], std::fabs(E->res[j](a) + dev(a)));
                    mw[a] = std::max(mw[a], std::fabs(dev(a)));
                }
            }
            for (int a = 0; a < 3; ++a) {
                E->err[a].add_extreme(me[a]);
                E->within[a].add_extreme(mw[a]);
            }
        }
        for (size_t s = 0; s < n; ++s) {
            const size_t j = c.j[s];
            if (j >= P) continue;
            const double *ls = c.l[s].data();
            for (size_t k = 0; k < seeds.size(); ++k) {
                double p[3];
                if (!triangulate(*seeds[k].geometry, ls, p)) {
                    ++sv[k].bad_samples;
                    continue;
                }
                if (seeds[k].ellipsoid) p[0] -= seeds[k].ellipsoid->xc(p[1], p[2]);
                for (int a = 0; a < 3; ++a) sv[k].err[a].add(p[a] - pos[j].ref(a));
                sum[k][j] += V3(p[0], p[1], p[2]);
                ++cnt[k][j];
            }
        }
    };
    if (!(piped ? for_each_sample_piped(d, visit, err) : for_each_sample_chunk(d, visit, err))) return false;
    for (auto &[to, from] : copies)
        for (int a = 0; a < 3; ++a) {
            to->err[a].mx = from->err[a].mx;
            to->within[a].mx = from->within[a].mx;
        }
    for (size_t k = 0; k < seeds.size(); ++k) {
        Eval &E = sv[k];
        for (size_t j = 0; j < P; ++j) {
            if (cnt[k][j] == 0) continue;
            E.est[j] = sum[k][j] / cnt[k][j];
            E.res[j] = E.est[j] - pos[j].ref;
            E.ok[j] = 1;
        }
        *seeds[k].out = std::move(E);
    }
    return true;
}

bool evaluate_seed(const DeviceGeometry &g, const Dataset &d, const std::vector<PreparedPos> &pos,
                   const Ellipsoid *ell, Eval &out, std::string &err, bool piped) {
    return sample_pass(d, pos, {}, {{&g, ell, &out}}, err, piped);
}

// The seed's eq. 5: the ellipsoid fitted to the x error of an evaluation
// over its estimated y, z, each position weighted by its sample count.
Ellipsoid ellipsoid_on(const Eval &E, const std::vector<PreparedPos> &pos) {
    std::vector<double> y, z, x, w;
    for (size_t j = 0; j < pos.size(); ++j)
        if (E.ok[j]) {
            y.push_back(E.est[j](1));
            z.push_back(E.est[j](2));
            x.push_back(E.res[j](0));
            w.push_back(pos[j].n);
        }
    return fit_ellipsoid(y, z, x, w);
}

V3 noise_floor(const Eval &E, const V3 &jig) {
    V3 n;
    for (int a = 0; a < 3; ++a) {
        const double w = E.within[a].n > 1 ? E.within[a].ss / E.within[a].n : 0;
        n(a) = std::sqrt(w + jig(a) * jig(a) + E.reading_var(a));
    }
    return n;
}

} // namespace diag
} // namespace cdm
