// The `cdm` command: parses, runs the selected command, and maps every outcome
// to one of three exit codes (commands.h) whatever the subcommand.
#include <cstdio>
#include <exception>
#include <string>

#include <cdm/cdm.h>
#include "commands.h"

namespace cdm::cli {
namespace {
Command g_command;

const char *const kFooter =
    "Exit status: 0 success, 1 runtime failure (device, file, fit), 2 usage error (bad or missing argument).";

// CLI11 gives footers only to the app it is set on; every --help shows it.
void set_footer(CLI::App *app) {
    app->footer(kFooter);
    for (CLI::App *sub : app->get_subcommands([](CLI::App *) { return true; })) set_footer(sub);
}

bool has_subcommand(CLI::App &app, const std::string &name) {
    for (CLI::App *sub : app.get_subcommands([](CLI::App *) { return true; }))
        if (sub->get_name() == name) return true;
    return false;
}

// `cdm bogus` and `cdm calib bogus`: CLI11 would say only that an argument
// was not expected; say which command is unknown and what exists.
bool unknown_command(CLI::App &app, int argc, char **argv) {
    CLI::App *level = &app;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a.empty() || a[0] == '-') return false;
        if (!has_subcommand(*level, a)) {
            std::string names;
            for (CLI::App *sub : level->get_subcommands([](CLI::App *) { return true; }))
                names += (names.empty() ? "" : ", ") + sub->get_name();
            std::fprintf(stderr, "cdm: unknown command \"%s\"; the commands%s%s are: %s (see cdm --help)\n",
                         a.c_str(), level == &app ? "" : " of ", level == &app ? "" : level->get_name().c_str(),
                         names.c_str());
            return true;
        }
        level = level->get_subcommand(a);
        if (level->get_subcommands([](CLI::App *) { return true; }).empty()) return false;
    }
    return false;
}

// The deepest subcommand the user named (for `cdm calib` alone: calib's help).
CLI::App *selected(CLI::App &app) {
    CLI::App *level = &app;
    for (;;) {
        auto subs = level->get_subcommands();
        if (subs.empty()) return level;
        level = subs.front();
    }
}

// An option given an empty value ("--json ''", "--jig-heights ''") is a
// usage error: taken as absent, it would silently mean the default. Except
// where empty is a value the option documents: no effects (diagnose's and
// simulate's default), ROS's empty frame id.
void refuse_empty_values(CLI::App &app) {
    static const char *const kEmptyAllowed[][2] = {
        {"diagnose", "--effects"}, {"simulate", "--effects"}, {"bridge", "--frame-id"}};
    for (CLI::App *level = &app; level;) {
        for (const CLI::Option *o : level->get_options()) {
            bool allowed = false;
            for (const auto &a : kEmptyAllowed) allowed = allowed || (level->get_name() == a[0] && o->get_name() == a[1]);
            for (const std::string &v : o->results()) {
                if (!v.empty() || o->get_expected_max() == 0 || allowed) continue;
                if (o->get_positional())
                    throw UsageError(o->get_name() + ": an empty argument (a name is needed)");
                throw UsageError(o->get_name() + ": an empty value (leave the option out for its default)");
            }
        }
        auto subs = level->get_subcommands();
        level = subs.empty() ? nullptr : subs.front();
    }
}

int run(int argc, char **argv) {
    CLI::App app{"cdm: driver and model-debugging toolkit for the cable-driven haptic master", "cdm"};
    app.option_defaults()->always_capture_default();
    app.require_subcommand(0, 1);
    app.set_version_flag("--version", std::string("cdm ") + cdm_version());
    add_device_commands(app);
    add_record_command(app);
    add_calib_commands(app);
    add_bridge_command(app);
    set_footer(&app);
    if (argc < 2) {
        std::fprintf(stderr, "%s", app.help().c_str());
        return kExitUsage;
    }
    if (unknown_command(app, argc, argv)) return kExitUsage;
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError &e) {
        const int rc = app.exit(e); // prints help, the version or the error
        return rc == 0 ? kExitOk : kExitUsage;
    }
    refuse_empty_values(app);
    if (!g_command) { // a command group without its subcommand
        std::fprintf(stderr, "%s", selected(app)->help().c_str());
        return kExitUsage;
    }
    return g_command();
}

} // namespace

void select_command(Command c) { g_command = std::move(c); }

} // namespace cdm::cli

int main(int argc, char **argv) {
    try {
        return cdm::cli::run(argc, argv);
    } catch (const cdm::cli::UsageError &e) {
        std::fprintf(stderr, "cdm: %s\n", e.what());
        return cdm::cli::kExitUsage;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "cdm: unexpected error: %s\n", e.what());
        return cdm::cli::kExitFailure;
    } catch (...) {
        std::fprintf(stderr, "cdm: unexpected error\n");
        return cdm::cli::kExitFailure;
    }
}
