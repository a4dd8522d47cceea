// The candidate table: every catalogued effect (and registered user effect)
// not in a model, added to it and fitted, with its likelihood-ratio test,
// its BIC change, what it would change in the positions (its fingerprint),
// and the candidates or model effects the data cannot tell it from.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/search/context.h"
#include "calib/evaluation/findings.h"

namespace cdm {
namespace diag {

struct Candidate {
    explicit Candidate(const DeviceGeometry &g) : m(g) {}
    std::string name;
    double dchi2 = 0;   // reading-space chi-square decrease when added
    int k = 0;          // parameters it adds (after the gauge)
    double bic = 0;     // BIC change: -dchi2 + k ln(n_obs)
    double p = 1;       // likelihood ratio: P(chi2(k) > dchi2)
    double p_adj = 1;   // Bonferroni over the candidates tried
    double corr = 0;    // correlation of its fingerprint with the model's residual
    double shift_rms_mm = 0; // RMS over positions of what it changes in the position (mm)
    Eval E;
    Verdict v;
    Model m;
    FitReport rep;
    std::vector<V3> fp;                  // per position: model residual - residual with it
    std::vector<std::string> in_model;   // model effects that reproduce it
    std::vector<std::string> confused;   // candidates (or model effects) it cannot be told from
    bool screened = false; // fitted by the screen's one step only (score_candidates' screen)
    bool significant() const { return p_adj < kFindingLevel; }
};

// Scores every candidate on top of `base` (fitted; `base_free` its reading-
// space free parameters, `base_chi2` its chi-square, `base_eval` its
// evaluation). Sorted by BIC change. False + err when cancelled. Without
// details only the tests are filled (dchi2, k, bic, p, p_adj, m, rep: what a
// search step chooses by); complete_candidates then adds the rest. With
// `screen`, every candidate not named in `in_full` is fitted by the screen
// only (FitJob::one_step: one Gauss-Newton step from its start; a seeded
// period's held starts, one step each) and marked `screened`: its numbers
// are estimates for ranking, not a candidate's fit (search.cpp).
bool score_candidates(const DiagContext &ctx, const Model &base, int base_free, double base_chi2,
                      const Eval &base_eval, const std::string &stage, std::vector<Candidate> &out,
                      std::string &err, bool details = true, bool screen = false,
                      const std::vector<std::string> &in_full = {});

// Fills what score_candidates leaves out without details: each candidate's
// evaluation E, its verdict v, its fingerprint fp, shift_rms_mm, corr and
// in_model (the same numbers as with details, whichever thread computes).
void complete_candidates(const DiagContext &ctx, const Model &base, const Eval &base_eval,
                         std::vector<Candidate> &cands);

// A one-effect swap's BIC change from `base`, estimated from below without
// fitting it: base - out + in is base + in with out's parameters held at
// their identity, so its chi-square is at least that of base + in (`cands`:
// the candidates on top of base, fitted in full, as ctx weighs) and it has
// at most out's parameter count fewer free parameters; its BIC change is
// then at least in's as a candidate less out's parameters' penalty. Not a
// proof: the inequality is between best fits of the data term, and each fit
// minimises it plus a weak prior anchored at its own start (a swap's local
// fit that found a better minimum, or a prior that moved, could pass it;
// callers keep a margin). -INFINITY (no bound) when `cands` has no full fit
// of in, when out is a user effect (it need not have an identity within
// its bounds), or when another effect's gauge depends on out (the two
// models are then not nested).
double swap_bound(const DiagContext &ctx, const Model &base, const std::string &out, const std::string &in,
                  const std::vector<Candidate> &cands);

// Fills each candidate's `confused` list (in_model, plus candidates equally
// good by BIC, within 10, explaining the same pattern, correlation > 0.9).
void mark_confusions(const Eval &base_eval, const V3 &jig, std::vector<Candidate> &cands);

nlohmann::json candidates_json(const std::vector<Candidate> &cands);
// Groups that cannot be told apart, with where their predictions part.
nlohmann::json inseparable_json(const std::vector<Candidate> &cands);

} // namespace diag
} // namespace cdm
