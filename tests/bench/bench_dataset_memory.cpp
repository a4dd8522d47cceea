// Memory and time of reading and diagnosing a jig dataset, against the
// number of samples per position. Writes the seed's jig
// (25x25 holes, 5 heights, an exit_pulley effect hidden) with 100 and with
// 1,000 samples per position (312,500 and 3,125,000 rows), then measures each
// step in a fresh process (this program re-executed, so each peak RSS is the
// step's own, from wait4):
//
//   idle      the process doing nothing: the floor every peak includes
//   scan      the baseline: read the file in 1 MiB pieces, find each line
//             and strtod every field (the least any reader must do)
//   load      load_dataset: parse and accumulate per-position statistics
//   diagnose  load_dataset + diagnose (candidates, validation, per-position
//             arrays: what `cdm calib diagnose` does) + the JSON text
//
// and prints each as a ratio to its baseline in the same run: peak RSS of
// 3.1 M rows over 312,500 rows, load time over scan time. Not run by ctest
// (timings are not pass/fail on a shared machine): docs/performance.md.
//
//   ./build/tests/bench/bench_dataset_memory [DIR]   (DIR for the two CSVs, default /tmp)
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "calib/dataset/dataset.h"
#include "calib/diagnosis/diagnose.h"
#include "calib/dataset/simulate.h"
#include "io/file.h"

namespace {

double now() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The baseline: every byte read, every line found, every field converted.
bool scan(const std::string &path, double &rows, std::string &err) {
    cdm::io::FileReader f;
    if (!f.open(path, cdm::io::kDatasetMaxBytes, err, "dataset")) return false;
    std::vector<char> buf(size_t(1) << 20);
    size_t have = 0, off = 0;
    double sink = 0;
    rows = 0;
    for (;;) {
        const long n = f.pread(buf.data() + have, buf.size() - have - 1, off, err);
        if (n < 0) return false;
        off += size_t(n);
        have += size_t(n);
        buf[have] = '\0';
        char *b = buf.data(), *end = b + have;
        for (char *nl; (nl = static_cast<char *>(memchr(b, '\n', size_t(end - b)))) != nullptr; b = nl + 1) {
            *nl = '\0';
            for (char *p = b; p < nl;) {
                char *q;
                sink += std::strtod(p, &q);
                p = q == p ? p + 1 : q + 1; // past the comma (or a character strtod refused)
            }
            rows += 1;
        }
        have = size_t(end - b);
        std::memmove(buf.data(), b, have);
        if (n == 0) break;
    }
    if (sink == 0.123456789) std::puts(""); // keep the conversions
    rows -= 1;                             // the header
    return true;
}

// One step, in this process; prints "rows seconds" on stdout.
int child(const char *step, const char *path) {
    std::string err;
    double rows = 0;
    const double t0 = now();
    if (!std::strcmp(step, "idle")) {
    } else if (!std::strcmp(step, "scan")) {
        if (!scan(path, rows, err)) return std::fprintf(stderr, "%s\n", err.c_str()), 1;
    } else {
        cdm::Dataset d;
        if (!cdm::load_dataset(path, d, err)) return std::fprintf(stderr, "%s\n", err.c_str()), 1;
        rows = double(d.rows);
        if (!std::strcmp(step, "diagnose")) {
            nlohmann::json out;
            cdm::Model fitted{cdm::DeviceGeometry{}};
            if (!cdm::diagnose(d, cdm::DeviceGeometry{}, cdm::DiagnoseOptions{}, out, fitted, err))
                return std::fprintf(stderr, "%s\n", err.c_str()), 1;
            const std::string text = out.dump();
            if (text.empty()) return 1;
        }
    }
    std::printf("%.0f %.6f\n", rows, now() - t0);
    return 0;
}

struct Result {
    double rows = 0, seconds = 0, rss_mb = 0;
};

// Runs `step` on `path` in a fresh process (this program, re-executed).
bool measure(const char *self, const char *step, const std::string &path, Result &r) {
    int fds[2];
    if (pipe(fds) != 0) return false;
    const pid_t pid = fork();
    if (pid < 0) return false;
    if (pid == 0) {
        dup2(fds[1], STDOUT_FILENO);
        close(fds[0]);
        close(fds[1]);
        char *const argv[] = {const_cast<char *>(self), const_cast<char *>("--step"), const_cast<char *>(step),
                              const_cast<char *>(path.c_str()), nullptr};
        execv("/proc/self/exe", argv);
        _exit(127);
    }
    close(fds[1]);
    char out[128] = {0};
    size_t got = 0;
    for (ssize_t n; got + 1 < sizeof out && (n = read(fds[0], out + got, sizeof out - 1 - got)) > 0;) got += size_t(n);
    close(fds[0]);
    int status = 0;
    struct rusage ru;
    if (wait4(pid, &status, 0, &ru) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return false;
    r.rss_mb = double(ru.ru_maxrss) / 1024.0; // KiB on Linux
    return std::sscanf(out, "%lf %lf", &r.rows, &r.seconds) == 2;
}

} // namespace

int main(int argc, char **argv) {
    if (argc == 4 && !std::strcmp(argv[1], "--step")) return child(argv[2], argv[3]);
    const std::string dir = argc > 1 ? argv[1] : "/tmp";
    const int samples[2] = {100, 1000};
    std::string paths[2];
    cdm::Model truth{cdm::DeviceGeometry{}};
    std::string err;
    if (!truth.add_effect_random("exit_pulley", 7, err)) return std::fprintf(stderr, "%s\n", err.c_str()), 1;
    for (int k = 0; k < 2; ++k) {
        paths[k] = dir + "/cdm_bench_jig_" + std::to_string(samples[k]) + ".csv";
        cdm::JigSimOptions o;
        o.samples = samples[k];
        if (!cdm::simulate_jig_csv(truth, o, paths[k], {}, err)) return std::fprintf(stderr, "%s\n", err.c_str()), 1;
    }
    const char *steps[] = {"idle", "scan", "load", "diagnose"};
    Result r[2][4];
    for (int k = 0; k < 2; ++k)
        for (int s = 0; s < 4; ++s)
            if (!measure(argv[0], steps[s], paths[k], r[k][s]))
                return std::fprintf(stderr, "step %s on %s failed\n", steps[s], paths[k].c_str()), 1;
    for (auto &p : paths) unlink(p.c_str());

    std::printf("| step | %.0f rows: s | peak RSS MB | %.0f rows: s | peak RSS MB | RSS ratio | time ratio |\n",
                r[0][2].rows, r[1][2].rows);
    std::printf("|---|---|---|---|---|---|---|\n");
    for (int s = 0; s < 4; ++s) {
        char tr[32] = "-"; // idle: no time to compare
        if (r[0][s].seconds > 1e-3) std::snprintf(tr, sizeof tr, "%.2f", r[1][s].seconds / r[0][s].seconds);
        std::printf("| %s | %.3f | %.1f | %.3f | %.1f | %.2f | %s |\n", steps[s], r[0][s].seconds, r[0][s].rss_mb,
                    r[1][s].seconds, r[1][s].rss_mb, r[1][s].rss_mb / r[0][s].rss_mb, tr);
    }
    for (int k = 0; k < 2; ++k)
        std::printf("%.0f rows: scan %.2f M rows/s; load / scan time %.2f; diagnose / scan time %.1f\n", r[k][1].rows,
                    r[k][1].rows / r[k][1].seconds / 1e6, r[k][2].seconds / r[k][1].seconds,
                    r[k][3].seconds / r[k][1].seconds);
    return 0;
}
