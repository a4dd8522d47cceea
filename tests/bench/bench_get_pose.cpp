// cdm_get_pose against a plain copy of the same struct, while the sim's
// reader thread publishes at 1 kHz, and the parts it is made of, each alone:
// the clock reads a stale check could use and the sequence-lock copies of
// the pose with and without the raw report. Prints every time as a ratio to
// the memcpy at the end (docs/performance.md quotes them). Built, not timed
// in ctest.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <string>

#include "cdm/cdm.h"
#include "device/seqlock.h"

namespace {

cdm_device *g_dev = nullptr;
std::map<std::string, double> g_ns;

void BM_memcpy_pose(benchmark::State &state) {
    cdm_pose src{}, dst{};
    src.struct_size = sizeof src;
    for (auto _ : state) {
        benchmark::DoNotOptimize(&src);
        std::memcpy(&dst, &src, sizeof dst);
        benchmark::DoNotOptimize(&dst);
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_memcpy_pose);

template <clockid_t Clock>
void BM_clock(benchmark::State &state) {
    timespec ts;
    for (auto _ : state) {
        clock_gettime(Clock, &ts);
        benchmark::DoNotOptimize(ts);
    }
}
BENCHMARK(BM_clock<CLOCK_MONOTONIC>)->Name("BM_clock_monotonic");
BENCHMARK(BM_clock<CLOCK_MONOTONIC_COARSE>)->Name("BM_clock_monotonic_coarse");

// The sequence lock alone (no writer): what copying through atomic words
// costs for the pose with the raw report beside it (a snapshot of both)
// and for the pose alone (what cdm_get_pose reads).
struct PoseAndRaw {
    cdm_pose pose;
    cdm_raw raw;
};
template <class T>
void BM_seqlock(benchmark::State &state) {
    cdm::SeqLock<T> lock;
    T v{};
    lock.store(v);
    for (auto _ : state) {
        benchmark::DoNotOptimize(lock.load(v));
        benchmark::DoNotOptimize(&v);
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_seqlock<PoseAndRaw>)->Name("BM_seqlock_pose_and_raw");
BENCHMARK(BM_seqlock<cdm_pose>)->Name("BM_seqlock_pose");

void BM_cdm_get_pose(benchmark::State &state) {
    cdm_pose p{};
    p.struct_size = sizeof p;
    for (auto _ : state) {
        benchmark::DoNotOptimize(cdm_get_pose(g_dev, &p));
        benchmark::DoNotOptimize(&p);
        benchmark::ClobberMemory();
    }
}
BENCHMARK(BM_cdm_get_pose);

class Capture : public benchmark::ConsoleReporter {
public:
    void ReportRuns(const std::vector<Run> &runs) override {
        // CPU time: on a shared machine the wall time also counts the time
        // this thread waited for a core; the work itself is the CPU time.
        // With --benchmark_repetitions, the median of the repetitions.
        for (const Run &r : runs) {
            std::string name = r.benchmark_name();
            if (r.run_type == Run::RT_Aggregate) {
                if (r.aggregate_name != "median") continue;
                name = name.substr(0, name.size() - std::strlen("_median"));
            }
            g_ns[name] = r.GetAdjustedCPUTime();
        }
        ConsoleReporter::ReportRuns(runs);
    }
};

} // namespace

int main(int argc, char **argv) {
    if (cdm_open("sim:?motion=random", &g_dev) != CDM_OK) {
        std::fprintf(stderr, "cannot open sim: %s\n", cdm_thread_error());
        return 1;
    }
    cdm_pose p{};
    p.struct_size = sizeof p;
    cdm_wait_pose_after(g_dev, 0, 2000, &p);
    benchmark::Initialize(&argc, argv);
    Capture rep;
    benchmark::RunSpecifiedBenchmarks(&rep);
    cdm_close(g_dev);
    const double base = g_ns["BM_memcpy_pose"];
    if (base > 0) {
        std::printf("\nCPU time, ratio to the memcpy of cdm_pose (%.1f ns):\n", base);
        for (const auto &kv : g_ns) std::printf("  %-28s %7.1f ns  %6.1f\n", kv.first.c_str(), kv.second, kv.second / base);
    }
    return 0;
}
