// The pieces of the diagnosis's JSON (docs/calibration.md) and the words
// of its advice, for diagnose.cpp.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/evaluation/eval.h"
#include "calib/fit/fit.h"

namespace cdm {
namespace diag {

// [x, y, z]
nlohmann::json vec3(const V3 &v);
// v's items with sep between them; `none` when v is empty.
std::string join(const std::vector<std::string> &v, const char *sep, const std::string &none);
// Every effect's parameters: {effect: {param: {value, std, unit}}}.
nlohmann::json params_json(const Model &model, const FitReport &rep);
// Advice an effect carries when it is recommended: what a person does
// about it, with the fitted number ("" for most effects).
std::string effect_advice(const Model &m, const FitReport &rep, const std::vector<PreparedPos> &pos);

} // namespace diag
} // namespace cdm
