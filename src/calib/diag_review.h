// The model review: is each effect of the user's model still earning its
// parameters (its removal's BIC change), and would a catalogued effect do its
// job better (the best one-effect swap)? Greedy forward selection can pick a
// many-parameter effect that mimics two small ones; this says so.
#pragma once

#include <nlohmann/json.hpp>

#include "calib/diag_context.h"

namespace cdm {
namespace diag {

// model: fitted; n_free, chi2: its reading-space free parameters and
// chi-square. False + err when cancelled.
bool review_model(const DiagContext &ctx, const Model &model, int n_free, double chi2, nlohmann::json &out,
                  std::string &err);

} // namespace diag
} // namespace cdm
