// Findings beyond the catalogue in the residuals of the best explanation:
// a period in cable length (pooled Lomb-Scargle over the four cables) and
// polynomial trends of the position residual against physical variables.
// Each finding carries structured fields beside its English text
// (docs/calibration.md, "The JSON").
#pragma once

#include <array>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/diag_eval.h"

namespace cdm {
namespace diag {

// lmean, lres: per position, each cable's mean reading and its residual
// against the model's prediction; angle: each cable's angle (deg) to the
// plate; E: the evaluation whose residuals are analysed; jig: tolerance.
nlohmann::json residual_findings(const std::vector<PreparedPos> &pos, const std::vector<std::array<double, 4>> &lmean,
                                 const std::vector<std::array<double, 4>> &lres,
                                 const std::vector<std::array<double, 4>> &angle, const Eval &bE, const V3 &jig);

} // namespace diag
} // namespace cdm
