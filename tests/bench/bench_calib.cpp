// The model-debugging path on the seed's full jig (25x25 holes, 5 heights,
// 100 samples = 312,500 rows). Baseline, in the same process: parsing the
// CSV text, the least any tool must do with the file. The diagnosis should
// stay a small multiple of it (docs/performance.md).
#include <benchmark/benchmark.h>

#include "calib/dataset.h"
#include "calib/diagnose.h"
#include "calib/fit.h"
#include "calib/simulate.h"

namespace {

struct Fixture {
    std::string text;
    cdm::Dataset data;
    cdm::Model truth{cdm::DeviceGeometry{}};
    Fixture() {
        std::string err;
        truth.add_effect_random("exit_pulley", 7, err);
        cdm::JigSimOptions o;
        cdm::simulate_jig(truth, o, data, err);
        // the same rows as text, for the parse baseline
        char buf[160];
        text = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
        for (auto &p : data.pos)
            for (int s = 0; s < p.n; ++s) {
                auto &l = data.samples[p.first + size_t(s)];
                std::snprintf(buf, sizeof buf, "%ld,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", p.point, p.ref[0], p.ref[1],
                              p.ref[2], l[0], l[1], l[2], l[3]);
                text += buf;
            }
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
