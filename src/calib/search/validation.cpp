// See validation.h.
#include "calib/search/validation.h"

#include <atomic>
#include <thread>
#include <vector>

namespace cdm {
namespace diag {

using nlohmann::json;

namespace {
json rms3(const Acc a[3]) {
    return {{"x", a[0].to_json()["rms"]}, {"y", a[1].to_json()["rms"]}, {"z", a[2].to_json()["rms"]}};
}
} // namespace

bool validate_heights(const DiagContext &ctx, const Model &model, const Eval &in_sample, json &out, std::string &err) {
    out = nullptr;
    const size_t P = ctx.pos.size();
    const auto &heights = ctx.data.heights;
    if (!ctx.G.layered || heights.size() <= 1 || heights.size() > 20) return true;
    // The folds are independent fits: on ctx.threads threads, each writing
    // its own; only the calling thread reports progress, and a cancel there
    // stops the others. Read in height order, so nothing depends on the
    // threads.
    const size_t H = heights.size();
    std::vector<Model> mv(H, model);
    std::vector<FitReport> rv(H);
    std::vector<Eval> ev(H);
    std::vector<std::vector<char>> use(H);
    std::vector<char> ok(H, 0);
    const std::thread::id caller = std::this_thread::get_id();
    std::atomic<bool> cancelled{false};
    const bool user = has_user_effect(model);
    for_each_parallel(
        ctx, H, [&](size_t) { return user; },
        [&](size_t h) {
            FitOptions f = ctx.fo;
            f.use.assign(P, 0);
            for (size_t j = 0; j < P; ++j) f.use[j] = ctx.G.height_index[j] != int(h);
            f.progress = [&](double fr) {
                if (std::this_thread::get_id() == caller && !ctx.report("validation", fr)) cancelled = true;
                return !cancelled.load();
            };
            if (cancelled) return;
            ok[h] = fit_model(mv[h], ctx.pos, f, rv[h]);
            if (!ok[h]) {
                cancelled = true;
                return;
            }
            ev[h] = evaluate(mv[h], ctx.pos);
            use[h] = std::move(f.use);
        });
    if (cancelled) {
        // The first fold that failed on its own, in height order; the
        // others were stopped because of it (or by the caller's cancel).
        err = "fit cancelled";
        for (size_t h = 0; h < H; ++h)
            if (!ok[h] && !rv[h].message.empty() && rv[h].message != "fit cancelled") {
                err = rv[h].message;
                break;
            }
        return false;
    }
    Acc held[3];
    json folds = json::array();
    for (size_t h = 0; h < H; ++h) {
        Acc f[3];
        for (size_t j = 0; j < P; ++j)
            if (!use[h][j] && ev[h].ok[j])
                for (int a = 0; a < 3; ++a) {
                    f[a].add(ev[h].res[j](a));
                    held[a].add(ev[h].res[j](a));
                }
        folds.push_back({{"height", heights[h]}, {"rms_mm", rms3(f)}});
    }
    Acc ins[3];
    for (size_t j = 0; j < P; ++j)
        if (in_sample.ok[j])
            for (int a = 0; a < 3; ++a) ins[a].add(in_sample.res[j](a));
    out = {{"method", "leave-one-height-out"}, {"folds", folds}, {"rms_mm", rms3(held)}, {"in_sample_rms_mm", rms3(ins)}};
    return true;
}

} // namespace diag
} // namespace cdm
