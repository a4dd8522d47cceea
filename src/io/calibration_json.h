// Calibration JSON <-> Model:
// {"format":"cdm-calibration","version":1,"device":{...},
//  "effects":[{"name":..,"params":{..every parameter..}}], ...}
// Every effect must give every one of its parameters, each finite and within
// the effect's declared bounds (ParamDesc lower/upper). A user effect's entry
// also carries "origin" (a plugin's path, "python:MODULE"; when known) and
// "fingerprint" (effect_fingerprint): loading names the origin when the
// effect is not registered and refuses another fingerprint.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "io/json.h"
#include "model/model.h"

namespace cdm::io {

bool model_from_json(const JsonValue &j, const std::string &source, Model &out, std::string &err);
bool parse_calibration_json(const std::string &text, const std::string &source, Model &out, std::string &err);
// read_file (kJsonMaxBytes) + parse_calibration_json.
bool load_calibration(const std::string &path, Model &out, std::string &err);
nlohmann::json model_to_json(const Model &m);

} // namespace cdm::io
