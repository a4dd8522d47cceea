// Misplaced positions set aside in rounds, for every job that fits a model
// to a jig (the diagnosis, the fit alone). A round runs the job on the
// data and names the positions its model and their neighbours both disown
// (find_outliers, calib/evaluation/outliers.h); the job is run again without them
// (their pull on the jig's tolerance and on the fit gone, more can show),
// at most kOutlierRounds runs, and at most kOutlierMaxFraction of the
// positions read over all rounds (so none below 50 positions: a small jig
// has no position to spare, and the fit needs its positions), or up to
// kOutlierScatteredFraction when they look like references off
// (find_outliers decides, told what earlier rounds set aside). The last
// run's result is the job's.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/dataset/dataset.h"
#include "calib/evaluation/outliers.h"
#include "calib/calibration/fit_calibration.h"

namespace cdm {

constexpr int kOutlierRounds = 3;

// One run of a job on `data`: false + err when the job fails; `found`: the
// positions (indices into data.pos) to set aside, empty when none, judged by
// find_outliers with `already` set aside of `read` (calib/evaluation/outliers.h).
using OutlierRound = std::function<bool(const Dataset &data, size_t already, size_t read,
                                        std::vector<diag::Outlier> &found, diag::Declined &declined,
                                        std::string &err)>;

// Runs `round` on `data`, then again without what it found while the
// budget lasts (with `enabled` false, once, whatever it finds). `report`:
// the JSON block {enabled, count, positions_read, test, set_aside: [{point,
// ref, residual_mm, neighbours_mm, chi2, chi2_neighbours, round}],
// declined: {count, why}: positions that failed both tests but were kept}.
bool run_setting_aside_outliers(const Dataset &data, bool enabled, const OutlierRound &round, nlohmann::json &report,
                                std::string &err);

// The positions a fitted calibration's model and their neighbours both
// disown, judged as the diagnosis judges them: on the residual with the
// jig's own per-height and per-hole offsets removed (calib/evaluation/jig.h), against
// the noise and the jig's tolerance.
std::vector<diag::Outlier> calibration_outliers(const CalibrationFit &cf, size_t already, size_t read,
                                                diag::Declined &declined);

} // namespace cdm
