// The HTML report of `cdm calib diagnose --report` (report_spawn.cpp).
#pragma once
#include <string>
#include <vector>

namespace cdm::cli {
// Runs `$PYTHON -m cdm.report BEFORE... JSON --out DIR` (PYTHON defaults to
// python3). 0 on success; 1 with a message saying what to install.
int run_report(const std::string &json_path, const std::vector<std::string> &before, const std::string &dir);
} // namespace cdm::cli
