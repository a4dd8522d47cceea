// See fit_outliers.h.
#include "calib/calibration/fit_outliers.h"

#include <cmath>

#include "calib/evaluation/jig.h"

namespace cdm {

using nlohmann::json;

bool run_setting_aside_outliers(const Dataset &data, bool enabled, const OutlierRound &round, json &report,
                                std::string &err) {
    std::vector<diag::Outlier> found;
    diag::Declined declined;
    const size_t P0 = data.pos.size();
    if (!round(data, 0, P0, found, declined, err)) return false;
    if (!enabled) found.clear(), declined = {};
    json set_aside = json::array();
    // find_outliers keeps the total within 2 % of P0, or 10 % for references off
    const size_t budget = size_t(std::floor(diag::kOutlierMaxFraction * double(P0))) >= 1
                              ? size_t(std::floor(diag::kOutlierScatteredFraction * double(P0)))
                              : 0;
    Dataset kept;
    const Dataset *cur = &data;
    int run = 1;
    for (; run < kOutlierRounds && !found.empty() && set_aside.size() + found.size() <= budget; ++run) {
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
        declined = {};
        if (!round(*cur, set_aside.size(), P0, found, declined, err)) return false;
    }
    // Found, and kept all the same: said, not dropped in silence.
    if (!found.empty())
        declined = {found.size(), run >= kOutlierRounds
                                      ? "found by the last of " + std::to_string(kOutlierRounds) + " runs"
                                      : budget == 0 ? "a jig of " + std::to_string(P0) + " positions has none to spare"
                                                    : "beyond 10 % of the positions read with those set aside"};
    report = {{"enabled", enabled},
              {"count", set_aside.size()},
              {"positions_read", P0},
              {"test", "chi-square (3 dof) of the residual against the noise and the jig's tolerance, "
                       "and of its difference from the mean residual of its neighbours on the plate, "
                       "both beyond the 1 % family-wise level (Bonferroni over the positions); only when "
                       "the median position's chi-square is within twice chi2(3)'s median; at most 2 % of the "
                       "positions read over all rounds (none below 50 positions), and none when more than a quarter of "
                       "a round's deviate as one cable's reading error would (chi-square, 2 dof, of the rest within its 1 % "
                       "point), counting only cables that two or more do so on (a reading effect); or up to 10 % when "
                       "at most a quarter of those each round finds deviate so and they are scattered as chance scatters them (join count of "
                       "neighbouring pairs against 999 random relabelings, p >= 0.05), else none"},
              {"set_aside", set_aside},
              {"declined", {{"count", declined.count}, {"why", declined.why}}}};
    return true;
}

std::vector<diag::Outlier> calibration_outliers(const CalibrationFit &cf, size_t already, size_t read,
                                                diag::Declined &declined) {
    const diag::JigAnalysis ja =
        diag::jig_analysis(cf.fitted, cf.grid, cf.pos, cf.jig, diag::noise_floor(cf.fitted, cf.jig));
    diag::Eval E = cf.fitted;
    for (size_t j = 0; j < E.res.size(); ++j) E.res[j] -= ja.offset[j];
    return diag::find_outliers(E, cf.grid, cf.jig, already, read, &declined);
}

} // namespace cdm
