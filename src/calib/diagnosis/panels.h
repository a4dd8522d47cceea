// The report's residual panels, tested: for each residual the report plots
// against a physical variable (a position axis against the height, the
// distance from the centre, each cable's length and angle; each cable's
// reading against its length), whether its mean varies with the variable.
// The test is a one-way analysis of variance over quantile bins of the
// variable (F = between-bin over within-bin mean squares, F(B-1, n-B)),
// Bonferroni over the panels' series: a panel that shows a trend says so,
// with the same level as every other test of the verdict (kFindingLevel).
#pragma once

#include <vector>

#include <nlohmann/json.hpp>

#include "calib/evaluation/eval.h"
#include "calib/evaluation/findings.h"

namespace cdm {
namespace diag {

struct BinnedTrend {
    double F = 0, d1 = 0, d2 = 0;
    double p = 1;        // one series, before the correction
    double range_mm = 0; // largest minus smallest bin mean
    int bins = 0;
};

// y against x over `bins` bins of equal counts (pairs with a non-finite
// member left out); bins = 0 when fewer than 3 bins of 10 values each fit.
BinnedTrend binned_trend(const std::vector<double> &x, const std::vector<double> &y, int bins);

// Every series of the report's panels. E: the model whose position residual
// the report plots (positions.residual_mm); lv: the view whose length
// residual it plots (positions.length_residual_mm). JSON: a list of
// {panel, variable, cable (1-4 or null), axis ("x","y","z" or "reading"),
// F, dof: [d1, d2], p_value (Bonferroni), range_mm, significant}.
nlohmann::json panel_trends(const std::vector<PreparedPos> &pos, const Eval &E, const LengthView &lv);

} // namespace diag
} // namespace cdm
