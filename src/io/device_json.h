// Device description JSON <-> DeviceGeometry, with physically sane
// magnitudes checked (the ranges are stated below and in the messages).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "io/json.h"
#include "model/model.h"

namespace cdm::io {

// Sane ranges. a and b: the smallest bench master has a frame of a few cm,
// the largest cable-driven haptic workspaces are ~2 m; outside 10 mm..5 m
// the file is in the wrong unit (metres, micrometres) or corrupt.
constexpr double kFrameMinMm = 10.0, kFrameMaxMm = 5000.0;
// m, the holder's size: at least 1 mm, and inside the frame (m < 2a, m < 2b).
constexpr double kHolderMinMm = 1.0;
// The pulley radius is the exit_pulley effect's starting value: that
// effect's own bound is 0..40 mm; 100 mm leaves room for a user effect.
constexpr double kPulleyMaxMm = 100.0;
// exit_axis is normalised, but a vector far from unit length means the file
// holds something else (a position, a scaled axis): norms in 0.5..2 pass.
constexpr double kAxisNormMin = 0.5, kAxisNormMax = 2.0;

bool device_from_json(const JsonValue &j, const std::string &source, DeviceGeometry &out, std::string &err);
bool parse_device_json(const std::string &text, const std::string &source, DeviceGeometry &out,
                       std::string &err);
// read_file (kJsonMaxBytes) + parse_device_json.
bool load_device_json(const std::string &path, DeviceGeometry &out, std::string &err);
nlohmann::json device_to_json(const DeviceGeometry &g);

// Shared by the codecs: a finite number in [lo, hi] at `key` of object `j`.
// Absent and not required: `out` untouched.
bool get_number(const JsonValue &j, const char *key, double lo, double hi, const char *unit,
                const std::string &source, double &out, std::string &err, bool required,
                const std::string &context = "");

} // namespace cdm::io
