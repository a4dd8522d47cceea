// `cdm calib simulate|diagnose|fit|effects`: the model-debugging workflow
// (docs/calibration.md). The numbers come from libcdm (cdm_diagnose); the
// figures from the Python package (python3 -m cdm.report).
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "calib/simulate.h"
#include "cdm/cdm.h"
#include "cli/commands.h"
#include "model/effect.h"
#include "io/calibration_json.h"
#include "io/device_json.h"

namespace cdm::cli {

namespace {

std::vector<std::string> split_list(const std::string &s) {
    std::vector<std::string> v;
    std::stringstream ss(s);
    std::string x;
    while (std::getline(ss, x, ','))
        if (!x.empty()) v.push_back(x);
    return v;
}

int progress_cb(void *, const char *stage, double f) {
    static std::string last;
    const int pct = int(std::lround(100 * f));
    if (isatty(2)) {
        std::fprintf(stderr, "\r  %-32s %3d%%", stage, pct);
        if (f >= 1.0 && std::string(stage) == "done") std::fprintf(stderr, "\n");
    } else if (last != stage) {
        std::fprintf(stderr, "  %s...\n", stage);
    }
    last = stage;
    return 0;
}

void print_stats_row(const char *name, const nlohmann::json &s) {
    if (s.is_null()) return;
    std::printf("  %-26s", name);
    for (const char *a : {"x", "y", "z"})
        std::printf("  %8.4f ± %-7.4f %7.4f %7.4f", s[a]["mean"].get<double>(), s[a]["std"].get<double>(),
                    s[a]["rms"].get<double>(), s[a]["max"].get<double>());
    std::printf("\n");
}

void print_summary(const nlohmann::json &r) {
    std::printf("\nPosition error (mm), estimate - reference, over every sample:\n");
    std::printf("  %-26s  %-34s  %-34s  %-34s\n", "", "x: mean ± std    rms     max", "y: mean ± std    rms     max",
                "z: mean ± std    rms     max");
    print_stats_row("nominal (eq. 1-3)", r["nominal_error_mm"]);
    print_stats_row("seed ellipsoid (eq. 4-5)", r["ellipsoid_error_mm"]);
    std::string cur = "model";
    if (!r["model"].empty()) {
        cur = "model +";
        for (auto &e : r["model"]) cur += " " + e.get<std::string>();
    }
    print_stats_row(cur.substr(0, 26).c_str(), r["error_mm"]);
    print_stats_row("noise floor", r["noise_floor_mm"]);
    std::printf("\n  jig tolerance %.4f mm (%s); chi2/dof %.3f; spatial structure z = %.1f (p = %.2g); "
                "failing positions %d of %d\n",
                r["jig_tolerance_mm"]["value"].get<double>(), r["jig_tolerance_mm"]["source"].get<std::string>().c_str(),
                r["chi2_per_dof"].get<double>(), r["structure"]["statistic"].get<double>(),
                r["structure"]["p_value"].get<double>(), r["failing_positions"].get<int>(),
                r["data"]["positions"].get<int>());
    std::printf("  explained: %s\n", r["explained"].get<bool>() ? "yes" : "no");
    if (!r["candidates"].empty()) {
        std::printf("\nMissing-effect candidates (best first):\n");
        std::printf("  %-18s %12s %12s %5s %10s  %s\n", "effect", "delta chi2", "BIC change", "k", "x rms after",
                    "confused with");
        for (auto &c : r["candidates"]) {
            std::string conf;
            for (auto &n : c["confused_with"]) conf += (conf.empty() ? "" : ", ") + n.get<std::string>();
            std::printf("  %-18s %12.1f %12.1f %5d %10.4f  %s%s\n", c["effect"].get<std::string>().c_str(),
                        c["delta_chi2"].get<double>(), c["bic_change"].get<double>(), c["n_params"].get<int>(),
                        c["error_mm_after"]["x"]["rms"].get<double>(), conf.c_str(),
                        c["explained_after"].get<bool>() ? "  (explains it)" : "");
        }
    }
    for (auto &g : r["inseparable"]) std::printf("\n  inseparable: %s\n", g["separate_by"].get<std::string>().c_str());
    std::printf("\nUnexplained structure: %s\n", r["unexplained_structure"]["summary"].get<std::string>().c_str());
    if (!r["validation"].is_null())
        std::printf("Leave-one-height-out RMS (mm): x %.4f y %.4f z %.4f (in sample: x %.4f y %.4f z %.4f)\n",
                    r["validation"]["rms_mm"]["x"].get<double>(), r["validation"]["rms_mm"]["y"].get<double>(),
                    r["validation"]["rms_mm"]["z"].get<double>(), r["validation"]["in_sample_rms_mm"]["x"].get<double>(),
                    r["validation"]["in_sample_rms_mm"]["y"].get<double>(),
                    r["validation"]["in_sample_rms_mm"]["z"].get<double>());
    std::printf("\nVerdict: %s\n", r["verdict"].get<std::string>().c_str());
}

bool write_atomic(const std::string &path, const std::string &text) {
    const std::string tmp = path + ".tmp";
    {
        std::ofstream f(tmp);
        f << text;
        if (!f) return false;
    }
    return std::rename(tmp.c_str(), path.c_str()) == 0;
}

int run_report(const std::string &json_path, const std::vector<std::string> &before, const std::string &dir) {
    std::string py = std::getenv("PYTHON") ? std::getenv("PYTHON") : "python3";
    std::string pp;
#ifdef CDM_SOURCE_DIR
    struct stat st;
    if (stat(CDM_SOURCE_DIR "/bindings/python/cdm/report.py", &st) == 0) pp = CDM_SOURCE_DIR "/bindings/python";
#endif
    std::string cmd;
    if (!pp.empty()) cmd = "PYTHONPATH='" + pp + "'${PYTHONPATH:+:$PYTHONPATH} ";
    cmd += py + " -m cdm.report";
    for (auto &b : before) cmd += " '" + b + "'";
    cmd += " '" + json_path + "' --out '" + dir + "'";
    int rc = std::system(cmd.c_str());
    if (rc != 0) {
        std::fprintf(stderr, "cdm calib: the report tool failed (%s)\n", cmd.c_str());
        return 1;
    }
    return 0;
}

struct DiagArgs {
    std::string data, device, effects, json_out, report, calib_out, plugin;
    std::vector<std::string> before;
    double jig = -1;
    bool quiet = false, no_candidates = false;
};

int cmd_diagnose(const DiagArgs &a, bool fit_only) {
    if (!a.plugin.empty() && cdm_effect_load_plugin(a.plugin.c_str()) != CDM_OK) {
        std::fprintf(stderr, "cdm calib: %s\n", cdm_thread_error());
        return 2;
    }
    nlohmann::json o;
    o["effects"] = split_list(a.effects);
    if (a.jig >= 0) o["jig_tolerance_mm"] = a.jig;
    if (!a.calib_out.empty()) o["calibration_out"] = a.calib_out;
    if (!fit_only && a.no_candidates) {
        o["candidates"] = false;
        o["validation"] = true;
    }
    char *res = nullptr;
    // fit: cdm_fit (the fit alone, no candidates/review/validation)
    int rc = (fit_only ? cdm_fit : cdm_diagnose)(a.data.c_str(), a.device.c_str(), o.dump().c_str(),
                                                 a.quiet ? nullptr : progress_cb, nullptr, &res);
    if (rc != CDM_OK) {
        std::fprintf(stderr, "cdm calib: %s: %s\n", cdm_strerror(rc), cdm_thread_error());
        return 2;
    }
    auto r = nlohmann::json::parse(res);
    cdm_free_string(res);
    if (fit_only) {
        std::printf("fitted %s on %s: x rms %.4f y %.4f z %.4f mm (jig tolerance x %.4f)\n", o["effects"].dump().c_str(),
                    a.data.c_str(), r["error_mm"]["x"]["rms"].get<double>(), r["error_mm"]["y"]["rms"].get<double>(),
                    r["error_mm"]["z"]["rms"].get<double>(), r["jig_tolerance_mm"][0].get<double>());
        std::printf("calibration written to %s\n", a.calib_out.c_str());
    } else {
        print_summary(r);
    }
    if (!a.json_out.empty() && !write_atomic(a.json_out, r.dump(1) + "\n")) {
        std::fprintf(stderr, "cdm calib: cannot write %s\n", a.json_out.c_str());
        return 2;
    }
    if (!a.report.empty()) {
        std::string jp = a.json_out;
        if (jp.empty()) {
            mkdir(a.report.c_str(), 0755);
            jp = a.report + "/diagnosis.json";
            if (!write_atomic(jp, r.dump() + "\n")) return 2;
        }
        if (run_report(jp, a.before, a.report) != 0) return 1;
        std::printf("report: %s/index.html\n", a.report.c_str());
    }
    return 0;
}

struct SimArgs {
    std::string out, effects, truth, device, plugin;
    uint64_t effect_seed = 1, seed = 1;
    JigSimOptions o;
    std::string heights;
    std::string truth_out;
};

int cmd_simulate(SimArgs &a) {
    DeviceGeometry g;
    std::string err;
    if (!a.plugin.empty() && cdm_effect_load_plugin(a.plugin.c_str()) != CDM_OK) {
        std::fprintf(stderr, "cdm calib simulate: %s\n", cdm_thread_error());
        return 2;
    }
    if (!a.device.empty()) {
        if (!io::load_device_json(a.device, g, err)) {
            std::fprintf(stderr, "cdm calib simulate: %s\n", err.c_str());
            return 2;
        }
    }
    Model truth(g);
    if (!a.truth.empty()) {
        if (!io::load_calibration(a.truth, truth, err)) {
            std::fprintf(stderr, "cdm calib simulate: %s\n", err.c_str());
            return 2;
        }
    }
    int k = 0;
    for (auto &e : split_list(a.effects))
        if (!truth.add_effect_random(e, a.effect_seed + uint64_t(k++), err)) {
            std::fprintf(stderr, "cdm calib simulate: %s\n", err.c_str());
            return 2;
        }
    if (!a.heights.empty()) {
        a.o.heights.clear();
        for (auto &h : split_list(a.heights)) a.o.heights.push_back(std::stod(h));
    }
    a.o.seed = a.seed;
    if (!simulate_jig_csv(truth, a.o, a.out, err)) {
        std::fprintf(stderr, "cdm calib simulate: %s\n", err.c_str());
        return 2;
    }
    if (!a.truth_out.empty() && !write_atomic(a.truth_out, io::model_to_json(truth).dump(2) + "\n")) return 2;
    std::printf("wrote %s (%zu positions x %d samples)\n", a.out.c_str(),
                a.o.heights.size() * size_t(a.o.n) * size_t(a.o.n), a.o.samples);
    return 0;
}

} // namespace

void add_calib_commands(CLI::App &app) {
    auto *calib = app.add_subcommand("calib", "Model debugging: compare the model with jig data, find what is missing, "
                                              "fit, write a calibration (docs/calibration.md)");
    calib->require_subcommand(1);

    static DiagArgs d, f;
    auto *diag = calib->add_subcommand("diagnose", "Fit the model with the given effects and diagnose what it misses");
    diag->add_option("data", d.data, "Jig dataset CSV: point,x_ref,y_ref,z_ref,l1,l2,l3,l4")->required();
    diag->add_option("--device", d.device, "Device description JSON {\"a_mm\":..,\"b_mm\":..,\"m_mm\":..}")->required();
    diag->add_option("--effects", d.effects, "Comma-separated effects to fit (default: none, the nominal model)");
    diag->add_option("--jig-tolerance-mm", d.jig, "Std of the jig's own position error (default: estimated)");
    diag->add_option("--json", d.json_out, "Write the diagnosis JSON here");
    diag->add_option("--report", d.report, "Write the HTML report with figures into this directory");
    diag->add_option("--before", d.before, "Earlier diagnosis JSON files to compare in the report");
    diag->add_option("--calibration", d.calib_out, "Also write the fitted calibration JSON");
    diag->add_option("--plugin", d.plugin, "Load a user-effect plugin (.so) first");
    diag->add_flag("--no-candidates", d.no_candidates, "Skip the ranking of missing effects");
    diag->add_flag("--quiet", d.quiet, "No progress output");
    diag->callback([] { std::exit(cmd_diagnose(d, false)); });

    auto *fit = calib->add_subcommand("fit", "Fit the model with the given effects and write the calibration");
    fit->add_option("data", f.data, "Jig dataset CSV")->required();
    fit->add_option("--device", f.device, "Device description JSON")->required();
    fit->add_option("--effects", f.effects, "Comma-separated effects to fit");
    fit->add_option("--jig-tolerance-mm", f.jig, "Std of the jig's own position error (default: estimated)");
    fit->add_option("--out", f.calib_out, "Calibration JSON to write")->required();
    fit->add_option("--json", f.json_out, "Also write the fit statistics JSON");
    fit->add_option("--plugin", f.plugin, "Load a user-effect plugin (.so) first");
    fit->add_flag("--quiet", f.quiet, "No progress output");
    fit->callback([] { std::exit(cmd_diagnose(f, true)); });

    static SimArgs s;
    auto *sim = calib->add_subcommand("simulate", "Write a simulated jig dataset (the seed's experiment) from a known model");
    sim->add_option("out", s.out, "Dataset CSV to write")->required();
    sim->add_option("--device", s.device, "Device description JSON (default: a=b=150, m=30 mm)");
    sim->add_option("--effects", s.effects, "Hidden effects, random realistic magnitudes");
    sim->add_option("--effect-seed", s.effect_seed, "Seed of the hidden effects' magnitudes");
    sim->add_option("--truth", s.truth, "Calibration JSON to use as the true model");
    sim->add_option("--plugin", s.plugin, "Load a user-effect plugin (.so) first (its effects can be in --truth)");
    sim->add_option("--truth-out", s.truth_out, "Write the true model (with the hidden magnitudes) here");
    sim->add_option("--seed", s.seed, "Noise seed");
    sim->add_option("--noise-mm", s.o.noise_mm, "Per-sample pot noise std (mm)");
    sim->add_option("--quant-mm", s.o.quant_mm, "ADC step (mm)");
    sim->add_option("--jig-tolerance-mm", s.o.jig_tolerance_mm, "Std of each position's own error (mm)");
    sim->add_option("--samples", s.o.samples, "Samples per position");
    sim->add_option("--holes", s.o.n, "Holes per side of the plate");
    sim->add_option("--pitch-mm", s.o.pitch_mm, "Hole pitch (mm)");
    sim->add_option("--heights", s.heights, "Comma-separated heights (mm)");
    sim->callback([] { std::exit(cmd_simulate(s)); });

    auto *eff = calib->add_subcommand("effects", "List the effect catalogue with each effect's physics");
    eff->callback([] {
        for (auto &e : all_effects()) {
            std::printf("%s\n    %s\n    parameters:", e->name.c_str(), e->doc.c_str());
            for (auto &p : e->params) std::printf(" %s[%s]", p.name.c_str(), p.unit.c_str());
            std::printf("\n");
        }
        std::exit(0);
    });
}

} // namespace cdm::cli
