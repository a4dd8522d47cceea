// The model-debugging workflow behind `cdm calib diagnose`: compare the model
// with jig data, see where it fails, rank the catalogued effects that could
// be missing, validate, and look beyond the catalogue. Produces the JSON of
// docs/calibration.md; the Python report draws it.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/dataset/dataset.h"
#include "calib/diagnosis/options.h"
#include "model/model.h"

namespace cdm {

// On success fills `out` (the diagnosis JSON) and `fitted` (the model with
// the requested effects fitted). False + err (naming what is wrong) otherwise.
bool diagnose(const Dataset &data, const DeviceGeometry &g, const DiagnoseOptions &opt, nlohmann::json &out,
              Model &fitted, std::string &err);

namespace diag {
struct Verdict;
// `cdm calib fit`'s words on a fit's own two tests (no candidate tried).
std::string fit_check_words(const Verdict &v);
} // namespace diag

} // namespace cdm
