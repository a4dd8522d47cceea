// `cdm calib simulate|diagnose|fit|check|effects` (`plan`: plan_cmd.cpp): the model-debugging workflow
// (docs/calibration.md). The numbers come from libcdm (cdm_diagnose,
// cdm_simulate_jig_dataset); the figures from the Python package
// (python3 -m cdm.report, report_spawn.cpp).
#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <cdm/cdm.h>
#include "commands.h"
#include "calib_outputs.h"
#include "report.h"

namespace cdm::cli {

namespace {

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

// The dataset's columns the reader left out, said once (the file is read
// all the same: docs/calibration.md, "Record a jig session").
void print_ignored_columns(const nlohmann::json &r) {
    const nlohmann::json none = nlohmann::json::array();
    const auto &cols = r.contains("data") ? r["data"].value("ignored_columns", none) : none;
    if (cols.empty()) return;
    std::string names;
    for (const auto &c : cols) names += (names.empty() ? "" : ", ") + c.get<std::string>();
    std::printf("note: columns ignored (not point, x_ref, y_ref, z_ref, l1..l4, t_s): %s\n", names.c_str());
}

void print_summary(const nlohmann::json &r) {
    print_ignored_columns(r);
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
    // The scale the plate's holes widen the chi-square test by, beside the
    // number it qualifies (docs/calibration.md, "The holes in the fit").
    const double scale = r.contains("chi2_test") ? r["chi2_test"].value("scale", 1.0) : 1.0;
    char widened[96] = "";
    if (r.contains("chi2_test") && r["chi2_test"].value("widened", false))
        std::snprintf(widened, sizeof widened, " (p = %.2g, test widened x%.2f for the plate's holes)",
                      r["chi2_p_value"].get<double>(), scale);
    std::printf("\n  jig tolerance %.4f mm (%s); chi2/dof %.3f%s; spatial structure z = %.1f (p = %.2g); "
                "failing positions %d of %d\n",
                r["jig_tolerance_mm"]["value"].get<double>(), r["jig_tolerance_mm"]["source"].get<std::string>().c_str(),
                r["chi2_per_dof"].get<double>(), widened, r["structure"]["statistic"].get<double>(),
                r["structure"]["p_value"].get<double>(), r["failing_positions"].get<int>(),
                r["data"]["positions"].get<int>());
    if (r.contains("reading_noise_mm") && r["reading_noise_mm"].value("value", 0.0) > 0) {
        // (Without repeated samples the pots' noise is not measured apart: it is in this value.)
        const bool apart = r["reading_noise_mm"].value("note", "").rfind("no repeated samples", 0) != 0;
        std::printf("  the readings' own scatter%s: %.4f mm per reading (from the cables' "
                    "misclosure; in every weight and test)\n",
                    apart ? " beyond the pots' noise" : ", the pots' noise in it (no repeated samples)",
                    r["reading_noise_mm"]["value"].get<double>());
    }
    std::printf("  explained: %s\n", r["explained"].get<bool>() ? "yes" : "no");
    if (r["data"].contains("outliers") && r["data"]["outliers"]["count"].get<size_t>() > 0)
        std::printf("  outliers set aside: %zu of %zu positions (the verdict says which)\n",
                    r["data"]["outliers"]["count"].get<size_t>(), r["data"]["outliers"]["positions_read"].get<size_t>());
    if (r["data"].contains("outliers") && r["data"]["outliers"]["declined"]["count"].get<size_t>() > 0)
        std::printf("  disowned positions kept: %zu (%s)\n", r["data"]["outliers"]["declined"]["count"].get<size_t>(),
                    r["data"]["outliers"]["declined"]["why"].get<std::string>().c_str());
    if (r["data"].contains("glitches") && r["data"]["glitches"]["count"].get<size_t>() > 0)
        std::printf("  glitches set aside: %zu samples at %zu positions (beyond %.1f sd; the verdict says more)\n",
                    r["data"]["glitches"]["count"].get<size_t>(), r["data"]["glitches"]["positions"].get<size_t>(),
                    r["data"]["glitches"]["threshold_sd"].get<double>());
    if (r.contains("recommended") && !r["recommended"].is_null()) {
        const auto &rec = r["recommended"];
        std::string names;
        for (auto &e : rec["effects"]) names += (names.empty() ? "" : " + ") + e.get<std::string>();
        std::printf("\nRecommended model: %s (x RMS %.4f mm; explained: %s)\n",
                    names.empty() ? "the nominal model" : names.c_str(), rec["error_mm"]["x"]["rms"].get<double>(),
                    rec["explained"].get<bool>() ? "yes" : rec["negligible_only"].get<bool>() ? "to within what matters" : "no");
        for (auto &st : rec["path"])
            std::printf("  step %d: %s (BIC %+.1f, x RMS %.4f mm)\n", st["step"].get<int>(),
                        (st.contains("added") && st.contains("removed")
                             ? st["removed"].get<std::string>() + " -> " + st["added"].get<std::string>()
                         : st.contains("added") ? "+ " + st["added"].get<std::string>()
                                                : "- " + st["removed"].get<std::string>())
                            .c_str(),
                        st["bic_change"].get<double>(), st["x_rms_mm"].get<double>());
    }
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

// The accuracy map's summary: the calibration's predicted error over the
// jig's volume, and past it.
void print_accuracy(const nlohmann::json &a) {
    if (!a.is_object() || !a.contains("summary") || a["summary"]["inside"].is_null()) {
        if (a.is_object() && a.contains("error"))
            std::printf("accuracy map: not computed (%s)\n", a["error"].get<std::string>().c_str());
        return;
    }
    const auto &in = a["summary"]["inside"];
    const auto &s = in["sigma_mm"];
    std::printf("predicted error (1-sigma) over the jig's volume: mean x %.4f y %.4f z %.4f, worst x %.4f y %.4f "
                "z %.4f mm; 95 %% ellipsoid's longest semi-axis mean %.4f, worst %.4f mm",
                s["x"]["mean"].get<double>(), s["y"]["mean"].get<double>(), s["z"]["mean"].get<double>(),
                s["x"]["max"].get<double>(), s["y"]["max"].get<double>(), s["z"]["max"].get<double>(),
                in["radius95_mm"]["mean"].get<double>(), in["radius95_mm"]["max"].get<double>());
    const auto &out = a["summary"]["outside"];
    if (!out.is_null()) std::printf(" (past it, to a fifth of the plate beyond: worst %.4f mm)", out["radius95_mm"]["max"].get<double>());
    std::printf("\n");
}

// A device description for cdm_diagnose when --device is absent: the nominal
// geometry, the same default as `calib simulate`, in a temporary file.
struct NominalDevice {
    std::string path;
    ~NominalDevice() {
        if (!path.empty()) unlink(path.c_str());
    }
};

int nominal_device(NominalDevice &nd) {
    char *json = nullptr;
    if (int rc = cdm_nominal_device_json(&json); rc != CDM_OK) return report_error("nominal device", rc);
    const std::string text = json;
    cdm_free_string(json);
    const char *tmpdir = std::getenv("TMPDIR");
    std::string tmpl = std::string(tmpdir && *tmpdir ? tmpdir : "/tmp") + "/cdm-device-XXXXXX";
    std::vector<char> name(tmpl.begin(), tmpl.end());
    name.push_back('\0');
    const int fd = mkstemp(name.data());
    if (fd < 0 || write(fd, text.data(), text.size()) != ssize_t(text.size())) {
        std::fprintf(stderr, "cdm: cannot write a temporary device description in %s: %s\n", tmpl.c_str(),
                     std::strerror(errno));
        if (fd >= 0) close(fd);
        return kExitFailure;
    }
    close(fd);
    nd.path = name.data();
    const auto g = nlohmann::json::parse(text);
    std::fprintf(stderr, "cdm: no --device: using the nominal geometry (a %s mm, b %s mm, m %s mm)\n",
                 num(g.value("a_mm", 0.0)).c_str(), num(g.value("b_mm", 0.0)).c_str(),
                 num(g.value("m_mm", 0.0)).c_str());
    return kExitOk;
}

struct DiagArgs {
    std::string data, device, effects, json_out, report, calib_out;
    std::vector<std::string> before, plugins;
    double jig = -1;
    bool quiet = false, no_candidates = false, no_search = false, keep_outliers = false;
};

int cmd_diagnose(const DiagArgs &a, bool fit_only) {
    const auto effects = split_list(a.effects);
    if (fit_only && effects.empty())
        throw UsageError("calib fit: --effects is required (a comma-separated list, e.g. cable_offset,cable_gain; "
                         "`cdm calib effects` lists them): without effects the calibration would correct nothing");
    const char *const cal_option = fit_only ? "--out" : "--calibration"; // where each names the calibration
    distinct_outputs({{cal_option, a.calib_out}, {"--json", a.json_out}});
    if (!a.calib_out.empty()) json_path(cal_option, a.calib_out);
    {
        std::vector<std::string> inputs = {a.data, a.device};
        inputs.insert(inputs.end(), a.before.begin(), a.before.end());
        check_outputs_first(a.json_out, a.report, "diagnosis.json", inputs);
    }
    if (int rc = load_plugins(a.plugins); rc != kExitOk) return rc;
    NominalDevice nd;
    std::string device = a.device;
    if (device.empty()) {
        if (int rc = nominal_device(nd); rc != kExitOk) return rc;
        device = nd.path;
    }
    nlohmann::json o;
    o["effects"] = effects;
    if (a.jig >= 0) o["jig_tolerance_mm"] = a.jig;
    if (!a.calib_out.empty()) o["calibration_out"] = a.calib_out; // UTF-8: checked above
    if (!fit_only && a.no_candidates) o["candidates"] = false;
    if (!fit_only && a.no_search) o["search"] = false;
    if (a.keep_outliers) o["outliers"] = false;
    char *res = nullptr;
    // fit: cdm_fit, the fit alone (no candidates, review or validation)
    const int rc = (fit_only ? cdm_fit : cdm_diagnose)(a.data.c_str(), device.c_str(), o.dump().c_str(),
                                                       a.quiet ? nullptr : progress_cb, nullptr, &res);
    if (rc != CDM_OK) return report_error(fit_only ? "calib fit" : "calib diagnose", rc);
    const auto r = nlohmann::json::parse(res);
    cdm_free_string(res);
    if (fit_only) {
        std::printf("fitted %s on %s: x rms %.4f y %.4f z %.4f mm (jig tolerance x %.4f mm)\n", a.effects.c_str(),
                    a.data.c_str(), r["error_mm"]["x"]["rms"].get<double>(), r["error_mm"]["y"]["rms"].get<double>(),
                    r["error_mm"]["z"]["rms"].get<double>(), r["jig_tolerance_mm"][0].get<double>());
        print_accuracy(r["accuracy_map"]);
        const auto &out = r["outliers"];
        if (out["count"].get<size_t>() > 0) {
            // The first 20 by name; --json lists every one.
            std::string pts;
            size_t shown = 0;
            for (auto &x : out["set_aside"])
                if (shown++ < 20) pts += (pts.empty() ? "" : ", ") + std::to_string(x["point"].get<long>());
            if (shown > 20) pts += " and " + std::to_string(shown - 20) + " more (--json lists them)";
            std::printf("outliers set aside: %zu of %zu positions, points %s (the model and their neighbours on the "
                        "plate both disown them; --keep-outliers keeps them)\n",
                        out["count"].get<size_t>(), out["positions_read"].get<size_t>(), pts.c_str());
        }
        if (out["declined"]["count"].get<size_t>() > 0)
            std::printf("warning: %zu positions that the fitted model and their neighbours both disown were kept (%s): "
                        "the calibration fits them too; `cdm calib diagnose` says more\n",
                        out["declined"]["count"].get<size_t>(), out["declined"]["why"].get<std::string>().c_str());
        if (r["glitches"]["count"].get<size_t>() > 0)
            std::printf("glitches set aside: %zu samples at %zu positions (beyond %.1f sd)\n",
                        r["glitches"]["count"].get<size_t>(), r["glitches"]["positions"].get<size_t>(),
                        r["glitches"]["threshold_sd"].get<double>());
        if (r.contains("model_check") && !r["model_check"]["explained"].get<bool>())
            std::printf("warning: %s\n", r["model_check"]["text"].get<std::string>().c_str());
        std::printf("calibration written to %s\n", a.calib_out.c_str());
    } else {
        print_summary(r);
    }
    std::vector<std::string> inputs = {a.data, a.device, a.calib_out};
    inputs.insert(inputs.end(), a.before.begin(), a.before.end());
    return write_outputs(a.json_out, a.report, a.before, r, inputs, "diagnosis.json");
}

struct CheckArgs {
    std::string data, calibration, json_out, report;
    std::vector<std::string> plugins;
    double jig = -1, max_error = -1;
    bool quiet = false;
};

void print_check(const CheckArgs &a, const nlohmann::json &r) {
    std::printf("checked %s on %s (%zu positions; %s)\n", a.calibration.c_str(), a.data.c_str(),
                r["positions"].get<size_t>(), r["jig"]["text"].get<std::string>().c_str());
    print_ignored_columns(r);
    std::printf("\nPosition error (mm), estimate - reference, over every sample:\n");
    std::printf("  %-26s  %-34s  %-34s  %-34s\n", "", "x: mean ± std    rms     max", "y: mean ± std    rms     max",
                "z: mean ± std    rms     max");
    print_stats_row("nominal (eq. 1-3)", r["nominal_error_mm"]);
    print_stats_row("calibration", r["error_mm"]);
    const auto &pe = r["position_error_mm"];
    std::printf("  per position (noise averaged out): rms x %.4f y %.4f z %.4f, max x %.4f y %.4f z %.4f\n",
                pe["x"]["rms"].get<double>(), pe["y"]["rms"].get<double>(), pe["z"]["rms"].get<double>(),
                pe["x"]["max"].get<double>(), pe["y"]["max"].get<double>(), pe["z"]["max"].get<double>());
    const auto &cf = r["calibration_fit"];
    if (cf.is_object() && cf.contains("error_mm") && cf["error_mm"].contains("x"))
        std::printf("  on the data it was fitted on: rms x %.4f y %.4f z %.4f\n",
                    cf["error_mm"]["x"]["rms"].get<double>(), cf["error_mm"]["y"]["rms"].get<double>(),
                    cf["error_mm"]["z"]["rms"].get<double>());
    const auto &f = r["failing"];
    std::printf("  failing positions: %zu of %zu\n", f["count"].get<size_t>(), r["positions"].get<size_t>());
    if (f.contains("beyond_max_error"))
        std::printf("  positions beyond %s mm: %zu\n", num(f["beyond_max_error"]["max_error_mm"].get<double>()).c_str(),
                    f["beyond_max_error"]["count"].get<size_t>());
    if (r["predicted"].value("available", false))
        std::printf("  against its accuracy map: %s\n", r["predicted"]["text"].get<std::string>().c_str());
    std::printf("\nVerdict: %s\n", r["model_check"]["text"].get<std::string>().c_str());
}

int cmd_check(const CheckArgs &a) {
    check_outputs_first(a.json_out, a.report, "check.json", {a.data, a.calibration});
    if (int rc = load_plugins(a.plugins); rc != kExitOk) return rc;
    nlohmann::json o = nlohmann::json::object();
    if (a.jig >= 0) o["jig_tolerance_mm"] = a.jig;
    if (a.max_error > 0) o["max_error_mm"] = a.max_error;
    char *res = nullptr;
    const int rc = cdm_check(a.data.c_str(), a.calibration.c_str(), o.dump().c_str(),
                             a.quiet ? nullptr : progress_cb, nullptr, &res);
    if (rc != CDM_OK) return report_error("calib check", rc);
    const auto r = nlohmann::json::parse(res);
    cdm_free_string(res);
    print_check(a, r);
    return write_outputs(a.json_out, a.report, {}, r, {a.data, a.calibration}, "check.json");
}

void add_check(CLI::App *calib) {
    static CheckArgs c;
    auto *chk = calib->add_subcommand("check", "Check a calibration on another jig session without refitting it "
                                               "(the jig placed anew)");
    chk->add_option("data", c.data, "Jig dataset CSV: point,x_ref,y_ref,z_ref,l1,l2,l3,l4")->required();
    chk->add_option("--calibration", c.calibration, "Calibration JSON to check (`cdm calib fit --out`)")->required();
    chk->add_option("--json", c.json_out, "Write the check's JSON here");
    chk->add_option("--report", c.report,
                    "Write the HTML report into this directory: the measured error at each position against the "
                    "error the calibration's accuracy map predicted there (runs $PYTHON -m cdm.report)");
    chk->add_option("--jig-tolerance-mm", c.jig, "Std of the jig's own position error (-1: estimated from the data)")
        ->check(tolerance_or_estimate());
    chk->add_option("--max-error-mm", c.max_error,
                    "List the positions whose mean error is longer than this (mm; default: none)")
        ->check(range(1e-6, 5000));
    add_plugin_option(chk, c.plugins);
    chk->add_flag("--quiet", c.quiet, "No progress output");
    chk->callback([] { select_command([] { return cmd_check(c); }); });
}

struct SimArgs {
    std::string out, effects, truth, device, heights, truth_out, plan;
    std::vector<std::string> plugins;
    int holes = 0, samples = 0;
    double pitch_mm = 0, noise_mm = 0, quant_mm = 0, jig_tolerance_mm = 0, jig_hole_mm = 0, jig_fixture_mm = 0;
    uint64_t seed = 0, effect_seed = 0;
};

// The library's defaults, so that --help shows the numbers it will use.
void sim_defaults(SimArgs &s) {
    char *text = nullptr;
    if (cdm_simulate_jig_defaults(&text) != CDM_OK) return;
    const auto d = nlohmann::json::parse(text);
    cdm_free_string(text);
    s.holes = d.at("holes").get<int>();
    s.samples = d.at("samples").get<int>();
    s.pitch_mm = d.at("pitch_mm").get<double>();
    s.noise_mm = d.at("noise_mm").get<double>();
    s.quant_mm = d.at("quant_mm").get<double>();
    s.jig_tolerance_mm = d.at("jig_tolerance_mm").get<double>();
    s.jig_hole_mm = d.at("jig_hole_mm").get<double>();
    s.jig_fixture_mm = d.at("jig_fixture_mm").get<double>();
    s.seed = d.at("seed").get<uint64_t>();
    s.effect_seed = d.at("effect_seed").get<uint64_t>();
}

int cmd_simulate(const SimArgs &a) {
    nlohmann::json o = {{"holes", a.holes},       {"samples", a.samples},   {"pitch_mm", a.pitch_mm},
                        {"noise_mm", a.noise_mm}, {"quant_mm", a.quant_mm}, {"jig_tolerance_mm", a.jig_tolerance_mm},
                        {"jig_hole_mm", a.jig_hole_mm},   {"jig_fixture_mm", a.jig_fixture_mm},
                        {"seed", a.seed},         {"effect_seed", a.effect_seed}};
    if (!a.heights.empty()) o["heights_mm"] = parse_number_list(a.heights, "--heights");
    if (!a.effects.empty()) o["effects"] = split_list(a.effects);
    if (!a.device.empty()) o["device"] = json_path("--device", a.device);
    if (!a.truth.empty()) o["truth"] = json_path("--truth", a.truth);
    distinct_outputs({{"OUT", a.out}, {"--truth-out", a.truth_out}});
    if (!a.truth_out.empty()) o["truth_out"] = json_path("--truth-out", a.truth_out);
    if (!a.plan.empty()) {
        o["plan"] = read_plan_csv(a.plan, "--plan");
        o["plan_file"] = json_path("--plan", a.plan); // an input: never written over
    }
    if (int rc = load_plugins(a.plugins); rc != kExitOk) return rc;
    if (int rc = cdm_simulate_jig_dataset(a.out.c_str(), o.dump().c_str()); rc != CDM_OK)
        return report_error("calib simulate", rc);
    const size_t n_heights = o.contains("heights_mm") ? o["heights_mm"].size() : 5;
    if (o.contains("plan"))
        std::printf("wrote %s (%zu planned positions of %s)\n", a.out.c_str(), o["plan"].size(), a.plan.c_str());
    else
        std::printf("wrote %s (%zu positions x %d samples)\n", a.out.c_str(),
                    n_heights * size_t(a.holes) * size_t(a.holes), a.samples);
    return kExitOk;
}

int cmd_effects(bool json) {
    nlohmann::json all = nlohmann::json::array();
    for (size_t i = 0; i < cdm_effect_count(); ++i) {
        nlohmann::json e = {{"name", cdm_effect_name(i)}, {"doc", cdm_effect_doc(i)}, {"parameters", nlohmann::json::array()}};
        if (!json) std::printf("%s\n    %s\n    parameters:", cdm_effect_name(i), cdm_effect_doc(i));
        for (size_t k = 0; k < cdm_effect_param_count(i); ++k) {
            const char *name = nullptr, *unit = nullptr;
            double scale = 0, lower = 0, upper = 0;
            if (cdm_effect_param(i, k, &name, &unit, &scale, &lower, &upper) != CDM_OK) continue;
            e["parameters"].push_back(
                {{"name", name}, {"unit", unit}, {"scale", scale}, {"lower", lower}, {"upper", upper}});
            if (!json)
                std::printf(" %s [%s, typical %s, bounds %s..%s]", name, unit, num(scale).c_str(), num(lower).c_str(),
                            num(upper).c_str());
        }
        if (!json) std::printf("\n");
        // A user effect's origin (a plugin's path) and fingerprint, which a
        // calibration written with it records.
        char fp[17];
        const char *origin = nullptr;
        if (cdm_effect_fingerprint(i, fp, sizeof fp, &origin) == CDM_OK && origin && *origin) {
            e["origin"] = origin;
            e["fingerprint"] = fp;
            if (!json) std::printf("    from %s, fingerprint %s\n", origin, fp);
        }
        all.push_back(e);
    }
    if (json) std::printf("%s\n", all.dump(1).c_str());
    return kExitOk;
}

void add_diagnose_options(CLI::App *c, DiagArgs &d) {
    c->add_option("data", d.data, "Jig dataset CSV: point,x_ref,y_ref,z_ref,l1,l2,l3,l4")->required();
    c->add_option("--device", d.device,
                  "Device description JSON {\"a_mm\":..,\"b_mm\":..,\"m_mm\":..} (default: the nominal a=b=150, "
                  "m=30 mm)");
    c->add_option("--jig-tolerance-mm", d.jig, "Std of the jig's own position error (-1: estimated from the data)")
        ->check(tolerance_or_estimate());
    add_plugin_option(c, d.plugins);
    c->add_flag("--quiet", d.quiet, "No progress output");
}

void add_simulate(CLI::App *calib) {
    static SimArgs s;
    sim_defaults(s);
    auto *sim = calib->add_subcommand("simulate", "Write a simulated jig dataset (the seed's experiment) from a known model");
    sim->add_option("out", s.out, "Dataset CSV to write")->required();
    sim->add_option("--device", s.device, "Device description JSON (default: the nominal a=b=150, m=30 mm)");
    sim->add_option("--effects", s.effects,
                    "Hidden effects, a comma-separated list (e.g. exit_pulley,cable_gain), random realistic "
                    "magnitudes (default: none)");
    sim->add_option("--effect-seed", s.effect_seed, "Seed of the hidden effects' magnitudes")->check(range(0, kMaxSeed));
    sim->add_option("--truth", s.truth, "Calibration JSON to use as the true model (default: the nominal model)");
    add_plugin_option(sim, s.plugins);
    sim->add_option("--truth-out", s.truth_out, "Write the true model (with the hidden magnitudes) here");
    sim->add_option("--seed", s.seed, "Noise seed")->check(range(0, kMaxSeed));
    sim->add_option("--noise-mm", s.noise_mm, "Per-sample pot noise std (mm)")->check(range(0, 100));
    sim->add_option("--quant-mm", s.quant_mm, "ADC step (mm)")->check(range(0, 100));
    sim->add_option("--jig-tolerance-mm", s.jig_tolerance_mm, "Std of each position's own error (mm)")
        ->check(range(0, 100));
    sim->add_option("--jig-hole-mm", s.jig_hole_mm,
                    "Std of each plate hole's (y, z) error, the same at every height (a plate drilled once) (mm)")
        ->check(range(0, 100));
    sim->add_option("--jig-fixture-mm", s.jig_fixture_mm,
                    "Std of each fixture height's x error, the same at every hole (a spacer machined once) (mm)")
        ->check(range(0, 100));
    sim->add_option("--samples", s.samples, "Samples per position")->check(range(1, 1000000));
    sim->add_option("--holes", s.holes, "Holes per side of the plate")->check(range(1, 1000));
    sim->add_option("--pitch-mm", s.pitch_mm, "Hole pitch (mm)")->check(range(1e-3, 1000));
    sim->add_option("--heights", s.heights, "Comma-separated fixture heights (mm) (default: 30,40,50,60,70)");
    sim->add_option("--plan", s.plan,
                    "Only the positions of this PLAN.csv (`cdm calib plan`), each with its samples; the plate and "
                    "heights as given here");
    sim->callback([] { select_command([] { return cmd_simulate(s); }); });
}

} // namespace

void add_calib_commands(CLI::App &app) {
    auto *calib = app.add_subcommand("calib", "Model debugging: compare the model with jig data, find what is missing, "
                                              "fit, write a calibration (docs/calibration.md)");
    calib->require_subcommand(0, 1);

    static DiagArgs d, f;
    auto *diag = calib->add_subcommand("diagnose", "Fit the model with the given effects and diagnose what it misses");
    add_diagnose_options(diag, d);
    diag->add_option("--effects", d.effects,
                     "Effects to fit, a comma-separated list (e.g. cable_offset,cable_gain) (default: none, the "
                     "nominal model)");
    diag->add_option("--json", d.json_out, "Write the diagnosis JSON here");
    diag->add_option("--report", d.report,
                     "Write the HTML report with figures into this directory (runs $PYTHON -m cdm.report; PYTHON "
                     "defaults to python3)");
    diag->add_option("--before", d.before, "Earlier diagnosis JSON files to compare in the report");
    diag->add_option("--calibration", d.calib_out, "Also write the fitted calibration JSON");
    diag->add_flag("--no-candidates", d.no_candidates,
                   "Skip the ranking of missing effects (and the search): the verdict then says nothing about "
                   "which effect could be missing");
    diag->add_flag("--no-search", d.no_search,
                   "Skip the model search (forward-backward stepwise by BIC from --effects; on by default)");
    diag->add_flag("--keep-outliers", d.keep_outliers,
                   "Keep every position: by default positions that the model and their neighbours on the plate "
                   "both disown (a mis-seated probe, a wrong hole) are set aside and the diagnosis run again");
    diag->callback([] { select_command([] { return cmd_diagnose(d, false); }); });

    auto *fit = calib->add_subcommand("fit", "Fit the model with the given effects and write the calibration");
    add_diagnose_options(fit, f);
    fit->add_option("--effects", f.effects,
                    "Effects to fit, a comma-separated list (e.g. cable_offset,cable_gain); required")
        ->required();
    fit->add_option("--out", f.calib_out, "Calibration JSON to write")->required();
    fit->add_option("--json", f.json_out, "Also write the fit statistics JSON");
    fit->add_flag("--keep-outliers", f.keep_outliers,
                  "Keep every position: by default positions that the fitted model and their neighbours on the "
                  "plate both disown (a mis-seated probe, a wrong hole) are set aside and the fit run again");
    fit->callback([] { select_command([] { return cmd_diagnose(f, true); }); });

    add_simulate(calib);
    add_check(calib);
    add_plan(calib);

    auto *eff = calib->add_subcommand("effects", "List the effect catalogue with each effect's physics");
    static bool e_json = false;
    static std::vector<std::string> e_plugins;
    eff->add_flag("--json", e_json, "print a JSON array of {name, doc, parameters[{name, unit, scale, lower, upper}]}");
    add_plugin_option(eff, e_plugins);
    eff->callback([] {
        select_command([] {
            if (int rc = load_plugins(e_plugins); rc != kExitOk) return rc;
            return cmd_effects(e_json);
        });
    });
}

} // namespace cdm::cli
