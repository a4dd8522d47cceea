#include "cli/commands.h"

namespace cdm::cli {
void add_calib_commands(CLI::App &app) { (void)app; }
} // namespace cdm::cli
