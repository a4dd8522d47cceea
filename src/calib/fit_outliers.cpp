// See fit_outliers.h.
#include "calib/fit_outliers.h"

#include <cmath>

#include "calib/diag_jig.h"

namespace cdm {

using nlohmann::json;

bool run_setting_aside_outliers(const Dataset &data, bool enabled, const OutlierRound &round, json &report,
                                std::string &err) {
    std::vector<diag::Outlier> found;
    if (!round(data, found, err)) return false;
    if (!enabled) found.clear();
    json set_aside = json::array();
    const size_t P0 = data.pos.size();
    const size_t budget = size_t(std::floor(diag::kOutlierMaxFraction * double(P0)));
    Dataset kept;
    const Dataset *cur = &data;
    for (int run = 1; run < kOutlierRounds && !found.empty() && set_aside.size() + found.size() <= budget; ++run) {
        std::vector<long> ids;
        for (auto &o : found) {
            const JigHole &h = cur->pos[o.j];
            ids.push_back(h.point);
            set_aside.push_back({{"point", h.point},
                                 {"ref", {h.ref[0], h.ref[1], h.ref[2]}},
                                 {"residual_mm", {o.res(0), o.res(1), o.res(2)}},
                                 {"neighbours_mm", {o.nb(0), o.nb(1), o.nb(2)}},
                                 {"chi2", o.chi2},
                                 {"chi2_neighbours", o.chi2_nb},
                                 {"round", run}});
        }
        Dataset next;
        if (!without_points(*cur, ids, next, err)) return false;
        kept = std::move(next);
        cur = &kept;
        found.clear();
        if (!round(*cur, found, err)) return false;
    }
    report = {{"enabled", enabled},
              {"count", set_aside.size()},
              {"positions_read", P0},
              {"test", "chi-square (3 dof) of the residual against the noise and the jig's tolerance, "
                       "and of its difference from the mean residual of its neighbours on the plate, "
                       "both beyond the 1 % family-wise level (Bonferroni over the positions); only when "
                       "the median position's chi-square is within twice chi2(3)'s median, and at most "
                       "2 % of the positions read over all rounds (none below 50 positions), else none"},
              {"set_aside", set_aside}};
    return true;
}

std::vector<diag::Outlier> calibration_outliers(const CalibrationFit &cf) {
    const diag::JigAnalysis ja =
        diag::jig_analysis(cf.fitted, cf.grid, cf.pos, cf.jig, diag::noise_floor(cf.fitted, cf.jig));
    diag::Eval E = cf.fitted;
    for (size_t j = 0; j < E.res.size(); ++j) E.res[j] -= ja.offset[j];
    return diag::find_outliers(E, cf.grid, cf.jig);
}

} // namespace cdm
