// cdm's model search beside the peer a Python user would write
// (tests/bench/search_peer.py: scipy.optimize.least_squares doing the same
// greedy forward search by BIC). Both search nominal + {cable_offset,
// cable_gain, exit_pulley} on the same per-position means and whitening (each
// position's four readings as one block) of a simulated jig hiding
// cable_gain and exit_pulley, each candidate fitted from the current
// model's parameters. cdm's side is its fit engine (fit_model: damped
// Gauss-Newton, then whitened SLSQP; AD Jacobian) with a step's candidates on 1
// and on --threads threads, as diagnose runs them (diag::fit_all).
//
//   bench_search [--holes 25] [--samples 100] [--repeat 3] [--threads 2]
//                [--python python3] [--script tests/bench/search_peer.py] [--dir /tmp] [--keep]
//
// Prints the median times and the ratio. Exits non-zero only on broken
// behaviour: the two searches add different effects, or a fit fails (the
// ctest smoke runs it on a small jig; speed is never pass/fail).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "calib/search/candidates.h"
#include "calib/search/context.h"
#include "calib/fit/fit.h"
#include "calib/dataset/simulate.h"

using namespace cdm;

namespace {

const std::vector<std::string> kCatalogue{"exit_pulley", "cable_gain", "cable_offset"};

struct Path {
    std::vector<std::string> added;
    std::vector<double> bic_change;
    double chi2 = 0;
};

// The greedy forward search on cdm's fit engine: each step fits every
// candidate not in the model (from the model's fitted values), takes the
// lowest BIC, stops when none lowers it.
bool cdm_search(const std::vector<PreparedPos> &pos, const FitOptions &fo, int threads, Path &out,
                std::string &err) {
    const DeviceGeometry g;
    Dataset none;
    diag::Grid grid;
    diag::DiagContext ctx{none, g, pos, grid, fo.jig_sigma, true, 0.05, fo, 4.0 * double(pos.size()), nullptr};
    ctx.threads = threads;
    Model cur{g};
    double chi2 = model_chi2(cur, pos, fo);
    int k_cur = 0;
    out = Path{};
    for (;;) {
        std::vector<diag::FitJob> jobs;
        for (auto &e : kCatalogue)
            if (!cur.has_effect(e)) jobs.emplace_back(model_with(cur, reading_effects(cur), e), e);
        if (jobs.empty()) break;
        if (!diag::fit_all(ctx, jobs, err)) return false;
        const diag::FitJob *best = nullptr;
        double best_bic = 0;
        for (auto &j : jobs) {
            const double b = ctx.bic(j.rep.chi2, j.rep.n_free) - ctx.bic(chi2, k_cur);
            if (!best || b < best_bic) {
                best = &j;
                best_bic = b;
            }
        }
        if (best_bic >= 0) break;
        out.added.push_back(best->stage);
        out.bic_change.push_back(best_bic);
        cur = best->m;
        chi2 = best->rep.chi2;
        k_cur = best->rep.n_free;
    }
    out.chi2 = chi2;
    return true;
}

// Per position: the nominal cable vectors, the mean readings, and the
// whitening fit_model weighs the nominal model's four readings with: the
// inverse of the lower Cholesky factor of their covariance (the pots' noise
// of the mean and the position's jig error through the readings' position
// derivative), its ten lower entries row by row.
bool write_means(const std::vector<PreparedPos> &pos, const FitOptions &fo, const std::string &path,
                 std::string &err) {
    const DeviceGeometry g;
    const Model m{g};
    std::ofstream f(path);
    f << "d1x,d1y,d1z,d2x,d2y,d2z,d3x,d3y,d3z,d4x,d4y,d4z,l1,l2,l3,l4,w00,w10,w11,w20,w21,w22,w30,w31,w32,w33\n";
    f.precision(17);
    for (auto &pp : pos) {
        double P[3], y[4], J[12];
        m.jig_to_device(pp.ref.data(), P);
        if (m.readings_jacobian(P, pp.t_s, y, J) != 0) {
            err = "nominal model fails at a jig position";
            return false;
        }
        for (int i = 0; i < 4; ++i) {
            const auto A = g.anchor(i), h = g.holder(i);
            for (int k = 0; k < 3; ++k) f << P[k] + h[size_t(k)] - A[size_t(k)] << ",";
        }
        for (int c = 0; c < 4; ++c) f << pp.mean(c) << ",";
        const Eigen::Matrix<double, 4, 3, Eigen::RowMajor> dP = Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>(J);
        Eigen::Matrix4d C = pp.cov_mean;
        C.diagonal() = pp.var_mean;
        C += dP * fo.jig_sigma.cwiseAbs2().asDiagonal() * dP.transpose();
        const Eigen::Matrix4d L = Eigen::LLT<Eigen::Matrix4d>(C).matrixL().solve(Eigen::Matrix4d::Identity());
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c <= r; ++c) f << L(r, c) << (r == 3 && c == 3 ? "\n" : ",");
    }
    f.close();
    if (!f) err = "cannot write " + path;
    return bool(f);
}

int run_python(const std::string &py, const std::string &script, const std::string &in, const std::string &out) {
    const pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        std::vector<char *> argv{const_cast<char *>(py.c_str()), const_cast<char *>(script.c_str()),
                                 const_cast<char *>(in.c_str()), const_cast<char *>(out.c_str()), nullptr};
        execvp(argv[0], argv.data());
        _exit(127);
    }
    int st = 0;
    if (waitpid(pid, &st, 0) < 0) return -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

std::string join(const std::vector<std::string> &v) {
    std::string s;
    for (auto &e : v) s += (s.empty() ? "" : " + ") + e;
    return s.empty() ? "(nominal)" : s;
}

} // namespace

int main(int argc, char **argv) {
    int holes = 25, samples = 100, repeat = 3, threads = 2;
    bool keep = false; // leave the means and the peer's result in --dir
    std::string py = "python3", script = std::string(CDM_SOURCE_DIR) + "/tests/bench/search_peer.py", dir = "/tmp";
    for (int k = 1; k < argc; ++k) {
        const std::string a = argv[k];
        auto val = [&]() -> std::string {
            if (k + 1 >= argc) {
                std::fprintf(stderr, "bench_search: %s needs a value\n", a.c_str());
                std::exit(2);
            }
            return argv[++k];
        };
        if (a == "--holes") holes = std::atoi(val().c_str());
        else if (a == "--samples") samples = std::atoi(val().c_str());
        else if (a == "--repeat") repeat = std::atoi(val().c_str());
        else if (a == "--threads") threads = std::atoi(val().c_str());
        else if (a == "--python") py = val();
        else if (a == "--script") script = val();
        else if (a == "--dir") dir = val();
        else if (a == "--keep") keep = true;
        else {
            std::fprintf(stderr, "bench_search: unknown option %s\n", a.c_str());
            return 2;
        }
    }
    if (holes < 3 || samples < 2 || repeat < 1 || threads < 1) {
        std::fprintf(stderr, "bench_search: --holes >= 3, --samples >= 2, --repeat >= 1, --threads >= 1\n");
        return 2;
    }
    std::string err;
    Model truth{DeviceGeometry{}};
    if (!truth.add_effect_random("cable_gain", 11, err) || !truth.add_effect_random("exit_pulley", 12, err)) {
        std::fprintf(stderr, "bench_search: %s\n", err.c_str());
        return 1;
    }
    JigSimOptions so;
    so.n = holes;
    so.pitch_mm = 5.0 * 25 / holes;
    so.samples = samples;
    so.seed = 3;
    Dataset d;
    if (!simulate_jig(truth, so, d, err)) {
        std::fprintf(stderr, "bench_search: %s\n", err.c_str());
        return 1;
    }
    const auto pos = prepare(d);
    FitOptions fo; // the jig tolerance fixed at 0.03 mm on both sides
    const std::string means = dir + "/cdm_bench_search_" + std::to_string(getpid()) + ".csv";
    const std::string result = means + ".json";
    if (!write_means(pos, fo, means, err)) {
        std::fprintf(stderr, "bench_search: %s\n", err.c_str());
        return 1;
    }
    std::printf("jig: %d x %d holes, 5 heights, %d samples (%zu rows, %zu positions); hidden cable_gain + exit_pulley\n",
                holes, holes, samples, size_t(d.rows), pos.size());
    std::printf("search: greedy forward by BIC over cable_offset, cable_gain, exit_pulley; median of %d\n\n", repeat);

    Path p1, pt;
    std::vector<double> t1, tt, tp;
    std::vector<std::string> peer_effects;
    for (int r = 0; r < repeat; ++r) {
        auto a = std::chrono::steady_clock::now();
        if (!cdm_search(pos, fo, 1, p1, err)) {
            std::fprintf(stderr, "bench_search: cdm search: %s\n", err.c_str());
            return 1;
        }
        auto b = std::chrono::steady_clock::now();
        if (!cdm_search(pos, fo, threads, pt, err)) {
            std::fprintf(stderr, "bench_search: cdm search: %s\n", err.c_str());
            return 1;
        }
        auto c = std::chrono::steady_clock::now();
        t1.push_back(std::chrono::duration<double>(b - a).count());
        tt.push_back(std::chrono::duration<double>(c - b).count());
        const int rc = run_python(py, script, means, result);
        if (rc != 0) {
            std::fprintf(stderr, "bench_search: %s %s exited with %d (scipy installed? scripts/setup.sh)\n", py.c_str(),
                         script.c_str(), rc);
            return 1;
        }
        std::ifstream f(result);
        nlohmann::json j;
        try {
            f >> j;
        } catch (const std::exception &e) {
            std::fprintf(stderr, "bench_search: %s: %s\n", result.c_str(), e.what());
            return 1;
        }
        tp.push_back(j["seconds"].get<double>());
        peer_effects.clear();
        for (auto &e : j["path"]) peer_effects.push_back(e["added"].get<std::string>());
        if (r == repeat - 1) {
            std::printf("peer path:");
            for (auto &e : j["path"])
                std::printf(" + %s (BIC %.1f)", e["added"].get<std::string>().c_str(), e["bic_change"].get<double>());
            std::printf("; chi2 %.2f\n", j["chi2"].get<double>());
        }
    }
    if (keep) {
        std::printf("kept %s and %s\n", means.c_str(), result.c_str());
    } else {
        std::remove(means.c_str());
        std::remove(result.c_str());
    }
    std::printf("cdm path: ");
    for (size_t k = 0; k < p1.added.size(); ++k) std::printf(" + %s (BIC %.1f)", p1.added[k].c_str(), p1.bic_change[k]);
    std::printf("; chi2 %.2f\n\n", p1.chi2);
    const double m1 = median(t1), mt = median(tt), mp = median(tp);
    std::printf("| search | median time | ratio to scipy |\n|---|---|---|\n");
    std::printf("| scipy.optimize.least_squares (peer, baseline) | %.3f s | 1 |\n", mp);
    std::printf("| cdm, 1 thread | %.3f s | %.1f |\n", m1, mp / m1);
    std::printf("| cdm, %d threads | %.3f s | %.1f |\n", threads, mt, mp / mt);
    // Broken behaviour: the searches disagree on what the data hide (the
    // same criterion on the same numbers; the tiny prior and the per-fit
    // weights of cdm cannot change which effect lowers the BIC by >> 10).
    auto sorted = [](std::vector<std::string> v) {
        std::sort(v.begin(), v.end());
        return v;
    };
    if (sorted(p1.added) != sorted(peer_effects) || p1.added != pt.added) {
        std::fprintf(stderr, "bench_search: the searches disagree: cdm %s, cdm (%d threads) %s, peer %s\n",
                     join(p1.added).c_str(), threads, join(pt.added).c_str(), join(peer_effects).c_str());
        return 1;
    }
    return 0;
}
