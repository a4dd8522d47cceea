// The model review: is each effect of the user's model still earning its
// parameters (its removal's BIC change), and would a catalogued effect do its
// job better (the best one-effect swap)? Greedy forward selection can pick a
// many-parameter effect that mimics two small ones; this says so.
#pragma once

#include <nlohmann/json.hpp>

#include "calib/search/candidates.h"
#include "calib/search/context.h"

namespace cdm {
namespace diag {

// model: fitted; n_free, chi2: its reading-space free parameters and
// chi-square. cands (optional): the candidates on top of it, fitted in
// full as ctx weighs; a swap whose bound (swap_bound) says it cannot gain
// the 10 a better_swap needs (with a margin of 5) is then not fitted. False + err when
// cancelled.
bool review_model(const DiagContext &ctx, const Model &model, int n_free, double chi2, nlohmann::json &out,
                  std::string &err, const std::vector<Candidate> *cands = nullptr);

} // namespace diag
} // namespace cdm
