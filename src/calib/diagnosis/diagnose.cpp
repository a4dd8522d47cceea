// See diagnose.h. diagnose() runs the stages in order (stages.h): the
// user's model fitted (fit_calibration), the candidates on top of it
// (calib/search/candidates.h), the model search (calib/search/search.h), the
// review (review.h), the held-out heights (validation.h), the residual
// analysis and what lies beyond the catalogue (calib/beyond/), the pass over
// every sample, the verdict (verdict.h, words.cpp); report.cpp writes the
// JSON of docs/calibration.md from what they returned.
#include "calib/diagnosis/diagnose.h"

#include <chrono>
#include <optional>

#include "calib/calibration/fit_outliers.h"
#include "calib/diagnosis/stages.h"
#include "calib/search/review.h"
#include "calib/search/validation.h"
#include "model/effect.h"

namespace cdm {

using nlohmann::json;
using namespace diag;

namespace {

// Candidates' own jig tolerance is capped as in fit_calibration(): a
// machined plate is within ~0.05 mm, and white scatter beyond that is not
// the jig's (without repeated samples there is nothing to cap against).
constexpr double kJigCapMm = 0.05;

// The user's model's own tests, the chi-square every candidate and review
// refit is compared with, and its noise floor.
void judge_user_model(UserModel &u) {
    const CalibrationFit &cf = u.cf;
    const Model &model = cf.model;
    u.model_free = cf.report.n_free;
    for (size_t k = 0; k < model.effect_count(); ++k)
        if (model.effect_desc(k).stage == Stage::Position) u.model_free -= int(model.effect_desc(k).params.size());
    u.v = judge(cf.fitted, cf.grid, cf.jig, cf.report.n_free, cf.fit_options.hole_sigma);
    u.chi2 = model_chi2(model, cf.pos, cf.fit_options);
    u.noise = noise_floor(cf.fitted, cf.jig);
}

// One round of the diagnosis on `data`; `outliers`: the positions the
// model and their neighbours both disown (find_outliers), for diagnose() to
// set aside; reading_retry: the readings' own error to run it again with.
bool diagnose_data(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, json &out,
                   Model &fitted, std::string &err, size_t already, size_t read, std::vector<Outlier> &outliers,
                   Declined &declined, std::optional<ReadingNoise> &reading_retry) {
    reading_retry.reset();
    const auto t0 = std::chrono::steady_clock::now();
    UserModel u(g);
    if (!fit_user_model(data, g, opt, u, err)) return false;
    CalibrationFit &cf = u.cf;
    DiagContext ctx{data, g, cf.pos, cf.grid, cf.jig, u.user_jig, u.repeats ? kJigCapMm : INFINITY, cf.fit_options,
                    4.0 * double(cf.pos.size()), opt.progress};
    ctx.threads = opt.threads > 0 ? opt.threads : usable_cores();
    remember_evaluation(ctx, cf.model, cf.fitted); // fit_calibration's evaluate(model, pos), as yet untouched
    judge_user_model(u);
    // --- candidates on top of the user's model. Their fits, and the
    // review's, weighed as the user's model weighs the data, as u.chi2 is
    // (calib/search/search.cpp says why).
    DiagContext uc = ctx;
    uc.fo.weigh_with = &cf.model;
    std::vector<Candidate> cands;
    if (opt.candidates) {
        if (!score_candidates(uc, cf.model, u.model_free, u.chi2, cf.fitted, "candidates", cands, err)) return false;
        mark_confusions(cf.fitted, cf.jig, cands);
    }
    // --- the model search
    SearchStage s(ctx);
    s.on = opt.search && opt.candidates;
    if (s.on && !search_stage(cf.model, cf.report, u.user_jig, s, err)) return false;
    // --- model review
    json review = json::array();
    if (!review_model(uc, cf.model, u.model_free, u.chi2, review, err, opt.candidates ? &cands : nullptr))
        return false;
    // --- leave-one-height-out validation
    json validation = nullptr;
    if (opt.validation && cf.report.n_free > 0 && !validate_heights(ctx, cf.model, cf.fitted, validation, err))
        return false;
    // --- beyond the catalogue
    Residuals r;
    if (!residual_stage(ctx, uc, u, cands, s, opt, already, read, outliers, declined, r, err)) return false;
    // --- what needs every sample
    Seed seed;
    if (!per_sample_stage(data, ctx, u, cands, s, seed, err)) return false;
    // --- verdict
    const Words w = verdict_words(data, opt, u, cands, s, review, r);
    const ReadingAgain reading = reading_noise_again(u, s);
    if (reading.retry) reading_retry = reading.r;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out = to_json({data, g, opt, u, cands, s, review, validation, r, seed, w, reading, seconds});
    fitted = cf.model;
    ctx.report("done", 1.0);
    return true;
}

} // namespace

// Outliers (calib/calibration/fit_outliers.h): the diagnosis is run again without the
// positions it set aside, and says which they were.
bool diagnose(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, json &out, Model &fitted,
              std::string &err) {
    json outliers;
    // Each round once more, with the readings' own error from the
    // recommended model's misclosure, when it disagrees with the one used
    // (diagnose_data): at most once.
    auto round = [&](const Dataset &d, size_t already, size_t read, std::vector<Outlier> &found, Declined &declined,
                     std::string &e) {
        std::optional<ReadingNoise> retry;
        if (!diagnose_data(d, g, opt, out, fitted, e, already, read, found, declined, retry)) return false;
        if (!retry || opt.reading_noise) return true;
        DiagnoseOptions o2 = opt;
        o2.reading_noise = retry;
        found.clear();
        declined = {};
        return diagnose_data(d, g, o2, out, fitted, e, already, read, found, declined, retry);
    };
    if (!run_setting_aside_outliers(data, opt.outliers, round, outliers, err)) return false;
    out["data"]["outliers"] = outliers;
    if (outliers["count"].get<size_t>() > 0)
        out["verdict"] = out["verdict"].get<std::string>() + " " + outliers_words(outliers["set_aside"], data.pos.size());
    return true;
}

} // namespace cdm
