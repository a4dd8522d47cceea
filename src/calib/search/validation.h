// Leave-one-height-out validation: the model fitted without each height,
// its error at that height (null when there is nothing to validate).
#pragma once

#include <nlohmann/json.hpp>

#include "calib/search/context.h"

namespace cdm {
namespace diag {

bool validate_heights(const DiagContext &ctx, const Model &model, const Eval &in_sample, nlohmann::json &out,
                      std::string &err);

} // namespace diag
} // namespace cdm
