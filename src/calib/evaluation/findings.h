// Findings beyond the catalogue in the residuals of the best explanation:
// a period in cable length (pooled Lomb-Scargle over the four cables), a
// drift over the session (the common reading residual against acquisition
// time), and polynomial trends of the position residual against physical
// variables. Each finding carries structured fields beside its English text
// (docs/calibration.md, "The JSON") and a p-value already corrected for the
// number of tests of its kind; a finding is listed only when that p-value is
// below kFindingLevel.
#pragma once

#include <array>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/evaluation/eval.h"

namespace cdm {
namespace diag {

// The family-wise level of every test the verdict rests on (the
// chi-square, the spatial structure, the candidates' likelihood ratios, the
// findings): 1e-3, each family Bonferroni-corrected.
constexpr double kFindingLevel = 1e-3;

// Per position: each cable's mean reading, its residual against a model's
// prediction at the jig position (at the position's acquisition time), and
// the cable's angle (deg) to the plate.
struct LengthView {
    std::vector<std::array<double, 4>> lmean, lres, angle;
    std::vector<std::array<V3, 4>> dir; // d length / d holder position: each cable's unit direction
    std::vector<std::array<double, 4>> chord; // each cable's straight length, anchor to holder (mm)
};
LengthView length_view(const Model &m, const std::vector<PreparedPos> &pos);
// The view with the holder moved by off[j] at each position (the jig's own
// error, jig.h, taken out of the length residuals).
LengthView shifted(const LengthView &v, const std::vector<V3> &off);

// The strongest period of the cable-length residual, pooled over the four
// cables (identical drums share a period) after a quadratic in length is
// taken out of each; fap: the false-alarm probability over the frequencies
// searched (periods 8 mm .. the length span). valid = false when the
// lengths span too little to search.
struct PeriodPeak {
    bool valid = false;
    double period_mm = 0, fap = 1, amplitude_mm = 0;
};
PeriodPeak length_period(const LengthView &v);

// The shortest period the periodogram searches (mm), and the number of
// independent periods it searches over lengths spanning `span_mm` (from
// kShortestPeriodMm to the span; 0 when the span is shorter): a searched
// period's false-alarm count, for the periodogram and for a candidate
// whose period starts from it (calib/search/candidates.cpp).
constexpr double kShortestPeriodMm = 8.0;
double periods_searched(double span_mm);

// lv: the length view of the evaluation bE's model, the jig's estimated
// errors taken out; jig: tolerance; across: the same view before the
// jig's errors (the fixture's per-height offsets, the holes') were taken
// out (the drift's session-long slope is judged on it: drift_finding).
nlohmann::json residual_findings(const std::vector<PreparedPos> &pos, const LengthView &lv, const Eval &bE,
                                 const V3 &jig, const LengthView &across);

} // namespace diag
} // namespace cdm
