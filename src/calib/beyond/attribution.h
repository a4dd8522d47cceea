// Whether the jig's estimated errors are the jig's. A spacer's error, or a
// hole's, is the same whatever model of the device is fitted; and spacers
// machined one by one do not line up along the heights. So the per-height
// offsets the diagnosis books to the fixture are questioned when they change
// with the device model (the recommended model against another that
// explains the data as well: the model with the discovered term), or when
// they follow a straight line in height, which a device effect makes and
// independent spacers do not; and a pattern over the plate that repeats at
// every hole and is smooth from hole to hole is named (a plate's holes are
// drilled independently), even where its size is under the hole test's.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "calib/evaluation/eval.h"
#include "calib/evaluation/spatial.h"

namespace cdm {
namespace diag {

struct Attribution {
    bool ambiguous = false;
    nlohmann::json report = nlohmann::json::object();
    std::string words; // sentences for the verdict ("" when nothing is in doubt)
};

// rec: the model whose offsets the diagnosis takes out; other (may be
// null): another model's evaluation, other_name its description; jig: the
// tolerance; noise: the noise floor per axis (a tenth of its norm is what
// the verdict calls negligible); jig_report: jig_analysis's report of rec.
Attribution jig_attribution(const Eval &rec, const Eval *other, const std::string &other_name, const Grid &G,
                            const V3 &jig, const V3 &noise, const nlohmann::json &jig_report);

} // namespace diag
} // namespace cdm
