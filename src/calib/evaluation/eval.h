// The model evaluated on jig data: per-position residuals, their noise, and
// per-sample error statistics, for the fitted model and for the seed's
// procedure (triangulation, optionally the ellipsoid).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Dense>

#include "calib/dataset/dataset.h"
#include "calib/evaluation/stats.h"
#include "calib/fit/fit.h"
#include "model/model.h"

namespace cdm {
namespace diag {

using V3 = Eigen::Vector3d;
struct Eval {
    std::vector<V3> res;                           // FK(mean) - T(ref), per position
    std::vector<Eigen::Matrix<double, 3, 4>> Jp;   // d position / d readings at the estimate
    std::vector<V3> var_mean;                      // noise variance of the position mean, per axis
    std::vector<char> ok;                          // FK converged
    std::vector<V3> est;                           // estimated position (device frame)
    Acc err[3];                                    // per-sample error statistics
    Acc within[3];                                 // per-sample deviation from the position mean
    size_t bad_samples = 0;
    // The four cables measure three coordinates: the mean readings' part
    // that no position explains, (mean - readings(est)) along the unit
    // direction dir no position change moves (J' dir = 0, J the readings'
    // derivative at est; its sign is the solver's, so readers align it),
    // mm, with its noise variance from the readings' covariance. Neither
    // the reference nor the jig's error enters it.
    std::vector<double> mis, mis_var;
    std::vector<Eigen::Vector4d> mis_dir;
    // The readings' own white error (PreparedPos::reading_var) in position
    // space, per axis, averaged over the positions (mm^2): part of the noise
    // floor.
    V3 reading_var = V3::Zero();
};

// The model on per-position statistics: residuals by FK of the mean
// readings, and the per-sample error's mean, std and RMS through the local
// linearisation (exact from each position's mean and covariance). The
// per-sample maxima (err[].mx, within[].mx) need every sample: NaN (null in
// JSON) until sample_pass() fills them. The positions on `threads` threads
// (the same numbers, bit for bit; in turn with a user effect).
Eval evaluate(const Model &m, const std::vector<PreparedPos> &pos, int threads = 1);

// The seed's procedure (triangulation, optionally the ellipsoid) applied to
// every sample, into `out`.
struct SeedRequest {
    const DeviceGeometry *geometry;
    const Ellipsoid *ellipsoid; // null: triangulation alone
    Eval *out;
};

// One pass over the dataset's rows (for_each_sample) for what needs every
// sample: the maxima of `linear` (evaluations from evaluate() on `pos`) and
// the seed evaluations asked for. False + err when the rows cannot be read
// again (the file changed since it was loaded). piped: the rows parsed on
// this thread and visited on a second one (the same results, bit for bit:
// eval.cpp); false, all on this thread.
bool sample_pass(const Dataset &d, const std::vector<PreparedPos> &pos, const std::vector<Eval *> &linear,
                 const std::vector<SeedRequest> &seeds, std::string &err, bool piped = false);
bool evaluate_seed(const DeviceGeometry &g, const Dataset &d, const std::vector<PreparedPos> &pos,
                   const Ellipsoid *ell, Eval &out, std::string &err, bool piped = false);
Ellipsoid ellipsoid_on(const Eval &E, const std::vector<PreparedPos> &pos);

// Per axis: the samples' scatter about their position mean, through the
// model's own Jacobian, and the jig's tolerance.
V3 noise_floor(const Eval &E, const V3 &jig);

} // namespace diag
} // namespace cdm
