// `cdm calib plan`: a jig session planned before any data (cdm_plan), written
// as PLAN.csv (x_ref,y_ref,z_ref,samples, in walking order); and the reader
// of that file for `cdm calib simulate --plan`.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <cdm/cdm.h>
#include "commands.h"

namespace cdm::cli {

namespace {

// The plan file's header (read back by the library: cdm_plan_file_read):
// the jig frame's reference (mm) and the samples to take there.
constexpr const char *kPlanHeader = "x_ref,y_ref,z_ref,samples";

struct PlanArgs {
    std::string out, json_out, effects, heights, device, after;
    int positions = 0, samples = 100, n = 25;
    double pitch = 5, noise = 0.05, jig = 0.03;
    bool quiet = false;
};

int progress_plan(void *, const char *, double f) {
    std::fprintf(stderr, "\r  planning %3d%%", int(std::lround(100 * f)));
    return 0;
}

std::string plan_csv(const nlohmann::json &r) {
    std::string text = std::string(kPlanHeader) + "\n";
    char b[160];
    for (const auto &p : r["positions"]) {
        // Every digit: simulate --plan matches them to the plate's holes.
        std::snprintf(b, sizeof b, "%.17g,%.17g,%.17g,%d\n", p[0].get<double>(), p[1].get<double>(),
                      p[2].get<double>(), p[3].get<int>());
        text += b;
    }
    return text;
}

void print_plan(const PlanArgs &a, const nlohmann::json &r) {
    const auto &s = r["predicted_sigma_mm"];
    std::printf("planned %zu of the plate's %zu positions x %d samples, in walking order, into %s\n",
                r["positions"].size(), r["plate_positions"].get<size_t>(), r["samples"].get<int>(), a.out.c_str());
    std::printf("predicted error over the workspace (1-sigma, the design model's): %.4f mm with the plan, %.4f mm "
                "with every position (x%.2f)\n",
                s["plan"].get<double>(), s["whole_plate"].get<double>(),
                s["plan"].get<double>() / s["whole_plate"].get<double>());
    const int picks = r["design"]["detectability_picks"].get<int>();
    std::printf("each effect's test against the nominal model at its typical size (power at alpha %s; %d position%s "
                "chosen for it first):\n",
                num(r["alpha"].get<double>()).c_str(), picks, picks == 1 ? "" : "s");
    for (const auto &e : r["detectability"])
        std::printf("  %-20s power %.3f (whole plate %.3f)%s\n", e["effect"].get<std::string>().c_str(),
                    e["power"].get<double>(), e["power_whole_plate"].get<double>(),
                    e["reachable"].get<bool>() ? (e["detectable"].get<bool>() ? "" : "  below the target")
                                               : "  not detectable at its typical size even on the whole plate");
    for (const auto &e : r["design"]["excluded"])
        std::printf("  %-20s left out: %s\n", e["effect"].get<std::string>().c_str(), e["why"].get<std::string>().c_str());
}

// Atomically; never over one of the command's inputs (empty names skipped).
int write_text(const std::string &path, const std::string &text, const std::vector<std::string> &inputs) {
    std::vector<const char *> p;
    for (const auto &i : inputs)
        if (!i.empty()) p.push_back(i.c_str());
    if (cdm_write_file_atomic(path.c_str(), text.data(), text.size(), p.data(), p.size()) == CDM_OK)
        return kExitOk;
    std::fprintf(stderr, "cdm: %s\n", cdm_thread_error());
    return kExitFailure;
}

int cmd_plan(const PlanArgs &a) {
    distinct_outputs({{"--out", a.out}, {"--json", a.json_out}});
    nlohmann::json o = {{"positions", a.positions}, {"samples", a.samples}, {"holes", a.n},
                        {"pitch_mm", a.pitch},      {"noise_mm", a.noise},   {"jig_tolerance_mm", a.jig}};
    if (!a.heights.empty()) o["heights_mm"] = parse_number_list(a.heights, "--jig-heights");
    if (!a.effects.empty()) o["effects"] = split_list(a.effects);
    if (!a.device.empty()) o["device"] = json_path("--device", a.device);
    if (!a.after.empty()) o["measured"] = read_plan_csv(a.after, "--after");
    char *res = nullptr;
    const bool shown = !a.quiet && isatty(2); // a bar, on a terminal only
    const int rc = cdm_plan(o.dump().c_str(), shown ? progress_plan : nullptr, nullptr, &res);
    if (shown) std::fprintf(stderr, "\n");
    if (rc != CDM_OK) return report_error("calib plan", rc);
    const auto r = nlohmann::json::parse(res);
    cdm_free_string(res);
    const std::vector<std::string> inputs{a.device, a.after};
    if (int w = write_text(a.out, plan_csv(r), inputs); w != kExitOk) return w;
    if (!a.json_out.empty())
        if (int w = write_text(a.json_out, r.dump(1) + "\n", inputs); w != kExitOk) return w;
    print_plan(a, r);
    return kExitOk;
}

} // namespace

nlohmann::json read_plan_csv(const std::string &path, const std::string &option) {
    char *rows = nullptr;
    if (cdm_plan_file_read(path.c_str(), &rows) != CDM_OK) throw UsageError(option + ": " + cdm_thread_error());
    const nlohmann::json j = nlohmann::json::parse(rows);
    cdm_free_string(rows);
    return j;
}

void add_plan(CLI::App *calib) {
    static PlanArgs p;
    auto *c = calib->add_subcommand("plan", "Plan a jig session before any data: which positions to measure "
                                            "(I-optimal, every catalogued effect detectable)");
    c->add_option("--positions", p.positions, "How many positions to choose")->required()->check(range(1, 1000000));
    c->add_option("--samples", p.samples, "Samples at each position")->capture_default_str()->check(range(1, 1000000));
    c->add_option("--jig-n", p.n, "Holes per side of the plate")->capture_default_str()->check(range(1, 1000));
    c->add_option("--jig-pitch", p.pitch, "Hole pitch (mm)")->capture_default_str()->check(range(1e-3, 1000));
    c->add_option("--jig-heights", p.heights, "Comma-separated fixture heights (mm) (default: 30,40,50,60,70)");
    c->add_option("--effects", p.effects,
                  "The model to plan for, a comma-separated list (default: every catalogued effect on the cables' "
                  "geometry, path and pots)");
    c->add_option("--device", p.device, "Device description JSON (default: the nominal a=b=150, m=30 mm)");
    c->add_option("--after", p.after,
                  "A PLAN.csv already measured: the plan goes on from it (its positions are in the design from the "
                  "start and --positions more are chosen, none of them again); with --effects the model its "
                  "data's diagnosis recommends, a session planned in two steps");
    c->add_option("--noise-mm", p.noise, "Per-sample pot noise (mm, std)")->capture_default_str()->check(range(1e-6, 100));
    c->add_option("--jig-tolerance-mm", p.jig, "Each visit's seating error (mm, std per axis)")
        ->capture_default_str()
        ->check(range(0, 100));
    c->add_option("--out", p.out, "PLAN.csv to write: x_ref,y_ref,z_ref,samples, in walking order")->required();
    c->add_option("--json", p.json_out, "Also write the plan's JSON (predictions, each effect's test)");
    c->add_flag("--quiet", p.quiet, "No progress output");
    c->callback([] { select_command([] { return cmd_plan(p); }); });
}

} // namespace cdm::cli
