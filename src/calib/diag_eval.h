// The model evaluated on jig data: per-position residuals, their noise, and
// per-sample error statistics, for the fitted model and for the seed's
// procedure (triangulation, optionally the ellipsoid).
#pragma once

#include <vector>

#include <Eigen/Dense>

#include "calib/dataset.h"
#include "calib/diag_stats.h"
#include "calib/fit.h"
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
};

Eval evaluate(const Model &m, const Dataset &d, const std::vector<PreparedPos> &pos);
Eval evaluate_seed(const DeviceGeometry &g, const Dataset &d, const std::vector<PreparedPos> &pos,
                   const Ellipsoid *ell);
Ellipsoid ellipsoid_on(const Eval &E, const std::vector<PreparedPos> &pos);

} // namespace diag
} // namespace cdm
