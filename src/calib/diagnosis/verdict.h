// The verdict's rule, in one place. A model explains the data only when
// every test shown beside it agrees: the chi-square of its residual against
// the noise and the jig's tolerance, the spatial-structure test, no
// candidate significant by its likelihood ratio (Delta chi2 against
// chi2(k), Bonferroni over the candidates tried), and no residual finding
// significant (each family at kFindingLevel). What is significant but moves
// positions by less than a tenth of the noise floor is named as negligible,
// with its number, and does not count against the model in the words
// ("explains the data to within what matters") while `explained` stays false.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/dataset/dataset.h"
#include "calib/search/candidates.h"
#include "calib/beyond/standins.h"

namespace cdm {
namespace diag {

struct Judgement {
    bool explained = false;     // every test passes
    bool negligible_only = false; // fails only on things below a tenth of the noise floor
    // The tests pass, but with effects whose fitted values their physics
    // does not allow (calib/beyond/standins.h): "fits to the noise floor with
    // stand-ins", neither explained nor negligible_only.
    bool with_stand_ins = false;
    std::string words;          // "explains the data; x RMS ..." or "does not explain the data: ..."
    nlohmann::json significant = nlohmann::json::array(); // what is left: candidates and findings
};

// v: the model's chi-square and structure tests; E: its evaluation;
// cands: the candidates on top of it (nullptr: not tried); findings: its
// residual findings (nullptr: not analysed); noise: the noise floor per
// axis (mm); x_rms_jig_out: E's x RMS with the fixture's per-height offsets
// out (x_rms_without_fixture; NaN: no fixture heights), printed beside the
// raw one when they differ, since the tests judge that one. stand_ins: the
// model's stand-ins (null or empty: none).
Judgement judge_model(const Verdict &v, const Eval &E, const std::vector<Candidate> *cands,
                      const nlohmann::json *findings, const V3 &noise, double x_rms_jig_out = NAN,
                      const std::vector<StandIn> *stand_ins = nullptr);

// The samples the dataset's glitch screen set aside (calib/dataset/glitches.h)
// as a sentence for the verdict ("" when none); their JSON is
// glitches_json (calib/dataset/dataset.h).
std::string glitches_words(const Dataset &d);
// The positions diagnose() set aside as outliers (data.outliers.set_aside),
// of `read` positions, as a sentence for the verdict.
std::string outliers_words(const nlohmann::json &set_aside, size_t read);


} // namespace diag
} // namespace cdm
