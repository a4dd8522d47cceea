// JSON for the model: device descriptions and calibrations. A temporary
// home (the io module takes these over); the only file of src/model that
// knows JSON, and it goes through Model's public accessors.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "model/model.h"

namespace cdm {

// Parses JSON text; on a syntax error returns false with `err` naming
// source:line:column.
bool parse_json_text(const std::string &text, const std::string &source, nlohmann::json &out, std::string &err);

// Parses a device description. On error returns false and sets `err` to a
// message naming `source` and, for JSON syntax errors, the line and column.
bool parse_device_json(const std::string &text, const std::string &source, DeviceGeometry &out,
                       std::string &err);
nlohmann::json device_to_json(const DeviceGeometry &g);

// Calibration JSON: {"format":"cdm-calibration","version":1,
//   "device":{...},"effects":[{"name":..,"params":{..}}], ...}
nlohmann::json model_to_json(const Model &m);
bool model_from_json(const nlohmann::json &j, const std::string &source, Model &out, std::string &err);

} // namespace cdm
