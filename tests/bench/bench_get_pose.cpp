// cdm_get_pose against a plain copy of the same struct, while the sim's
// reader thread publishes at 1 kHz: what the seqlock, the clock read for the
// stale check and the struct_size handling cost a haptic loop. Prints the
// ratio at the end (docs/performance.md quotes it). Built, not timed in ctest.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstring>

#include "cdm/cdm.h"

namespace {

cdm_device *g_dev = nullptr;
double g_ns[2] = {0, 0};

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
        for (const Run &r : runs) {
            const double ns = r.GetAdjustedRealTime();
            if (r.benchmark_name() == "BM_memcpy_pose") g_ns[0] = ns;
            if (r.benchmark_name() == "BM_cdm_get_pose") g_ns[1] = ns;
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
    cdm_wait_pose(g_dev, 2000, &p);
    benchmark::Initialize(&argc, argv);
    Capture rep;
    benchmark::RunSpecifiedBenchmarks(&rep);
    cdm_close(g_dev);
    if (g_ns[0] > 0 && g_ns[1] > 0)
        std::printf("cdm_get_pose: %.1f ns, memcpy of cdm_pose: %.1f ns, ratio %.1f\n", g_ns[1], g_ns[0],
                    g_ns[1] / g_ns[0]);
    return 0;
}
