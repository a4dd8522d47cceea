// Fitting a calibration without diagnosing it: the model with the requested
// effects fitted to jig data, the jig tolerance estimated from the data's
// white scatter, and the error statistics before and after. This is the
// first stage of diagnose(), and all of what `cdm calib fit` needs.
#pragma once

#include <functional>
#include <future>
#include <optional>
#include <string>
#include <vector>

#include "calib/evaluation/eval.h"
#include "calib/evaluation/noise.h"
#include "calib/evaluation/spatial.h"

namespace cdm {

struct FitCalibrationOptions {
    std::vector<std::string> effects; // "ellipsoid" is fitted in position space on top
    // Not null: a calibration checked on this data instead of one fitted
    // (effects ignored). The model is taken as it is and only the jig is
    // fitted: its placement (the model's Jig-stage effects, jig_misalignment
    // added at zero when it has none) and the fixture heights' offsets, for
    // a jig is placed anew at every session; every other parameter stays the
    // calibration's. The noise model (reading noise, jig tolerance) is
    // estimated from this data as a fit's is.
    const Model *check = nullptr;
    double jig_tolerance_mm = -1;     // < 0: estimated from the data
    // Each reading's own white error (CalibrationFit::reading): none,
    // estimated from the fitted model's misclosure; given, this estimate
    // (the diagnosis's second run, with the recommended model's).
    std::optional<diag::ReadingNoise> reading_noise;
    std::function<bool(const std::string &stage, double fraction)> progress;
    // Fill fitted's per-sample maxima (a pass over the rows). A caller that
    // makes its own pass at the end (diagnose) turns it off.
    bool fitted_maxima = true;
    // 1: everything on the calling thread. Otherwise the nominal
    // triangulation's pass over the rows, which needs nothing from the fit,
    // runs on a second thread beside it (without fitted_maxima; with it,
    // both are one pass at the end).
    int threads = 0;
    // Not null (with nominal_err): the nominal triangulation's pass over the
    // rows, when it runs on a second thread, is left running beside the
    // caller's own work, in *nominal_pending, and not waited for here
    // (diagnose needs its result, CalibrationFit::nominal, only at its own
    // pass at the end). The caller must get() it (false: *nominal_err says
    // why) before reading `nominal`, and before `out`, the dataset, the
    // geometry or *nominal_err go: declared after them, its destructor
    // waits. Invalid when the pass ran here (and succeeded).
    std::future<bool> *nominal_pending = nullptr;
    std::string *nominal_err = nullptr;
};

struct CalibrationFit {
    explicit CalibrationFit(const DeviceGeometry &g) : model(g) {}
    Model model;
    FitReport report;
    FitOptions fit_options;         // with the jig tolerance used
    // per axis, mm: each position's white scatter, holes included (the part
    // a plate's hole shares at every height: fit_options.hole_sigma)
    diag::V3 jig = diag::V3::Zero();
    // Each mean reading's own white error beyond the pots' noise
    // (diag::estimate_reading_noise, on the fitted model's misclosure); when
    // its sigma is not zero, sigma^2 is in every position's var_mean and
    // cov_mean below (PreparedPos::reading_var), so that every weight and
    // test carries it.
    diag::ReadingNoise reading;
    std::vector<PreparedPos> pos;
    diag::Grid grid;
    diag::Eval nominal, fitted;     // the nominal triangulation and the fitted model
    // The nested sub-model the joint fit was run again from, when its first
    // fit ended above that sub-model fitted alone (fit_not_worse_than_nested):
    // its effects; empty when the first fit stood.
    std::vector<std::string> restarted_from;
    // A check (FitCalibrationOptions::check) whose calibration had no
    // Jig-stage effect: jig_misalignment was added to place the jig.
    bool jig_added = false;
};

// False + err (naming what is wrong) on too few positions, an unknown
// effect, cancellation through progress, or rows that cannot be read again.
// A check's model (FitCalibrationOptions::check) must be on g's geometry.
bool fit_calibration(const Dataset &data, const DeviceGeometry &g, const FitCalibrationOptions &opt,
                     CalibrationFit &out, std::string &err);

} // namespace cdm
