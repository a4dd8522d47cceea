// The search fits a step's candidates, removals and swaps on several
// threads (diag::fit_all): the diagnosis must not depend on how many. Each
// fit is deterministic and independent of the others, so the JSON must be
// identical, to the last bit, with 1, 2 and 3 threads (only the timings
// differ). Half-resolution jig as in test_diagnose.cpp; the hidden effects
// make the search take several steps, swaps and alternatives.
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/diagnosis/diagnose.h"
#include "calib/dataset/simulate.h"

extern "C" {
#include <cmocka.h>
}
#include "jig_text.h"

using namespace cdm;

static nlohmann::json diagnose_with(const Dataset &d, int threads) {
    DiagnoseOptions o;
    o.threads = threads;
    nlohmann::json out;
    Model fitted{DeviceGeometry{}};
    std::string err;
    if (!diagnose(d, DeviceGeometry{}, o, out, fitted, err)) fail_msg("diagnose failed: %s", err.c_str());
    out.erase("seconds");
    out["fit"].erase("seconds");
    return out;
}

// The half-resolution jig both tests use (jig_text.h), noise seed `seed`.
static Dataset half_jig(const Model &truth, uint64_t seed) {
    const JigSimOptions so = test::half_jig(seed);
    Dataset d;
    std::string err;
    if (!simulate_jig(truth, so, d, err)) fail_msg("simulate: %s", err.c_str());
    return d;
}

// The first path (a/b/3/c) at which two JSON documents differ, for the
// failure message ("" when equal).
static std::string first_difference(const nlohmann::json &a, const nlohmann::json &b, const std::string &at = "") {
    if (a.type() != b.type() || (!a.is_object() && !a.is_array())) return a == b ? "" : (at.empty() ? "/" : at);
    if (a.is_array()) {
        if (a.size() != b.size()) return at + " (length)";
        for (size_t k = 0; k < a.size(); ++k) {
            const std::string d = first_difference(a[k], b[k], at + "/" + std::to_string(k));
            if (!d.empty()) return d;
        }
        return "";
    }
    for (auto it = a.begin(); it != a.end(); ++it) {
        if (!b.contains(it.key())) return at + "/" + it.key() + " (missing)";
        const std::string d = first_difference(it.value(), b[it.key()], at + "/" + it.key());
        if (!d.empty()) return d;
    }
    return a.size() == b.size() ? "" : at + " (keys)";
}

static void same_result_on_any_thread_count(void **) {
    const std::vector<std::vector<std::string>> hidden{{"cable_gain", "exit_pulley"}, {"drum_eccentricity"}};
    uint64_t seed = 40;
    for (auto &effects : hidden) {
        Model truth{DeviceGeometry{}};
        std::string err;
        for (auto &e : effects) assert_true(truth.add_effect_random(e, ++seed, err));
        const Dataset d = half_jig(truth, ++seed);
        const auto one = diagnose_with(d, 1);
        // the search ran and moved (else this test would show nothing)
        assert_false(one["recommended"]["path"].empty());
        for (int t : {2, 3}) {
            const auto many = diagnose_with(d, t);
            if (many != one)
                fail_msg("hidden %s: %d threads give another diagnosis than 1, first at %s (recommended %s vs %s)",
                         effects[0].c_str(), t, first_difference(one, many).c_str(),
                         many["recommended"]["effects"].dump().c_str(),
                         one["recommended"]["effects"].dump().c_str());
        }
    }
}

// A cancel from the progress callback while a batch of fits runs on two
// threads (a seeded ripple's held starts and joint fits among them, the
// review's refits, the validation's folds): the diagnosis stops and says it
// was cancelled, and nothing runs on after it returns (ThreadSanitizer and
// AddressSanitizer builds run this too). The user's model has an effect so
// that the review and the validation have fits to run.
static void cancel_inside_a_batch(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    for (const char *e : {"cable_gain", "exit_pulley"}) assert_true(truth.add_effect_random(e, 61, err));
    const Dataset d = half_jig(truth, 62);
    // (Only the calling thread reports, every fifth evaluation of the fit it
    // runs: stages it is sure to report inside a fit.)
    for (const char *prefix : {"candidates", "search step", "reviewing", "validation"}) {
        DiagnoseOptions o;
        o.effects = {"exit_pulley"};
        o.threads = 2;
        bool reached = false;
        int calls = 0;
        o.progress = [&](const std::string &stage, double) {
            if (stage.rfind(prefix, 0) != 0) return true;
            reached = true;
            return ++calls < 2; // the second report of the stage: inside its fits
        };
        nlohmann::json out;
        Model fitted{DeviceGeometry{}};
        std::string e2;
        const bool ok = diagnose(d, DeviceGeometry{}, o, out, fitted, e2);
        if (!reached) fail_msg("premise: the diagnosis never reported a stage \"%s\"", prefix);
        if (ok) fail_msg("cancelled in \"%s\", the diagnosis still returned a result", prefix);
        if (e2.find("cancel") == std::string::npos)
            fail_msg("cancelled in \"%s\": the error says \"%s\"", prefix, e2.c_str());
    }
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(same_result_on_any_thread_count),
        cmocka_unit_test(cancel_inside_a_batch),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
