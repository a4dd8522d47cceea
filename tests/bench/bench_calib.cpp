// The model-debugging path on the seed's full jig (25x25 holes, 5 heights,
// 100 samples = 312,500 rows). Baseline, in the same process: parsing the
// CSV text, the least any tool must do with the file. The diagnosis should
// stay a small multiple of it (docs/performance.md).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <unistd.h>

#include "calib/dataset/dataset.h"
#include "calib/diagnosis/diagnose.h"
#include "calib/fit/fit.h"
#include "calib/dataset/simulate.h"
#include "io/file.h"

namespace {

struct Fixture {
    std::string text;
    cdm::Dataset data;
    cdm::Model truth{cdm::DeviceGeometry{}};
    Fixture() {
        std::string err;
        truth.add_effect_random("exit_pulley", 7, err);
        cdm::JigSimOptions o;
        // The CSV text `cdm calib simulate` writes, for the parse baseline.
        char path[] = "/tmp/cdm_bench_calib_XXXXXX";
        const int fd = mkstemp(path);
        if (fd < 0 || close(fd) != 0 || !cdm::simulate_jig_csv(truth, o, path, {}, err) ||
            !cdm::io::read_file(path, cdm::io::kDatasetMaxBytes, text, err, "dataset") ||
            !cdm::parse_dataset(text, "bench", data, err)) {
            std::fprintf(stderr, "bench_calib: %s\n", err.c_str());
            std::exit(1);
        }
        unlink(path);
    }
};
Fixture &fx() {
    static Fixture f;
    return f;
}

void BM_ParseCsv_Baseline(benchmark::State &st) {
    auto &f = fx();
    for (auto _ : st) {
        cdm::Dataset d;
        std::string err;
        benchmark::DoNotOptimize(cdm::parse_dataset(f.text, "bench", d, err));
    }
    st.SetItemsProcessed(int64_t(st.iterations()) * int64_t(f.data.rows));
}

void BM_FitExitPulley(benchmark::State &st) {
    auto &f = fx();
    auto pos = cdm::prepare(f.data);
    for (auto _ : st) {
        cdm::Model m{cdm::DeviceGeometry{}};
        std::string err;
        m.add_effect("exit_pulley", {}, err);
        cdm::FitReport r;
        benchmark::DoNotOptimize(cdm::fit_model(m, pos, cdm::FitOptions{}, r));
    }
}

void BM_FitAnchorsAndJig(benchmark::State &st) {
    auto &f = fx();
    auto pos = cdm::prepare(f.data);
    for (auto _ : st) {
        cdm::Model m{cdm::DeviceGeometry{}};
        std::string err;
        m.add_effect("anchor_position", {}, err);
        m.add_effect("jig_misalignment", {}, err);
        cdm::FitReport r;
        benchmark::DoNotOptimize(cdm::fit_model(m, pos, cdm::FitOptions{}, r));
    }
}

void BM_DiagnoseFull(benchmark::State &st) {
    auto &f = fx();
    for (auto _ : st) {
        cdm::DiagnoseOptions o;
        nlohmann::json out;
        cdm::Model fitted{cdm::DeviceGeometry{}};
        std::string err;
        benchmark::DoNotOptimize(cdm::diagnose(f.data, f.truth.geometry(), o, out, fitted, err));
    }
}

} // namespace

BENCHMARK(BM_ParseCsv_Baseline)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FitExitPulley)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FitAnchorsAndJig)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DiagnoseFull)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK_MAIN();
