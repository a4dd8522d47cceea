#include "cdm/cdm.h"
#include "cli/commands.h"

int main(int argc, char **argv) {
    CLI::App app{"cdm: driver and model-debugging toolkit for the cable-driven haptic master"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("cdm ") + cdm_version());
    cdm::cli::add_device_commands(app);
    cdm::cli::add_calib_commands(app);
    CLI11_PARSE(app, argc, argv);
    return 0;
}
