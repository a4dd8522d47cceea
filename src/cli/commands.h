// Command groups of the `cdm` command; main.cpp wires them into one CLI11 app.
#pragma once
#include <CLI/CLI.hpp>

namespace cdm::cli {
// `cdm list|info|stream|record` (device_cmd.cpp)
void add_device_commands(CLI::App &app);
// `cdm calib fit|diagnose|simulate` (calib_cmd.cpp)
void add_calib_commands(CLI::App &app);
} // namespace cdm::cli
