// Command groups of the `cdm` command and what they share; main.cpp wires
// them into one CLI11 app. The CLI sees libcdm only through <cdm/cdm.h>
// (with its experimental block), as any application would.
#pragma once
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cdm/cdm.h>

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace cdm::cli {

// Exit codes: the same for every subcommand (README, "The cdm command").
enum Exit : int { kExitOk = 0, kExitFailure = 1, kExitUsage = 2 };

// The command the parse selected; main runs it once parsing succeeded, so
// that nothing runs inside CLI11's callbacks and every exception reaches
// main's handler.
using Command = std::function<int()>;
void select_command(Command c);

// A usage error found after parsing (a malformed number list, a missing
// option that depends on another): main prints it and exits kExitUsage.
struct UsageError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// `cdm list|info|stream` (device_cmd.cpp), `cdm record` (record_cmd.cpp),
// `cdm calib ...` (calib_cmd.cpp), `cdm bridge` (bridge_cmd.cpp).
void add_device_commands(CLI::App &app);
void add_record_command(CLI::App &app);
void add_calib_commands(CLI::App &app);
void add_bridge_command(CLI::App &app);

// Monotonic clock of our own (CLOCK_MONOTONIC, the clock libcdm stamps
// host_time_ns with, so ages computed from the two agree).
uint64_t now_ns();
double now_s();

// A number as a person writes it: 1, 0.5, 1000000, 1e-05.
std::string num(double v);
// CLI11 range validator whose message prints its bounds with num().
CLI::Validator range(double lo, double hi);
// A jig tolerance in mm: -1 (estimated from the data) or a std in [0, 5000].
CLI::Validator tolerance_or_estimate();
// Seeds: whole numbers a double holds exactly, each of its own (what the
// JSON options carry): below 2^53, so that no two seeds given read as one.
constexpr double kMaxSeed = 9007199254740991.0; // 2^53 - 1

// "30,40,50" -> {30,40,50}; throws UsageError naming `option` and the item.
std::vector<double> parse_number_list(const std::string &text, const std::string &option);
// `path`, for an options JSON of libcdm (UTF-8 only): throws UsageError
// naming `option` when it is not valid UTF-8.
const std::string &json_path(const std::string &option, const std::string &path);
// Both paths exist and are one file (the same device and inode: a link or
// another spelling of one path included); "" is no file.
bool same_file(const std::string &a, const std::string &b);
// Throws UsageError when two of a command's outputs ({option, path}; ""
// skipped) are one file: the same directory (symbolic links resolved) and
// name, or, existing, the same inode. The second would replace the first.
void distinct_outputs(const std::vector<std::pair<std::string, std::string>> &outputs);
std::vector<std::string> split_list(const std::string &s);

// "cdm: WHAT: <cdm_strerror>: <detail>" on stderr; returns kExitFailure.
int report_error(const std::string &what, int rc);
// A device's counters (cdm_stats) as the JSON summaries give them.
nlohmann::json stats_json(const cdm_stats &st);
// "D dropped, M malformed, O out of order, J sequence jumps, R restarts".
std::string losses_text(const cdm_stats &st);

// --plugin PATH, repeatable, on a command that evaluates a model (a
// calibration, a sim: URI's effects= or truth=, --effects): the user-effect
// plugins (.so) to load before it runs. load_plugins loads them in order:
// kExitOk, or kExitFailure naming the one that failed; a path ending in
// ".py" is a usage error saying how Python effects are used (the command
// does not embed Python).
void add_plugin_option(CLI::App *app, std::vector<std::string> &plugins);
int load_plugins(const std::vector<std::string> &plugins);

// `cdm calib plan` (plan_cmd.cpp), and its PLAN.csv read back for
// `cdm calib simulate --plan` and `cdm calib plan --after`: [[x_ref, y_ref,
// z_ref, samples], ...]; throws UsageError naming the option, the file,
// line and what is wrong.
void add_plan(CLI::App *calib);
nlohmann::json read_plan_csv(const std::string &path, const std::string &option);

} // namespace cdm::cli
