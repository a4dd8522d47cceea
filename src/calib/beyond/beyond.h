// Beyond the catalogue, as one stage of the diagnosis: the stand-ins of the
// user's model and of the recommended one (standins.h); where a model
// leans on stand-ins or leaves structure, the term the catalogue lacks
// (discover.h), searched in the residual of the model without its
// stand-ins and compared with them; and whether the jig's booked errors are
// the jig's (attribution.h).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/beyond/attribution.h"
#include "calib/search/context.h"
#include "calib/beyond/discover.h"
#include "calib/beyond/standins.h"

namespace cdm {
namespace diag {

struct Beyond {
    std::vector<StandIn> user, recommended;
    Discovery discovery;
    Attribution attribution;
};

// ctx: the noise model the target was judged under; target/target_rep: the
// model the residual analysis speaks of (the recommended one, or the
// user's without the search); target_E its evaluation and target_explained
// its verdict's tests; user/user_rep: the user's model; jig_report:
// jig_analysis's report of target_E; noise: target's noise floor; out:
// default-constructed (it is filled, not reset). False + err when a fit or
// a user effect fails.
bool beyond_catalogue(const DiagContext &ctx, const Model &user, const FitReport &user_rep, const Model &target,
                      const FitReport &target_rep, const Eval &target_E, bool target_explained,
                      const nlohmann::json &jig_report, const V3 &noise, Beyond &out, std::string &err);

} // namespace diag
} // namespace cdm
