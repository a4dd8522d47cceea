// Where `cdm calib diagnose|fit|check` put their results (calib_outputs.cpp):
// the JSON (--json) and the HTML report (--report DIR), each written whole
// or not at all, never over one of the command's inputs, never over a file
// of the user's in the report's directory, and checked before the work.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace cdm::cli {

// Through libcdm's one atomic writer; false (said on stderr) on failure.
bool write_atomic(const std::string &path, const std::string &text, const std::vector<std::string> &protect);
// "" when DIR is the report's to write `name` into, else why not.
std::string report_dir_refusal(const std::string &dir, const std::string &name);
// The outputs' checks that need no result; throws UsageError.
void check_outputs_first(const std::string &json_out, const std::string &report, const char *name,
                         const std::vector<std::string> &inputs);
// The result's JSON and report; an exit status.
int write_outputs(const std::string &json_out, const std::string &report, const std::vector<std::string> &before,
                  const nlohmann::json &r, const std::vector<std::string> &inputs, const char *name);

} // namespace cdm::cli
