// The model-debugging workflow on simulated jig data: every catalogued
// effect hidden in turn (random magnitudes in its realistic range) must be
// ranked first, or be in the reported inseparable set of the first; with it
// added the residual must be consistent with noise. Clean data must come out
// explained; an effect outside the catalogue must come out unexplained with
// its signature found, and a user-defined effect must then remove it.
//
// The jig is the seed's at half resolution (13x13 holes at 10 mm, 5 heights,
// 40 samples) to keep the test short; the statistics do not depend on the
// grid being 25x25. Noise 0.05 mm, ADC step 0.01 mm, jig tolerance 0.03 mm.
#include <algorithm>
#include <cmath>
#include <random>
#include <regex>
#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>

#include <cfloat>
#include <fcntl.h>
#include <unistd.h>

#include "calib/evaluation/eval.h"
#include "calib/evaluation/outliers.h"
#include "calib/evaluation/spatial.h"
#include "calib/diagnosis/diagnose.h"
#include "calib/fit/fit.h"
#include "calib/dataset/simulate.h"
#include "model/effect.h"

extern "C" {
#include <cmocka.h>
}
#include "jig_text.h"
#include "shard.h"

using namespace cdm;


static nlohmann::json run(const Model &truth, uint64_t seed, std::vector<std::string> effects, bool candidates,
                          bool scattered = false, double hole_mm = 0, double fixture_mm = 0) {
    Dataset d;
    std::string err;
    JigSimOptions so = test::half_jig(seed);
    so.scattered = scattered;
    so.jig_hole_mm = hole_mm;
    so.jig_fixture_mm = fixture_mm;
    assert_true(simulate_jig(truth, so, d, err));
    DiagnoseOptions o;
    o.effects = std::move(effects);
    o.candidates = candidates;
    o.validation = false;
    o.per_position = false;
    nlohmann::json out;
    Model fitted{DeviceGeometry{}};
    if (!diagnose(d, truth.geometry(), o, out, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
    // The simulator's jigs have no outliers (every position is seated to
    // the jig's tolerance): none may be set aside, whatever is hidden.
    if (out["data"]["outliers"]["count"].get<int>() != 0)
        fail_msg("outliers set aside in data without any: %s", out["data"]["outliers"].dump().c_str());
    return out;
}

static void clean_data_is_explained(void **) {
    for (uint64_t seed : {5u, 6u}) {
        auto r = run(Model{DeviceGeometry{}}, seed, {}, false);
        if (!r["explained"].get<bool>())
            fail_msg("clean data (seed %d) not explained: chi2/dof %g structure p %g", int(seed),
                     r["chi2_per_dof"].get<double>(), r["structure"]["p_value"].get<double>());
        // the jig tolerance estimate recovers the simulated 0.03 mm to within
        // its sampling error (~5 % for ~1000 second differences per axis)
        assert_true(std::fabs(r["jig_tolerance_mm"]["value"].get<double>() - 0.03) < 0.006);
    }
}

static void each_hidden_effect_is_found(void **) {
    uint64_t k = 0;
    for (auto &e : candidate_effects()) {
        if (e->stage == Stage::User) continue;
        ++k;
        Model truth{DeviceGeometry{}};
        std::string err;
        assert_true(truth.add_effect_random(e->name, 100 + k, err));
        auto r = run(truth, 200 + k, {}, true);
        assert_false(r["explained"].get<bool>());
        const auto &top = r["candidates"][0];
        bool found = top["effect"] == e->name;
        for (auto &c : top["confused_with"]) found = found || c == e->name;
        if (!found) fail_msg("hidden %s: ranked first %s", e->name.c_str(), top["effect"].get<std::string>().c_str());
        auto r2 = run(truth, 200 + k, {e->name}, false);
        // Paired with the same noise and no effect at all: with the effect
        // added, the statistics must be those of clean data (the explained
        // test has a false-alarm rate of ~1e-3 per dataset, so the clean
        // twin's statistics, not the verdict, are the reference). chi2/dof of clean
        // data scatters by sqrt(2/dof) ~ 0.03 between seeds but by far less
        // between twins; the structure z by < 1.
        auto clean = run(Model{truth.geometry()}, 200 + k, {}, false);
        const double dz = r2["structure"]["statistic"].get<double>() - clean["structure"]["statistic"].get<double>();
        const double dc = r2["chi2_per_dof"].get<double>() - clean["chi2_per_dof"].get<double>();
        if (std::fabs(dz) > 1.0 || std::fabs(dc) > 0.03)
            fail_msg("with %s added: chi2/dof %g structure z %g; clean twin: %g, %g", e->name.c_str(),
                     r2["chi2_per_dof"].get<double>(), r2["structure"]["statistic"].get<double>(),
                     clean["chi2_per_dof"].get<double>(), clean["structure"]["statistic"].get<double>());
        // and the x error is down to the noise floor (within the ~3 % a
        // sampled RMS of ~1e5 values and the fitted parameters' own error allow)
        assert_true(r2["error_mm"]["x"]["rms"].get<double>() < 1.05 * r2["noise_floor_mm"]["x"]["rms"].get<double>());
    }
}

// Beyond the catalogue: a worn spot on the pot tracks. Where the cable
// rests at the home position the wiper has worn a dip into each track, so
// the reading is off in a narrow band of cable length (a Gaussian of 6 mm
// around 180 mm): nothing in the catalogue is local in length like that.
struct WornSpot {
    double centre_mm = 180, width_mm = 6;
};
static WornSpot kSpot;
static int worn_spot(void *user, const double *p, const double *, double r[4]) {
    const WornSpot &w = *static_cast<WornSpot *>(user);
    for (int i = 0; i < 4; ++i) {
        const double u = (r[i] - w.centre_mm) / w.width_mm;
        r[i] += p[0] * std::exp(-u * u);
    }
    return 0;
}
static void register_worn_spot() {
    static const char *names[] = {"depth_mm"};
    static const double scale[] = {0.1};
    cdm_effect_def d{};
    d.struct_size = sizeof d;
    d.n_params = 1;
    d.name = "worn_spot";
    d.doc = "a dip worn into the pot tracks around one cable length";
    d.param_names = names;
    d.param_scale = scale;
    d.apply = worn_spot;
    d.user = &kSpot;
    assert_int_equal(cdm_effect_register(&d), CDM_OK);
}

static void effect_outside_catalogue(void **) {
    register_worn_spot();
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("worn_spot", ParamValues{{"depth_mm", -0.25}}, err));
    assert_int_equal(cdm_effect_unregister("worn_spot"), CDM_OK); // the catalogue does not know it
    auto r = run(truth, 77, {}, true);
    assert_false(r["explained"].get<bool>());
    for (auto &c : r["candidates"])
        if (c["explained_after"].get<bool>()) fail_msg("%s explains a worn spot", c["effect"].dump().c_str());
    // The search lands on what the catalogue can do, and says it is not enough.
    assert_false(r["recommended"]["explained"].get<bool>());
    assert_false(r["recommended"]["negligible_only"].get<bool>());
    register_worn_spot(); // the user adds it
    auto r2 = run(truth, 77, {"worn_spot"}, true);
    if (!r2["explained"].get<bool>())
        fail_msg("with the user effect: %s", r2["verdict"].dump().c_str());
    const double depth = r2["params"]["worn_spot"]["depth_mm"]["value"].get<double>();
    const double sd = r2["params"]["worn_spot"]["depth_mm"]["std"].get<double>();
    // Within 5 standard errors of the truth (the fit's own uncertainty).
    if (std::fabs(depth + 0.25) > 5 * sd) fail_msg("depth %g +- %g, truth -0.25", depth, sd);
    assert_int_equal(cdm_effect_unregister("worn_spot"), CDM_OK);
}


// The verdict never contradicts a number beside it: `explained` only when
// the chi-square and structure tests pass at 1e-3, no candidate on top is
// significant and no finding is listed; the same for the recommended model.
static void check_consistent(const nlohmann::json &r) {
    auto check = [](const nlohmann::json &explained, const nlohmann::json &cands, double chi2_p, double struct_p,
                    const nlohmann::json *findings, const char *what) {
        if (!explained.get<bool>()) return;
        if (chi2_p < 1e-3 || struct_p < 1e-3) fail_msg("%s explained with chi2 p %g structure p %g", what, chi2_p, struct_p);
        for (auto &c : cands)
            if (c["significant"].get<bool>()) fail_msg("%s explained beside significant %s", what, c["effect"].dump().c_str());
        if (findings && !findings->empty()) fail_msg("%s explained beside findings %s", what, findings->dump().c_str());
    };
    const auto &f = r["unexplained_structure"]["findings"];
    const auto &rec = r["recommended"];
    // A candidate contains the model it extends (its effect at the neutral
    // start): its fit should not end above it. One unit of chi-square is
    // the base fit's own convergence (calib/search/candidates.cpp): below it no test
    // moves. (While the fixture offsets' profile clamped them off their
    // sum-zero gauge, the fixture-height test's exit_pulley row read delta
    // chi2 -629485 on the nominal model.) Not a theorem: the fit minimises
    // chi2 plus the fixture offsets' prior, and a candidate that moves the
    // jig's x (exit_pulley) may give back chi-square for a smaller offset:
    // with the jig 0.15 mm off in x (a_jig_off_in_x_is_the_jigs) its row
    // read -6.4 and exit_pulley's -1.7, the prior's cost (about 45)
    // falling by more. Allowed: the base's offsets' whole prior cost, sum
    // (o / 0.05 mm)^2, the base's own fitted offsets: the user's model's
    // (fit.fixture_x_mm) for its table, the recommended model's
    // (jig.fixture_fitted_x_mm) for the recommendation's. A base chi-square
    // too low by less than that goes unseen; the -629485 class does not.
    auto give_back = [](const nlohmann::json &offsets) {
        double s = 0;
        if (offsets.is_array())
            for (auto &v : offsets) {
                const double o = std::min(std::fabs(v.get<double>()), kFixtureMaxMm) / kFixturePriorSdMm;
                s += o * o;
            }
        return s;
    };
    const std::pair<const nlohmann::json *, double> tables[] = {
        {&r["candidates"], give_back(r["fit"]["fixture_x_mm"])},
        {rec.is_null() ? nullptr : &rec["candidates"], give_back(r["jig"]["fixture_fitted_x_mm"])}};
    for (const auto &t : tables)
        if (t.first)
            for (auto &c : *t.first)
                if (c["delta_chi2"].get<double>() < -1 - t.second)
                    fail_msg("candidate %s ended above the model it extends: delta chi2 %g (the offsets' prior "
                             "could give back %g)",
                             c["effect"].dump().c_str(), c["delta_chi2"].get<double>(), t.second);
    if (!rec.is_null())
        check(rec["explained"], rec["candidates"], rec["chi2_p_value"].get<double>(),
              rec["structure"]["p_value"].get<double>(), &f, "the recommended model");
    // A candidate significant on top of the recommended model is named in
    // the verdict's sentence on it: each of its lists gives the strongest
    // three, then "; and N more"; the names found and those counts together
    // cover every significant candidate.
    if (!rec.is_null() && r["verdict"].is_string()) {
        const std::string v = r["verdict"].get<std::string>();
        std::string head = v.substr(0, v.find(" Search from"));
        head = head.substr(0, head.find(" Your model"));
        size_t named = 0, significant = 0, more = 0;
        std::string missing;
        for (auto &c : rec["candidates"]) {
            if (!c["significant"].get<bool>()) continue;
            ++significant;
            const std::string name = c["effect"].get<std::string>();
            if (head.find(name + " (Delta chi2") != std::string::npos)
                ++named;
            else
                missing += name + " ";
        }
        static const std::regex kMore("; and ([0-9]+) more");
        for (std::sregex_iterator it(head.begin(), head.end(), kMore), end; it != end; ++it)
            more += std::stoul((*it)[1].str());
        // The two tests' p-values as printed on the recommended model
        // ("chi2/dof 1.02 (p = 0.210), spatial structure z = 3.4 (p =
        // 0.0012)") read as the JSON's within their rounding (5 %): p =
        // 0.0012 printed as "p = 0.001" beside "explains the data" read as a
        // p at the level (1e-3).
        {
            static const std::regex kP("\\(p ([=<]) ([0-9.e+-]+)\\)");
            const double want[2] = {rec["chi2_p_value"].get<double>(), rec["structure"]["p_value"].get<double>()};
            int k = 0;
            for (std::sregex_iterator it(head.begin(), head.end(), kP), end; it != end && k < 2; ++it, ++k) {
                if ((*it)[1].str() == "<") continue;
                const double shown = std::stod((*it)[2].str());
                if (!(std::fabs(shown - want[k]) <= 0.051 * want[k]))
                    fail_msg("the recommended model's p %g is printed as %s: %s", want[k], (*it)[2].str().c_str(),
                             head.c_str());
            }
            if (k < 2) fail_msg("the verdict's head does not print the two tests' p: %s", head.c_str());
        }
        if (named + more < significant)
            fail_msg("the verdict names %zu of the %zu candidates significant on the recommended model (and %zu more); "
                     "not named: %s: %s",
                     named, significant, more, missing.c_str(), head.c_str());
    }
    const bool same = rec.is_null() || rec["effects"] == r["model"];
    check(r["explained"], r["candidates"], r["chi2_p_value"].get<double>(), r["structure"]["p_value"].get<double>(),
          same ? &f : nullptr, "the user's model");
}

// The diagnosis as the scenario tests run it on a dataset (the search on;
// no validation, no per-position arrays; outliers as asked), checked
// against its own numbers.
static nlohmann::json diagnosed(const Dataset &d, const Model &truth, bool outliers = true) {
    DiagnoseOptions o;
    o.validation = false;
    o.per_position = false;
    o.outliers = outliers;
    nlohmann::json r;
    std::string err;
    Model fitted{DeviceGeometry{}};
    if (!diagnose(d, truth.geometry(), o, r, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
    check_consistent(r);
    return r;
}

static std::vector<std::string> sorted_names(const nlohmann::json &a) {
    std::vector<std::string> v;
    for (auto &e : a) v.push_back(e.get<std::string>());
    std::sort(v.begin(), v.end());
    return v;
}

// Hidden effects, each with its magnitudes (empty: random ones from the seed).
using Truth = std::vector<std::pair<std::string, ParamValues>>;

// The true model, and the names of its effects, sorted, into `want`.
static Model make_truth(const Truth &t, uint64_t seed, std::vector<std::string> &want) {
    Model truth{DeviceGeometry{}};
    std::string err;
    want.clear();
    for (auto &e : t) {
        if (e.second.empty())
            assert_true(truth.add_effect_random(e.first, seed, err));
        else
            assert_true(truth.add_effect(e.first, e.second, err));
        want.push_back(e.first);
    }
    std::sort(want.begin(), want.end());
    return truth;
}

// The search lands on `want`: the recommended model, or one the data cannot
// tell from it (an alternative).
static void assert_lands_on(const nlohmann::json &r, const std::vector<std::string> &want) {
    const auto &rec = r["recommended"];
    bool found = sorted_names(rec["effects"]) == want;
    for (auto &alt : rec["alternatives"]) found = found || sorted_names(alt) == want;
    if (!found) fail_msg("hidden %s: recommended %s, alternatives %s", nlohmann::json(want).dump().c_str(),
                         rec["effects"].dump().c_str(), rec["alternatives"].dump().c_str());
}

// Several effects hidden at once, small ones among them: following the
// recommendation lands on them (or on a set the data cannot tell from them,
// listed as an alternative), at the noise floor, with nothing extra.
static void search_lands_on_hidden_effects(void **) {
    const std::vector<Truth> cases = {
        {{"cable_gain", {{"g1", 0.002}, {"g2", -0.0015}, {"g3", 0.001}, {"g4", -0.002}}},
         {"exit_pulley", {{"radius_mm", 1.0}}}},
        {{"cable_offset", {{"o1", 0.3}, {"o2", -0.2}, {"o3", 0.25}, {"o4", -0.3}}},
         {"jig_misalignment", {}}},
        {{"exit_pulley", {{"radius_mm", 3.0}}},
         {"drum_eccentricity", {{"period", 94.2}, {"a1", 0.15}, {"a2", 0.15}, {"a3", 0.15}, {"a4", 0.15}}}},
    };
    uint64_t seed = 400;
    for (auto &c : cases) {
        std::vector<std::string> want;
        const Model truth = make_truth(c, seed, want);
        auto r = run(truth, ++seed, {}, true);
        check_consistent(r);
        assert_lands_on(r, want);
        const auto &rec = r["recommended"];
        if (!rec["explained"].get<bool>() && !rec["negligible_only"].get<bool>())
            fail_msg("recommended model not explained: %s", r["verdict"].dump().c_str());
        // At the noise floor: within the ~3 % a sampled RMS allows.
        const double xr = rec["error_mm"]["x"]["rms"].get<double>();
        const double nf = rec["noise_floor_mm"][0].get<double>();
        if (xr > 1.05 * nf) fail_msg("recommended x RMS %g above the noise floor %g", xr, nf);
        assert_true(r["verdict"].get<std::string>().rfind("Recommended model: ", 0) == 0);
    }
}

// `cdm calib simulate --effects cable_gain,exit_pulley` (effect seed 1: gains
// of 0.6-0.9 %, a 6.9 mm pulley) on the small jig, noise seed 1: with each
// fit weighing the data as its own start does, the search recommends
// cable_stretch beside the two (a stretch changes that weighting), while the
// review of the same three effects says to drop it. Every chi-square a step
// compares is weighed as the model it stands on: exactly the two.
static void realistic_gain_and_pulley_nothing_extra(void **) {
    std::vector<std::string> want;
    const Model truth = make_truth({{"exit_pulley", {{"radius_mm", 6.933110955199806}}},
                                    {"cable_gain",
                                     {{"g1", 0.006412970711184978},
                                      {"g2", 0.009026368482865109},
                                      {"g3", 0.00828023776738099},
                                      {"g4", 0.00891012159831646}}}},
                                   1, want);
    auto r = run(truth, 1, {}, true);
    check_consistent(r);
    const auto &rec = r["recommended"];
    if (sorted_names(rec["effects"]) != want)
        fail_msg("recommended %s, hidden %s; path %s", rec["effects"].dump().c_str(), nlohmann::json(want).dump().c_str(),
                 rec["path"].dump().c_str());
    assert_true(rec["explained"].get<bool>());
}

// A sparse, noisy jig (3 heights, 10 mm pitch, 13 x 13 holes, 10
// samples, pot noise 0.25 mm, the default 0.03 mm seating error): the per-
// position noise estimate from 10 samples is poor, and a chi-square that
// takes it at face value (or its maximum with the pooled one) calls the
// true model "not explained" (chi2/dof 1.13 on 1,500 dof). Clean
// data must come out explained with nothing added; two hidden effects must
// be found (or an inseparable equivalent), explained.
static void sparse_noisy_jig(void **) {
    const std::vector<Truth> cases = {
        {},
        {{"cable_gain", {{"g1", 0.002}, {"g2", -0.0015}, {"g3", 0.001}, {"g4", -0.002}}},
         {"exit_pulley", {{"radius_mm", 1.0}}}},
    };
    uint64_t seed = 700;
    for (auto &c : cases) {
        std::vector<std::string> want;
        const Model truth = make_truth(c, seed, want);
        std::string err;
        JigSimOptions so = test::half_jig(++seed);
        so.heights = {30, 50, 70};
        so.samples = 10;
        so.noise_mm = 0.25;
        Dataset d;
        assert_true(simulate_jig(truth, so, d, err));
        const nlohmann::json r = diagnosed(d, truth);
        assert_lands_on(r, want);
        const auto &rec = r["recommended"];
        if (!rec["explained"].get<bool>())
            fail_msg("sparse jig, recommended model not explained: %s", r["verdict"].dump().c_str());
    }
    // The chi-square of the true model itself, over 6 independent jigs: its
    // sum must be chi-square with the summed dof, sd sqrt(2 * 9,000) = 134
    // (the jig tolerance estimated from the same residuals only narrows
    // it). The old noise model gave chi2/dof 1.03 to 1.16 on every seed,
    // Z about 7; the bound is 4 sd.
    double chi2 = 0, dof = 0;
    for (int k = 0; k < 6; ++k) {
        Model truth{DeviceGeometry{}};
        std::string err;
        assert_true(truth.add_effect("cable_gain", {{"g1", 0.002}, {"g2", -0.0015}, {"g3", 0.001}, {"g4", -0.002}}, err));
        assert_true(truth.add_effect("exit_pulley", {{"radius_mm", 1.0}}, err));
        JigSimOptions so = test::half_jig(800 + uint64_t(k));
        so.heights = {30, 50, 70};
        so.samples = 10;
        so.noise_mm = 0.25;
        Dataset d;
        assert_true(simulate_jig(truth, so, d, err));
        DiagnoseOptions o;
        o.effects = {"cable_gain", "exit_pulley"};
        o.candidates = false;
        o.search = false;
        o.validation = false;
        o.per_position = false;
        nlohmann::json r;
        Model fitted{DeviceGeometry{}};
        if (!diagnose(d, truth.geometry(), o, r, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
        chi2 += r["chi2_per_dof"].get<double>() * r["dof"].get<double>();
        dof += r["dof"].get<double>();
    }
    const double z = (chi2 - dof) / std::sqrt(2 * dof);
    if (std::fabs(z) > 4) fail_msg("sparse jig, true model: chi2 %g on %g dof (Z %.2f)", chi2, dof, z);
}

// The noise model's shrinkage (prepare()): with one noise everywhere each
// position's variance is pulled toward the pooled one (prior weight 50);
// where a tenth of the positions are really 4x noisier in variance, the
// spread of the sample variances says so and they keep most of their own
// (a fixed weight of 50 gives them 1.7x the pooled's 1/1.3, 0.43 of their
// truth, and a chi-square 2.3x too large there). Sample variances
// drawn as sigma^2 chi2(9)/9 (10 samples), 600 positions.
static void noisier_positions_keep_their_variance(void **) {
    for (bool uneven : {false, true}) {
        Dataset d;
        uint64_t s = 12345;
        auto unif = [&]() {
            s = s * 6364136223846793005ULL + 1442695040888963407ULL;
            return (double(s >> 11) + 0.5) / 9007199254740992.0;
        };
        auto gauss = [&]() { return std::sqrt(-2 * std::log(unif())) * std::cos(2 * M_PI * unif()); };
        double noisy_ratio = 0, quiet_ratio = 0;
        int noisy = 0, quiet = 0;
        for (int j = 0; j < 600; ++j) {
            JigHole h;
            h.n = 10;
            h.ref[0] = 30;
            h.ref[1] = j;
            const double var = (uneven && j % 10 == 0 ? 4.0 : 1.0) * 0.0025;
            for (int c = 0; c < 4; ++c) {
                double chi = 0;
                for (int k = 0; k < 9; ++k) {
                    const double g = gauss();
                    chi += g * g;
                }
                h.cov[c][c] = var * chi / 9;
                h.mean[c] = 200;
            }
            d.pos.push_back(h);
        }
        const auto pp = prepare(d);
        for (size_t j = 0; j < pp.size(); ++j) {
            const double truth = (uneven && j % 10 == 0 ? 4.0 : 1.0) * 0.0025 / 10;
            for (int c = 0; c < 4; ++c) {
                if (uneven && j % 10 == 0) {
                    noisy_ratio += pp[j].var_mean(c) / truth;
                    ++noisy;
                } else {
                    quiet_ratio += pp[j].var_mean(c) / truth;
                    ++quiet;
                }
            }
        }
        quiet_ratio /= quiet;
        if (!uneven) {
            // One noise: nearly the pooled everywhere, so the ratio's mean is
            // 1 within the pooled estimate's sampling error (600 x 9 x 4 dof).
            if (std::fabs(quiet_ratio - 1) > 0.05) fail_msg("even noise: var_mean / truth %g", quiet_ratio);
            continue;
        }
        noisy_ratio /= noisy;
        // The prior by moments here is nu0 = 4 + 2 / 0.48 = 8.2, so they get
        // (9 x 4 + 8.2 x 1.3) / 17.2 / 4 = 0.68 of it; a fixed 50 gives
        // 0.43. 0.6 lies between, far beyond the mean's spread (about 0.02
        // over 240 values).
        if (noisy_ratio < 0.6) fail_msg("4x noisier positions get %g of their variance", noisy_ratio);
        // The quiet majority is not pulled up much by the noisy tenth
        // (the pooled is 1.3x theirs; their own weighs in).
        if (quiet_ratio > 1.2) fail_msg("quiet positions get %g of their variance", quiet_ratio);
    }
}

// A drum ripple: the period is fitted, within 1 % of the truth and within
// 5 of its own standard errors.
static void ripple_period_is_fitted(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("drum_eccentricity",
                                 ParamValues{{"period", 94.2}, {"a1", 0.15}, {"b2", 0.15}, {"a3", -0.15}, {"b4", -0.15}},
                                 err));
    auto r = run(truth, 501, {}, true);
    check_consistent(r);
    const auto &rec = r["recommended"];
    assert_true(sorted_names(rec["effects"]) == std::vector<std::string>{"drum_eccentricity"});
    const double per = rec["params"]["drum_eccentricity"]["period"]["value"].get<double>();
    const double sd = rec["params"]["drum_eccentricity"]["period"]["std"].get<double>();
    if (std::fabs(per - 94.2) > 0.01 * 94.2 || std::fabs(per - 94.2) > 5 * sd)
        fail_msg("period %g +- %g mm, truth 94.2", per, sd);
}

// A real plate: each hole off by the same amount at every height (0.03 mm
// in y and z), each fixture height off in x (0.03 mm), beside anchor errors
// and an exit pulley. With the true effects, and after the search, the model
// explains the data (or leaves only what is under a tenth of the noise
// floor); the plate's holes and the fixture are named as the jig's, with
// the holes' size within 25 % (169 holes x 5 heights: the estimate's own
// relative spread is ~1/sqrt(2 x 169) = 5 %, and the seat scatter, 0.03 mm,
// is as large as the hole errors); and no trend or repeat is left as a
// finding.
static void plate_is_named_as_the_jig(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("anchor_position", 77, err));
    assert_true(truth.add_effect("exit_pulley", ParamValues{{"radius_mm", 2.0}}, err));
    for (bool search : {false, true}) {
        auto r = run(truth, 610, search ? std::vector<std::string>{} : std::vector<std::string>{"anchor_position",
                                                                                            "exit_pulley"},
                     true, false, 0.03, 0.03);
        check_consistent(r);
        const auto &judged = search ? r["recommended"] : r;
        if (!judged["explained"].get<bool>() && !judged["negligible_only"].get<bool>())
            fail_msg("a plate's own errors left the model unexplained: %s", r["verdict"].dump().c_str());
        if (search) { // the true effects, or a set the data cannot tell from them
            const std::vector<std::string> want{"anchor_position", "exit_pulley"};
            bool found = sorted_names(judged["effects"]) == want;
            for (auto &alt : judged["alternatives"]) found = found || sorted_names(alt) == want;
            if (!found)
                fail_msg("search on a real plate recommends %s, alternatives %s", judged["effects"].dump().c_str(),
                         judged["alternatives"].dump().c_str());
        }
        const auto &jig = r["jig"];
        if (jig["holes"]["named"] != "plate") fail_msg("holes not named as the plate's: %s", jig.dump().c_str());
        for (const char *a : {"y", "z"}) {
            const double s = jig["holes"]["std_mm"][a].get<double>();
            if (std::fabs(s - 0.03) > 0.25 * 0.03) fail_msg("hole error %s %g mm, truth 0.03", a, s);
        }
        const std::string v = r["verdict"].get<std::string>();
        if (v.find("the plate's holes are off by about") == std::string::npos ||
            v.find("the height fixture's spacers") == std::string::npos)
            fail_msg("the verdict does not name the jig: %s", v.c_str());
        if (!r["unexplained_structure"]["findings"].empty())
            fail_msg("findings on a plate's own errors: %s", r["unexplained_structure"]["findings"].dump().c_str());
    }
}

// A fixture height off by three standard deviations of the spacers'
// tolerance (fixture 0.05 mm per height, one height at 0.153 mm, holes
// 0.04 mm, seats 0.01 mm, hidden cable_gain). With the bound at three
// (0.15 mm) the fit stops the offset on it and a judge taking a height's mean
// out only within the bound takes none of it: "not explained" (chi2/dof
// 4.7), and the search adds jig_misalignment and pot_drift to chase the
// height. With the bound at five (0.25 mm) and the judge clamping a mean past
// it as the fit does, the search lands on the truth, explained.
static void a_three_sigma_fixture_height_is_the_jigs(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("cable_gain", ParamValues{{"g1", -0.004860096290106038}, {"g2", 0.009673002994543035},
                                                           {"g3", -0.007781211680338852}, {"g4", -0.0076124605468636305}},
                                 err));
    Dataset d;
    JigSimOptions so = test::half_jig(51);
    so.jig_hole_mm = 0.04;
    so.jig_fixture_mm = 0.05;
    so.jig_tolerance_mm = 0.01;
    assert_true(simulate_jig(truth, so, d, err));
    const auto r = diagnosed(d, truth);
    double worst = 0;
    for (auto &v : r["jig"]["fixture"]["offsets_mm"]["x"]) worst = std::max(worst, std::fabs(v.get<double>()));
    if (!(worst > 0.15)) fail_msg("premise: no fixture height past 0.15 mm (largest %g)", worst);
    assert_lands_on(r, {"cable_gain"});
    if (!r["recommended"]["explained"].get<bool>() && !r["recommended"]["negligible_only"].get<bool>())
        fail_msg("a fixture height at %g mm left the true model unexplained: %s", worst, r["verdict"].dump().c_str());
}

// Spacers are off by their own amounts, so their mean is off too: the
// jig's placement along x, not the device's. On clean data with spacers
// machined to 0.05 mm, offsets summing to zero leave that mean to the
// device, and the search then recommends cable_stretch or exit_pulley for it
// on four of six noise seeds (601-606; the mean is -0.032 mm on seed 602).
// With every offset free, the nominal model must be
// recommended with nothing added. Premise: the nominal model's mean x error
// (the spacers' mean) on these seeds is at least 0.02 mm, some 25 standard errors of a height's mean x
// (noise 0.05 mm / sqrt(169 holes x 40 samples) ~ 0.0006 mm, with the seat
// scatter ~ 0.002 mm), so a device effect would gain a great deal by it.
static void spacers_mean_adds_nothing(void **) {
    for (uint64_t seed : {602u, 604u}) {
        auto r = run(Model{DeviceGeometry{}}, seed, {}, true, false, 0.0, 0.05);
        check_consistent(r);
        // the nominal model's mean x error: the spacers' mean (what the fit
        // does with it does not enter)
        const double mean = r["nominal_error_mm"]["x"]["mean"].get<double>();
        if (!(std::fabs(mean) > 0.02)) fail_msg("premise: seed %d's mean x error is %g mm", int(seed), mean);
        if (!r["recommended"]["effects"].empty())
            fail_msg("seed %d: clean data with the spacers' mean at %g mm recommends %s", int(seed), mean,
                     r["recommended"]["effects"].dump().c_str());
        if (!r["recommended"]["explained"].get<bool>())
            fail_msg("seed %d: clean data not explained: %s", int(seed), r["verdict"].dump().c_str());
    }
}

// A jig mounted 0.15 mm off along x, nothing else: within the spacers'
// bound the fixture's offsets take it, so nothing is recommended, and the
// words must not call it each height's own offset: "the jig sits ... off in
// x at every fixture height",
// the heights' spread about it within the noise.
// The raw x RMS then includes it (0.185 mm against a floor of 0.111): the
// verdict must print the RMS its tests saw beside it, within 5 % of the
// floor (a sampled RMS over 845 x 40 samples is good to ~1 %; the jig's
// seat scatter adds the rest).
static void a_jig_off_in_x_is_the_jigs(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("jig_misalignment", ParamValues{{"tx", 0.15}}, err));
    auto r = run(truth, 5, {}, true);
    check_consistent(r);
    const auto &rec = r["recommended"];
    if (!rec["effects"].empty() || !rec["explained"].get<bool>())
        fail_msg("a jig 0.15 mm off in x: %s", r["verdict"].dump().c_str());
    const std::string v = r["verdict"].get<std::string>();
    if (v.find("jig sits +0.1") == std::string::npos || v.find("ach fixture height has its own") != std::string::npos)
        fail_msg("the words for a jig off in x: %s", v.c_str());
    std::smatch m;
    if (!std::regex_search(v, m, std::regex("\\(([0-9.]+) mm with the fixture's per-height offsets out\\) at the noise "
                                            "floor ([0-9.]+) mm")))
        fail_msg("no x RMS with the offsets out: %s", v.c_str());
    const double out = std::stod(m[1].str()), floor = std::stod(m[2].str());
    if (out > 1.05 * floor) fail_msg("x RMS with the offsets out %g, noise floor %g", out, floor);
}

// A plate whose hole errors (0.04 mm in y and z, the same at every height)
// dominate what is left per position (0.01 mm): the fit weighs each hole's
// readings as one block (FitOptions::hole_sigma) and the verdict's tests
// are widened for the holes' correlation across heights. Treated as
// independent, a candidate that follows part of the plate's pattern gains
// several times the chi-square independent errors would give: on these five
// noise seeds the recommendation is then cable_gain + cable_offset +
// drum_eccentricity once, and the true model "not explained" three more
// times (docs/calibration.md). Each must recommend the true effect alone and explain the data; the hole estimate is
// within 25 % of 0.04 mm (169 holes: its sampling spread is a few percent).
static void strong_plate_holes_add_nothing(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("cable_gain", 9, err));
    for (uint64_t seed = 53; seed <= 57; ++seed) {
        Dataset d;
        JigSimOptions so = test::half_jig(seed);
        so.jig_hole_mm = 0.04;
        so.jig_tolerance_mm = 0.01;
        assert_true(simulate_jig(truth, so, d, err));
        DiagnoseOptions o;
        o.validation = false;
        o.per_position = false;
        nlohmann::json r;
        Model fitted{DeviceGeometry{}};
        if (!diagnose(d, truth.geometry(), o, r, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
        check_consistent(r);
        const auto &rec = r["recommended"];
        if (sorted_names(rec["effects"]) != std::vector<std::string>{"cable_gain"} || !rec["explained"].get<bool>())
            fail_msg("seed %d: a plate with strong hole errors: %s", int(seed), r["verdict"].dump().c_str());
        for (int a : {1, 2}) {
            const double s = rec["plate_holes_mm"][size_t(a)].get<double>();
            if (std::fabs(s - 0.04) > 0.25 * 0.04) fail_msg("seed %d: hole error %g mm, truth 0.04", int(seed), s);
        }
    }
}

// A device effect that does not change with height repeats at every hole
// too, but smoothly over the plate: never named as the plate's.
static void smooth_repeat_is_not_the_plate(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("exit_pulley", ParamValues{{"radius_mm", 3.0}}, err));
    auto r = run(truth, 611, {}, false, false, 0.0, 0.0);
    check_consistent(r);
    if (r["jig"]["holes"]["named"] == "plate") fail_msg("a device effect named as the plate: %s", r["jig"].dump().c_str());
}

// The pots drift during the session: without the catalogue the residual
// against acquisition time names a drift; with it the search picks pot_drift
// and the verdict says what to do.
static void drift_is_named(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    // 3 mm/h over this jig's 0.094 h session (33,800 rows at 0.01 s): 0.28 mm.
    assert_true(truth.add_effect("pot_drift", ParamValues{{"r1", 3}, {"r2", 3}, {"r3", 3}, {"r4", 3}}, err));
    auto r0 = run(truth, 601, {}, false);
    check_consistent(r0);
    bool drift = false;
    for (auto &f : r0["unexplained_structure"]["findings"])
        if (f["kind"] == "drift") {
            drift = true;
            // The session's drift, 0.28 mm, within 20 % (the common residual
            // also carries what the nominal model gets wrong meanwhile).
            const double a = f["amplitude_mm"].get<double>();
            if (std::fabs(a - 0.282) > 0.2 * 0.282) fail_msg("drift of %g mm found, truth 0.282", a);
        }
    if (!drift) fail_msg("no drift finding: %s", r0["unexplained_structure"].dump().c_str());
    auto r = run(truth, 601, {}, true);
    check_consistent(r);
    assert_true(sorted_names(r["recommended"]["effects"]) == std::vector<std::string>{"pot_drift"});
    if (r["verdict"].get<std::string>().find("drift by") == std::string::npos)
        fail_msg("the verdict does not word the drift: %s", r["verdict"].dump().c_str());
}

// A small drift beside anchor errors (a blind case, heights measured one
// after the other). With each reading weighed alone, the drift's candidate
// was significant by its likelihood ratio (p about 1e-6) but the BIC did not
// pay for it (change +0.3), and it moved positions by less than a tenth of
// the noise floor, while residual findings left the recommended model
// unexplained; the verdict named only the findings, so the drift the
// candidate table showed was on no sentence. check_consistent now asks that
// every significant candidate be named. With each position's four readings
// weighed as one block (calib/fit/problem.h) that drift is recommended (anchors or their equivalent holder points, and the
// drift); at 0.6 of its size it is where the blind case was: significant,
// not paid for by the BIC, and named.
static void small_drift_beside_a_finding_is_named(void **) {
    for (double f : {1.0, 0.6}) {
        Model truth{DeviceGeometry{}};
        std::string err;
        assert_true(truth.add_effect("anchor_position",
                                     ParamValues{{"a1_x", -0.677944}, {"a1_y", -0.964588}, {"a1_z", 0.252894},
                                                 {"a2_x", 0.891692}, {"a2_y", -0.291877}, {"a2_z", 0.698327},
                                                 {"a3_x", -0.579637}, {"a3_y", -0.875351}, {"a3_z", -0.844709},
                                                 {"a4_x", 0.971416}, {"a4_y", 0.987392}, {"a4_z", 0.930014}},
                                     err));
        assert_true(truth.add_effect(
            "pot_drift",
            ParamValues{{"r1", -0.384201 * f}, {"r2", 0.199695 * f}, {"r3", 0.14118 * f}, {"r4", 0.112338 * f}}, err));
        const auto r = run(truth, 41, {}, true);
        check_consistent(r);
        const auto rec = sorted_names(r["recommended"]["effects"]);
        if (f == 1.0) {
            if (std::find(rec.begin(), rec.end(), "pot_drift") == rec.end())
                fail_msg("the blind case's drift not recommended: %s", r["recommended"]["effects"].dump().c_str());
            continue;
        }
        bool premise = false;
        for (auto &c : r["recommended"]["candidates"])
            if (c["effect"] == "pot_drift" && c["significant"].get<bool>() && c["bic_change"].get<double>() > 0)
                premise = true;
        if (!premise)
            fail_msg("premise: pot_drift at 0.6 not significant-but-unpaid on the recommended model %s",
                     r["recommended"]["effects"].dump().c_str());
    }
}

// A drift beside anchor errors and an exit pulley (a blind case: half jig,
// noise seed 56707, the CLI's magnitudes for effect seed 170468): the drift's
// likelihood ratio is significant and it moves positions by a third of the
// noise floor, but its BIC change is positive, so the search leaves it out
// and the verdict says "does not explain the data". The verdict must then
// say why the recommendation leaves it out, and what to do.
static void significant_but_unpaid_is_explained_to_the_reader(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("anchor_position",
                                 ParamValues{{"a1_x", -0.8877576556947395}, {"a1_y", 0.32340053419083475},
                                             {"a1_z", 0.9118083619241364}, {"a2_x", 0.5716434974332439},
                                             {"a2_y", -0.7374697342451062}, {"a2_z", 0.33847711588468743},
                                             {"a3_x", -0.9540932841760619}, {"a3_y", 0.44540890284492574},
                                             {"a3_z", 0.7865407024261202}, {"a4_x", 0.22312775300468682},
                                             {"a4_y", 0.8432795772438513}, {"a4_z", -0.9595241400809968}},
                                 err));
    assert_true(truth.add_effect("exit_pulley", ParamValues{{"radius_mm", 9.915334143680296}}, err));
    assert_true(truth.add_effect("pot_drift",
                                 ParamValues{{"r1", 0.45233398306281547}, {"r2", 0.22153738151323063},
                                             {"r3", 0.29353921458716714}, {"r4", 0.17619647030249835}},
                                 err));
    const auto r = run(truth, 56707, {}, true);
    check_consistent(r);
    bool premise = false;
    for (auto &c : r["recommended"]["candidates"])
        if (c["effect"] == "pot_drift" && c["significant"].get<bool>() && c["bic_change"].get<double>() > 0 &&
            c["position_change_rms_mm"].get<double>() >= 0.1 * r["recommended"]["noise_floor_mm"][0].get<double>())
            premise = true;
    if (!premise)
        fail_msg("premise: pot_drift not significant, unpaid and material on %s",
                 r["recommended"]["effects"].dump().c_str());
    const std::string v = r["verdict"].get<std::string>();
    if (v.find("The search leaves pot_drift out") == std::string::npos)
        fail_msg("the verdict does not say why the drift is left out: %s", v.c_str());
}

// Positions not on a plate (a tracker or robot-arm reference): neighbours
// are found in 3-D, and the same verdicts come out.
static void scattered_positions(void **) {
    auto clean = run(Model{DeviceGeometry{}}, 31, {}, false, true);
    if (!clean["explained"].get<bool>())
        fail_msg("clean scattered data not explained: chi2/dof %g structure z %g", clean["chi2_per_dof"].get<double>(),
                 clean["structure"]["statistic"].get<double>());
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("exit_pulley", 32, err));
    auto r = run(truth, 33, {}, true, true);
    assert_false(r["explained"].get<bool>());
    assert_string_equal(r["candidates"][0]["effect"].get<std::string>().c_str(), "exit_pulley");
    assert_true(r["candidates"][0]["explained_after"].get<bool>());
}

// Two effects hidden (a pot gain error and a tilted jig): the greedy ranking
// takes the 12-parameter anchor_position first (it mimics the jig's rigid
// motion and part of the gain), gain next; the model review then sees that
// the jig transform does the anchors' job with 6 parameters fewer.
static void review_suggests_the_leaner_model(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("cable_gain", 21, err));
    assert_true(truth.add_effect_random("jig_misalignment", 22, err));
    auto r = run(truth, 5, {"anchor_position", "cable_gain"}, false);
    bool swap = false;
    for (auto &it : r["model_review"])
        if (it["effect"] == "anchor_position" && it.contains("better_swap") &&
            it["better_swap"]["effect"] == "jig_misalignment")
            swap = true;
    if (!swap) fail_msg("no swap suggested: %s", r["model_review"].dump().c_str());
    // and a right model gets no advice
    auto r2 = run(truth, 5, {"jig_misalignment", "cable_gain"}, false);
    for (auto &it : r2["model_review"]) {
        assert_false(it.contains("better_swap"));
        assert_false(it["redundant"].get<bool>());
    }
}


// The dataset keeps per-position statistics, not samples. The per-sample
// error's mean, std and RMS through the linearisation follow from each
// position's mean and co-moment matrix; the maxima and the seed's per-sample
// triangulation come from a pass over the rows. Checked here against the
// per-sample computation on the rows read back one by one.
static void per_sample_statistics_without_samples(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("exit_pulley", 3, err));
    JigSimOptions so = test::half_jig(9);
    so.n = 5;
    so.samples = 70; // 125 positions: 8,750 rows, three of the piped pass's chunks
    Dataset d;
    assert_true(simulate_jig(truth, so, d, err));
    const auto pos = prepare(d);
    diag::Eval E = diag::evaluate(truth, pos), S;
    for (int a = 0; a < 3; ++a) assert_true(std::isnan(E.err[a].mx)); // no maximum before the pass
    diag::Eval E1 = E, S1;
    assert_true(diag::sample_pass(d, pos, {&E}, {{&truth.geometry(), nullptr, &S}}, err, true));
    // In turn on one thread: the same, bit for bit.
    assert_true(diag::sample_pass(d, pos, {&E1}, {{&truth.geometry(), nullptr, &S1}}, err, false));
    for (int a = 0; a < 3; ++a) {
        assert_true(E1.err[a].mx == E.err[a].mx && E1.within[a].mx == E.within[a].mx);
        assert_true(S1.err[a].s == S.err[a].s && S1.err[a].ss == S.err[a].ss && S1.err[a].mx == S.err[a].mx);
    }
    for (size_t j = 0; j < pos.size(); ++j) assert_true(S1.est[j] == S.est[j]);

    diag::Acc err_ref[3], within_ref[3], seed_ref[3];
    std::vector<diag::V3> seed_sum(pos.size(), diag::V3::Zero());
    std::vector<int> seed_n(pos.size(), 0);
    double lmax = 0, smin = INFINITY;
    assert_true(for_each_sample(d, [&](size_t j, const double *l) {
        Eigen::Vector4d dl;
        for (int c = 0; c < 4; ++c) dl(c) = l[c] - pos[j].mean(c), lmax = std::max(lmax, l[c]);
        const diag::V3 dev = E.Jp[j] * dl;
        for (int a = 0; a < 3; ++a) {
            err_ref[a].add(E.res[j](a) + dev(a));
            within_ref[a].add(dev(a));
        }
        double p[3];
        assert_true(triangulate(truth.geometry(), l, p));
        for (int a = 0; a < 3; ++a) seed_ref[a].add(p[a] - pos[j].ref(a));
        seed_sum[j] += diag::V3(p[0], p[1], p[2]);
        ++seed_n[j];
    }, err));
    for (const auto &p : pos)
        for (int c = 0; c < 4; ++c) smin = std::min(smin, std::sqrt(p.cov(c, c)));
    // Rounding bound of the two ways of summing: N terms, each deviation
    // l - mean carrying the rounding of readings of size lmax against a
    // spread of at least smin.
    const double N = double(d.rows), tol = N * DBL_EPSILON * lmax / smin;
    for (int a = 0; a < 3; ++a) {
        assert_true(E.err[a].n == err_ref[a].n && E.within[a].n == within_ref[a].n);
        const double ss_scale = err_ref[a].ss, s_scale = std::sqrt(N * ss_scale);
        if (std::fabs(E.err[a].s - err_ref[a].s) > tol * s_scale ||
            std::fabs(E.err[a].ss - err_ref[a].ss) > tol * ss_scale ||
            std::fabs(E.within[a].ss - within_ref[a].ss) > tol * ss_scale)
            fail_msg("axis %d: moments %.17g %.17g %.17g, per sample %.17g %.17g %.17g (tol %g)", a, E.err[a].s,
                     E.err[a].ss, E.within[a].ss, err_ref[a].s, err_ref[a].ss, within_ref[a].ss, tol);
        // the maxima (the same in any order: the pass takes them a chunk at a
        // time) and the seed's pass (the same operations in the same order)
        assert_true(E.err[a].mx == err_ref[a].mx && E.within[a].mx == within_ref[a].mx);
        assert_true(S.err[a].s == seed_ref[a].s && S.err[a].ss == seed_ref[a].ss && S.err[a].mx == seed_ref[a].mx);
    }
    for (size_t j = 0; j < pos.size(); ++j) {
        assert_int_equal(seed_n[j], pos[j].n);
        assert_true(S.est[j] == seed_sum[j] / seed_n[j]);
    }
}

// The pass over the rows parses on one thread and visits on another, in
// chunks (calib/evaluation/eval.cpp). A file changed in place after it was loaded, on a
// row in its second chunk, fails the pass there with the reader's error
// naming that row's line, and the pass ends (no visit left waiting, no
// thread left): as the pass in turn would.
static void sample_pass_on_a_file_changed_late_fails(void **) {
    JigSimOptions so = test::half_jig(12);
    so.samples = 10; // 845 positions x 10: 8,450 rows, three chunks of 4,096
    std::vector<std::string> lines = test::simulated_lines(so);
    char p[] = "/tmp/cdm_sp_XXXXXX";
    const int fd = mkstemp(p);
    assert_true(fd >= 0);
    const std::string text = test::join(lines);
    assert_int_equal(write(fd, text.data(), text.size()), ssize_t(text.size()));
    Dataset d;
    std::string err;
    assert_true(load_dataset(p, d, err));
    const auto pos = prepare(d);
    const DeviceGeometry g;
    diag::Eval E = diag::evaluate(Model{g}, pos), S;
    assert_true(diag::sample_pass(d, pos, {&E}, {{&g, nullptr, &S}}, err, true)); // unchanged: passes
    // Row 6,000's reference height changed in place (its first digit: the
    // same length), in the second chunk.
    const size_t k = 6000; // lines[0] is the header: line k + 1
    const size_t c0 = lines[k].find(',') + 1;
    char &digit = lines[k][c0];
    digit = digit == '9' ? '8' : char(digit + 1);
    const std::string changed = test::join(lines);
    assert_int_equal(pwrite(fd, changed.data(), changed.size(), 0), ssize_t(changed.size()));
    close(fd);
    err.clear();
    assert_false(diag::sample_pass(d, pos, {&E}, {{&g, nullptr, &S}}, err, true));
    const std::string where = std::string(p) + ":" + std::to_string(k + 1) + ":";
    if (err.find(where) == std::string::npos) // (the reader's words: the point's x_ref disagrees with its own rows)
        fail_msg("error \"%s\" does not name %s", err.c_str(), where.c_str());
    unlink(p);
}

// Spikes in the pots' readings (0.2 % of the samples, 2 to 10 mm, as a
// loose wiper gives) change nothing but the count the verdict reports: the
// same recommended model as the clean file and the same noise floor. Left
// in, they would double the noise floor and hide the small gain error.
static void spikes_change_nothing_but_their_count(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("cable_gain", {{"g1", 0.001}, {"g2", -0.001}, {"g3", 0.0008}, {"g4", -0.0006}}, err));
    assert_true(truth.add_effect("exit_pulley", {{"radius_mm", 1.0}}, err));
    std::vector<std::string> lines = test::simulated_lines(test::half_jig(31), truth);
    nlohmann::json r[2];
    int injected = 0;
    for (int spiky = 0; spiky < 2; ++spiky) {
        if (spiky) {
            std::mt19937_64 rng(9);
            for (size_t k = 1; k < lines.size(); ++k)
                if (rng() % 500 == 0) {
                    test::spike(lines, k, int(rng() % 4), (rng() % 2 ? 1 : -1) * (2 + double(rng() % 81) / 10));
                    ++injected;
                }
        }
        Dataset d;
        assert_true(parse_dataset(test::join(lines), spiky ? "spiky.csv" : "clean.csv", d, err));
        r[spiky] = diagnosed(d, truth);
    }
    const auto &clean = r[0]["recommended"], &spiky = r[1]["recommended"];
    assert_int_equal(r[0]["data"]["glitches"]["count"].get<int>(), 0);
    // Every spike is 2-10 mm, 40-200 times the 0.05 mm noise: each one is
    // set aside, and nothing else.
    assert_true(injected > 20);
    assert_int_equal(r[1]["data"]["glitches"]["count"].get<int>(), injected);
    if (sorted_names(spiky["effects"]) != std::vector<std::string>{"cable_gain", "exit_pulley"})
        fail_msg("spiky data: recommended %s", spiky["effects"].dump().c_str());
    assert_true(sorted_names(clean["effects"]) == sorted_names(spiky["effects"]));
    assert_true(spiky["explained"].get<bool>());
    // The noise floor of the file without the spikes: a tenth of a percent
    // of the samples gone moves it by far less than 1 %.
    for (int a = 0; a < 3; ++a) {
        const double c = clean["noise_floor_mm"][a].get<double>(), s = spiky["noise_floor_mm"][a].get<double>();
        if (std::fabs(s - c) > 0.01 * c) fail_msg("axis %d noise floor %g with spikes, %g without", a, s, c);
    }
    if (r[1]["verdict"].get<std::string>().find("set aside as glitches") == std::string::npos)
        fail_msg("the verdict does not name the glitches: %s", r[1]["verdict"].dump().c_str());
}

// Each mean reading with an error of its own, 0.02 mm per cable and
// position (a pot's hysteresis: the same for a position's samples, so the
// pots' noise of the mean does not show it). Weighed as one block with only
// the pots' noise in the direction no position error moves, the readings'
// own error made a ripple of the noise: drum_eccentricity was recommended on
// clean data. The diagnosis must estimate it from the cables' misclosure
// (within 20 %: its standard error on this jig is ~3 % of sigma, from the
// spread of the plate's lines), weigh the fits with it, and recommend
// nothing; without the error the estimate must be zero (not significant).
static void readings_own_error_is_noise(void **) {
    const Model truth{DeviceGeometry{}};
    std::string err;
    std::vector<std::string> lines = test::simulated_lines(test::half_jig(7), truth);
    Dataset clean;
    assert_true(parse_dataset(test::join(lines), "jig.csv", clean, err));
    const auto r0 = diagnosed(clean, truth);
    if (r0["reading_noise_mm"]["value"].get<double>() != 0)
        fail_msg("clean data: readings' own error %s", r0["reading_noise_mm"].dump().c_str());
    test::per_position_offsets(lines, 0.02, 11);
    Dataset d;
    assert_true(parse_dataset(test::join(lines), "jig.csv", d, err));
    const auto r = diagnosed(d, truth);
    const double s = r["reading_noise_mm"]["value"].get<double>();
    if (std::fabs(s - 0.02) > 0.2 * 0.02) fail_msg("readings' own error %g mm, truth 0.02", s);
    if (!r["recommended"]["effects"].empty() || !r["recommended"]["explained"].get<bool>())
        fail_msg("a per-reading error of 0.02 mm: %s", r["verdict"].dump().c_str());
}

// Three positions whose reference is wrong by 0.6 to 1.4 mm (a mis-seated
// probe, a wrong hole): set aside by point, the diagnosis run again without
// them, landing where the file without them lands, with the jig tolerance
// of the clean file (the outliers would otherwise inflate it toward its
// 0.05 mm cap). With outliers=false every position is kept.
static void misplaced_positions_are_set_aside(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("exit_pulley", {{"radius_mm", 1.5}}, err));
    const std::vector<std::string> clean = test::simulated_lines(test::half_jig(41), truth);
    std::vector<std::string> lines = clean;
    const long bad[3] = {100, 431, 702};
    test::misplace(lines, bad[0], 0.6, -0.4);
    test::misplace(lines, bad[1], -1.0, 1.0);
    test::misplace(lines, bad[2], 0.0, 1.4);
    nlohmann::json r[3];
    for (int k = 0; k < 3; ++k) {
        Dataset d;
        assert_true(parse_dataset(test::join(k == 0 ? clean : lines), "jig.csv", d, err));
        r[k] = diagnosed(d, truth, k != 2);
    }
    assert_int_equal(r[0]["data"]["outliers"]["count"].get<int>(), 0);
    const auto &out = r[1]["data"]["outliers"];
    std::vector<long> got;
    for (auto &x : out["set_aside"]) got.push_back(x["point"].get<long>());
    std::sort(got.begin(), got.end());
    if (got != std::vector<long>(bad, bad + 3)) fail_msg("set aside: %s", out.dump().c_str());
    assert_int_equal(r[1]["data"]["positions"].get<int>(), 845 - 3);
    assert_true(sorted_names(r[1]["recommended"]["effects"]) == std::vector<std::string>{"exit_pulley"});
    assert_true(r[1]["recommended"]["explained"].get<bool>());
    if (r[1]["verdict"].get<std::string>().find("Set aside as outliers: 3 of 845 positions") == std::string::npos)
        fail_msg("the verdict does not name the outliers: %s", r[1]["verdict"].dump().c_str());
    // The jig tolerance: the clean file's to its sampling error (~5 %, as
    // in clean_data_is_explained); kept, the outliers inflate it.
    const double j0 = r[0]["jig_tolerance_mm"]["value"].get<double>(), j1 = r[1]["jig_tolerance_mm"]["value"].get<double>(),
                 j2 = r[2]["jig_tolerance_mm"]["value"].get<double>();
    if (std::fabs(j1 - j0) > 0.05 * j0) fail_msg("jig tolerance %g without the outliers, %g in the clean file", j1, j0);
    if (!(j2 > 1.1 * j0)) fail_msg("kept, the outliers leave the jig tolerance at %g (clean %g)", j2, j0);
    assert_int_equal(r[2]["data"]["outliers"]["count"].get<int>(), 0);

    // A jig of 48 positions has none to spare (2 % of them is less than
    // one): the misplaced point stays, and the diagnosis still runs.
    JigSimOptions tiny = test::half_jig(43);
    tiny.n = 4;
    tiny.heights = {30, 50, 70};
    std::vector<std::string> few = test::simulated_lines(tiny, truth);
    test::misplace(few, 5, 1.0, 1.0);
    Dataset d;
    assert_true(parse_dataset(test::join(few), "tiny.csv", d, err));
    DiagnoseOptions o;
    o.validation = false;
    nlohmann::json t;
    Model fitted{DeviceGeometry{}};
    if (!diagnose(d, truth.geometry(), o, t, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
    assert_int_equal(t["data"]["outliers"]["count"].get<int>(), 0);
    assert_int_equal(t["data"]["positions"].get<int>(), 48);
}

// More than the few: 6 % of the references moved (51 of 845, by 0.3 to 1.5
// mm in a direction of the plate drawn at random, a deterministic draw).
// Nothing physical picks them: the deviations are no cable's reading error
// and they are scattered, so they are set aside (up to 10 %), where before
// the search chased them with stand-in effects. The worn spot (a reading
// error, effect_outside_catalogue) keeps its positions: run() asserts it.
static void many_misplaced_positions_are_set_aside(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("exit_pulley", {{"radius_mm", 1.5}}, err));
    std::vector<std::string> lines = test::simulated_lines(test::half_jig(47), truth);
    std::mt19937_64 rng(47);
    std::vector<long> bad;
    for (long p = 0; p < 845; ++p) bad.push_back(p);
    std::shuffle(bad.begin(), bad.end(), rng);
    bad.resize(51);
    std::uniform_real_distribution<double> mag(0.3, 1.5), ang(0, 2 * M_PI);
    for (long p : bad) {
        const double r = mag(rng), a = ang(rng);
        test::misplace(lines, p, r * std::cos(a), r * std::sin(a));
    }
    std::sort(bad.begin(), bad.end());
    Dataset d;
    assert_true(parse_dataset(test::join(lines), "jig.csv", d, err));
    const nlohmann::json r = diagnosed(d, truth);
    std::vector<long> got;
    for (auto &x : r["data"]["outliers"]["set_aside"]) got.push_back(x["point"].get<long>());
    std::sort(got.begin(), got.end());
    if (got != bad) fail_msg("set aside %zu, moved %zu: %s", got.size(), bad.size(), r["data"]["outliers"].dump().c_str());
    assert_true(sorted_names(r["recommended"]["effects"]) == std::vector<std::string>{"exit_pulley"});
    assert_true(r["recommended"]["explained"].get<bool>());
}

// The structure test's z on white residuals is a standard normal: on the
// half jig (13 x 13 holes, 5 heights, 1560 neighbour pairs) 4000 draws of
// independent unit normals (per-height means removed, as the judge does)
// must give z a standard deviation within 0.035 of 1 (the moments are
// exact, so only the estimate's own spread, 1/sqrt(2 x 4000) = 0.011,
// is left: 3 of those; a 7 % error in the variance fails it) and cross the
// verdict's one-sided 1e-3 point (3.09) at most 3 times the stated rate
// (4 expected; 12 is 4 standard deviations of a Poisson count above).
// With Cliff and Ord's S1 and S2 halved and quartered the standard
// deviation is 1.41 and the 1e-3 point is crossed 8 times as often: clean
// data read "not explained" one run in twenty or so.
static void structure_test_is_calibrated(void **) {
    std::vector<PreparedPos> pos;
    std::vector<double> heights{30, 40, 50, 60, 70};
    for (double x : heights)
        for (int y = -6; y <= 6; ++y)
            for (int z = -6; z <= 6; ++z) {
                PreparedPos p;
                p.ref = Eigen::Vector3d(x, 10.0 * y, 10.0 * z);
                p.mean.setZero();
                p.var_mean.setZero();
                p.cov.setZero();
                pos.push_back(p);
            }
    const diag::Grid G = diag::make_grid(pos, heights);
    const std::vector<char> ok(pos.size(), 1);
    std::mt19937_64 rng(20261125);
    std::normal_distribution<double> g(0.0, 1.0);
    const int draws = 4000;
    double s = 0, s2 = 0;
    int past = 0;
    std::vector<double> v(pos.size());
    for (int t = 0; t < draws; ++t) {
        for (double &e : v) e = g(rng);
        const double z = diag::moran_z(v, ok, G);
        s += z;
        s2 += z * z;
        past += z > 3.09;
    }
    const double mean = s / draws, sd = std::sqrt(s2 / draws - mean * mean);
    if (std::fabs(sd - 1) > 0.035) fail_msg("Moran z on white residuals: sd %g (mean %g)", sd, mean);
    if (std::fabs(mean) > 0.1) fail_msg("Moran z on white residuals: mean %g", mean);
    if (past > 12) fail_msg("Moran z past 3.09 in %d of %d white draws (1e-3 expects 4)", past, draws);
}

// A ripple's period is picked where the residual looks most like one, so
// on data with none drum_eccentricity's delta chi2 is the largest of about
// M = span / 8 mm - 1 chi-square(8)'s, not a chi-square(9) (it averaged 19
// on 20 clean half jigs). Its p must say so: on 10 clean half jigs (no jig
// errors) at most 3 may read p < 0.05 (binomial(10, 0.05) passes 3 once in
// a thousand). Against chi-square(9) most do.
static void ripple_p_counts_the_periods_searched(void **) {
    int small = 0;
    std::string ps;
    for (uint64_t seed = 700; seed < 710; ++seed) {
        Dataset d;
        std::string err;
        assert_true(simulate_jig(Model{DeviceGeometry{}}, test::half_jig(seed), d, err));
        DiagnoseOptions o;
        o.search = false;
        o.validation = false;
        o.per_position = false;
        nlohmann::json r;
        Model fitted{DeviceGeometry{}};
        if (!diagnose(d, DeviceGeometry{}, o, r, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
        for (auto &c : r["candidates"])
            if (c["effect"] == "drum_eccentricity") {
                const double p = c["lr_p_value"].get<double>();
                small += p < 0.05;
                ps += " " + std::to_string(p);
            }
    }
    if (small > 3) fail_msg("drum_eccentricity on clean data: %d of 10 p < 0.05 (p:%s)", small, ps.c_str());
}

// The two tests that let more than the few be set aside, on their own.
static void references_off_are_told_from_structure(void **) {
    // Join count: a 3 x 3 block of a 13 x 13 plate marked is clustered;
    // nine positions spread a few holes apart are not.
    std::vector<PreparedPos> pos;
    for (int y = 0; y < 13; ++y)
        for (int z = 0; z < 13; ++z) {
            PreparedPos p;
            p.ref = Eigen::Vector3d(30, 10.0 * y, 10.0 * z);
            p.mean.setZero();
            p.var_mean.setZero();
            p.cov.setZero();
            pos.push_back(p);
        }
    const diag::Grid G = diag::make_grid(pos, {30});
    std::vector<char> ok(pos.size(), 1), block(pos.size(), 0), spread(pos.size(), 0);
    for (int y = 5; y < 8; ++y)
        for (int z = 5; z < 8; ++z) block[size_t(13 * y + z)] = 1;
    for (int y = 1; y < 13; y += 4)
        for (int z = 1; z < 13; z += 4) spread[size_t(13 * y + z)] = 1;
    const double p_block = diag::join_count_p(G, ok, block), p_spread = diag::join_count_p(G, ok, spread);
    if (!(p_block < 0.01)) fail_msg("a 3 x 3 block: join-count p %g", p_block);
    assert_true(p_spread == 1.0); // no two of them are neighbours
    // One link by chance among nine spread positions is no cluster: the
    // relabelings (not the no-link shortcut) must say so.
    std::vector<char> chance = spread;
    chance[size_t(13 * 1 + 2)] = 1; // beside (1, 1)
    chance[size_t(13 * 9 + 9)] = 0;
    const double p_chance = diag::join_count_p(G, ok, chance);
    if (!(p_chance >= 0.05)) fail_msg("one chance link: join-count p %g", p_chance);
    // One cable: a deviation along a column of the position's Jacobian is
    // one reading's error (chi-square 0); across all four it is not.
    Eigen::Matrix<double, 3, 4> Jp;
    Jp << 1, 0, 0, 1, 0, 1, 0, 1, 0, 0, 1, 1;
    const diag::V3 var = diag::V3::Constant(1e-3);
    const double along = diag::one_cable_chi2(Jp, 0.5 * Jp.col(3), var);
    const double across = diag::one_cable_chi2(Jp, diag::V3(0.5, -0.5, 0), var);
    assert_true(along < 1e-9);
    // 0.5 mm across every column: at least 0.25 mm^2 / 0.001 mm^2 per axis left
    if (!(across > 100)) fail_msg("a deviation across the columns leaves chi2 %g", across);
}

// A reference off the plate's grid (a misplaced probe) does not set the
// plate's pitch: the smallest spacing of the y values that columns of
// holes share is 10 mm, not the 0.57 mm between the misplaced y and its
// column (with which no position found a neighbour, and the jig's
// tolerance, Moran's I and the outliers' neighbour test went blind).
static void grid_ignores_a_misplaced_reference(void **) {
    std::vector<PreparedPos> pos;
    for (int h = 0; h < 2; ++h)
        for (int y = -2; y <= 2; ++y)
            for (int z = -2; z <= 2; ++z) {
                PreparedPos p;
                p.ref = Eigen::Vector3d(30 + 20 * h, 10.0 * y, 10.0 * z);
                p.mean.setZero();
                p.var_mean.setZero();
                p.cov.setZero();
                pos.push_back(p);
            }
    pos[7].ref += Eigen::Vector3d(0, 0.57, -0.4);
    const diag::Grid G = diag::make_grid(pos, {30, 50});
    assert_true(std::fabs(G.pitch - 10) < 1e-9);
    for (size_t j = 0; j < pos.size(); ++j)
        if (G.nb[j].size() < 2) fail_msg("position %zu has %zu neighbours", j, G.nb[j].size());
    assert_int_equal(G.nb[12].size(), 4); // the centre of the first plate, beside the moved one
}

int main(int argc, char** argv) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(per_sample_statistics_without_samples),
        cmocka_unit_test(sample_pass_on_a_file_changed_late_fails),
        cmocka_unit_test(clean_data_is_explained),
        cmocka_unit_test(each_hidden_effect_is_found),
        cmocka_unit_test(effect_outside_catalogue),
        cmocka_unit_test(scattered_positions),
        cmocka_unit_test(review_suggests_the_leaner_model),
        cmocka_unit_test(search_lands_on_hidden_effects),
        cmocka_unit_test(sparse_noisy_jig),
        cmocka_unit_test(noisier_positions_keep_their_variance),
        cmocka_unit_test(ripple_period_is_fitted),
        cmocka_unit_test(realistic_gain_and_pulley_nothing_extra),
        cmocka_unit_test(drift_is_named),
        cmocka_unit_test(small_drift_beside_a_finding_is_named),
        cmocka_unit_test(significant_but_unpaid_is_explained_to_the_reader),
        cmocka_unit_test(plate_is_named_as_the_jig),
        cmocka_unit_test(strong_plate_holes_add_nothing),
        cmocka_unit_test(a_three_sigma_fixture_height_is_the_jigs),
        cmocka_unit_test(spacers_mean_adds_nothing),
        cmocka_unit_test(a_jig_off_in_x_is_the_jigs),
        cmocka_unit_test(smooth_repeat_is_not_the_plate),
        cmocka_unit_test(spikes_change_nothing_but_their_count),
        cmocka_unit_test(readings_own_error_is_noise),
        cmocka_unit_test(misplaced_positions_are_set_aside),
        cmocka_unit_test(grid_ignores_a_misplaced_reference),
        cmocka_unit_test(many_misplaced_positions_are_set_aside),
        cmocka_unit_test(references_off_are_told_from_structure),
        cmocka_unit_test(structure_test_is_calibrated),
        cmocka_unit_test(ripple_p_counts_the_periods_searched),
    };
    return cdm_test::run_shard(argc, argv, "calib_diagnose", tests);
}
