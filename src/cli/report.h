// The HTML report of `cdm calib diagnose --report` (report_spawn.cpp).
#pragma once
#include <string>
#include <vector>

namespace cdm::cli {
// Runs `$PYTHON -m cdm.report BEFORE... JSON --out DIR` (PYTHON defaults to
// python3), with --claim when the command wrote JSON into DIR itself (the
// report then lists it as its own). 0 on success; 1 with a message saying
// what to install.
int run_report(const std::string &json_path, const std::vector<std::string> &before, const std::string &dir,
               bool claim = false);
} // namespace cdm::cli
