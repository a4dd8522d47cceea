// The diagnosis as stages, each a function that returns what the later
// ones, the verdict and the JSON read (private to calib/diagnosis):
// diagnose.cpp runs them in order, report.cpp writes the JSON of
// docs/calibration.md from their results and computes nothing.
#pragma once

#include <chrono>
#include <future>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/beyond/beyond.h"
#include "calib/calibration/fit_calibration.h"
#include "calib/diagnosis/options.h"
#include "calib/diagnosis/verdict.h"
#include "calib/evaluation/findings.h"
#include "calib/evaluation/jig.h"
#include "calib/evaluation/outliers.h"
#include "calib/search/candidates.h"
#include "calib/search/context.h"
#include "calib/search/search.h"

namespace cdm {
namespace diag {

// The user's model fitted (fit_calibration) and judged: what every later
// stage starts from.
struct UserModel {
    explicit UserModel(const DeviceGeometry &g) : cf(g) {}
    // In this order so that, on any way out, the nominal triangulation's
    // pass over the rows (a thread writing nominal_err and cf.nominal, left
    // running beside the candidates and the search) ends before they go.
    std::string nominal_err;
    CalibrationFit cf;
    std::future<bool> nominal_pending;
    bool user_jig = false;  // the jig tolerance given by the user
    bool repeats = false;   // positions of more than one sample
    int model_free = 0;     // its fitted parameters in reading space
    Verdict v;              // its chi-square and structure tests
    double chi2 = 0;        // its reading-space chi-square: what candidates and review refits compare with
    V3 noise = V3::Zero();  // its noise floor
};
bool fit_user_model(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, UserModel &u,
                    std::string &err);

// The model search (when opt.search and opt.candidates): the recommended
// model and the noise model it was judged under (sctx; ctx's when no
// search ran).
struct SearchStage {
    explicit SearchStage(const DiagContext &ctx) : sctx(ctx), sr(ctx.g) {}
    bool on = false;
    DiagContext sctx;
    SearchResult sr;
    std::vector<std::pair<std::vector<std::string>, double>> alts;
};
bool search_stage(const Model &model, const FitReport &rep, bool user_jig, SearchStage &s, std::string &err);

// Beyond the catalogue: what is left after the best catalogued explanation
// (the recommended model; without the search, the user's model, or the top
// candidate on top of it when neither explains the data): the jig's own
// errors, the findings against physical variables, the outliers, the
// stand-ins, the term the catalogue lacks.
struct Residuals {
    bool use_top = false;  // the top candidate on top of the user's model is what is analysed
    V3 jig = V3::Zero();   // the jig tolerance of what is analysed
    LengthView lv;
    JigAnalysis ja;
    nlohmann::json findings;
    Beyond bey;
};
bool residual_stage(const DiagContext &ctx, const DiagContext &uc, const UserModel &u,
                    const std::vector<Candidate> &cands, const SearchStage &s, const DiagnoseOptions &opt,
                    size_t already, size_t read, std::vector<Outlier> &outliers, Declined &declined, Residuals &r,
                    std::string &err);

// What needs every sample, in one pass over the rows: the maxima of the
// reported evaluations, and the seed's procedure with its ellipsoid.
struct Seed {
    Ellipsoid ell;
    Eval E;
};
bool per_sample_stage(const Dataset &data, const DiagContext &ctx, UserModel &u, std::vector<Candidate> &cands,
                      SearchStage &s, Seed &seed, std::string &err);

// The verdict: the user's model's judgement, the recommended model's, and
// the sentences.
struct Words {
    std::string modelname;            // "the model with ..."
    Judgement jm;                     // the user's model
    Verdict vr;                       // the recommended model's tests (with the search)
    Judgement jr;                     // and its judgement
    std::string verdict, unexplained_summary;
};
Words verdict_words(const Dataset &data, const DiagnoseOptions &opt, const UserModel &u,
                    const std::vector<Candidate> &cands, const SearchStage &s, const nlohmann::json &review,
                    const Residuals &r);

// The readings' own error again, from the recommended model's misclosure
// (with the search; diagnose() runs the diagnosis again with `r` when
// `retry`).
struct ReadingAgain {
    bool on = false;
    ReadingNoise again, r;
    bool retry = false;
};
ReadingAgain reading_noise_again(const UserModel &u, const SearchStage &s);

// Everything the JSON is written from.
struct Diagnosis {
    const Dataset &data;
    const DeviceGeometry &g;
    const DiagnoseOptions &opt;
    const UserModel &u;
    const std::vector<Candidate> &cands;
    const SearchStage &s;
    const nlohmann::json &review, &validation;
    const Residuals &r;
    const Seed &seed;
    const Words &w;
    const ReadingAgain &reading;
    double seconds;
};
// The JSON of docs/calibration.md (report.cpp).
nlohmann::json to_json(const Diagnosis &d);

} // namespace diag
} // namespace cdm
