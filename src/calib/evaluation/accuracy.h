// How good a fitted model is where it is used: the position error its
// parameters' uncertainty leaves at any point of the workspace, propagated
// from the fit's covariance (FitReport::cov: the readings' noise, the jig's
// estimated tolerance and errors, the parameters' correlations), over the
// jig's volume and beyond it.
//
// At a device-frame point p the calibrated model reads the true device's
// lengths l = R(p) and answers p^ with R^(p^) = l, R^ its own readings.
// To first order p^ - p = -A J d, with d the parameters' error, J = dR/dtheta
// at p and A = dp/dl the forward kinematics' sensitivity (the readings'
// least-squares inverse (D'D)^-1 D', D = dR/dp: Model::position's at an
// exact solution): its covariance is A J C J' A' (C the parameters'
// covariance). The jig's placement (Jig-stage effects) takes no part: it
// maps the jig, not the device. Position-stage effects (the seed's
// ellipsoid, fitted apart in position space) are neither propagated nor in
// A. Every point is evaluated in one batch (a user effect on arrays is
// called once).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "calib/evaluation/eval.h"
#include "calib/evaluation/spatial.h"
#include "calib/fit/fit.h"
#include "model/model.h"

namespace cdm {
namespace diag {

// chi-square(3)'s 95 % quantile: the 95 % ellipsoid is {e : e' S^-1 e <= k}.
constexpr double kChi2Of3At95 = 7.814727903251178;

// The covariance (mm^2) of the calibrated position at device-frame points
// pts (t_s: the time the readings are taken, for effects that drift),
// with cov the fit's (FitReport::cov, ReadingEvaluator's order). ok[j]
// false where the model cannot place point j (outside its workspace).
// False + err when a user effect fails or cov does not match the model.
bool position_covariances(const Model &m, const Eigen::MatrixXd &cov, const std::vector<V3> &pts, double t_s,
                          std::vector<Eigen::Matrix3d> &out, std::vector<char> &ok, std::string &err);

// The map over a grid: the jig's fixture heights in x (each one's mean
// device-frame x), and one level past each end at the heights' spacing;
// in y and z the plate's span in steps extended by a fifth of it on each
// side. A point is inside when it lies within the jig's box (x between the
// lowest and the highest height, y and z within the plate's span);
// outside, the map extrapolates. A scattered layout: five levels over its
// x span and one past each end.
struct AccuracyMap {
    std::vector<V3> p;                  // device frame, mm
    std::vector<Eigen::Matrix3d> cov;   // mm^2
    std::vector<char> inside, ok;
    std::vector<double> levels;         // the x levels, mm
    int ny = 0, nz = 0;                 // points per level: ny * nz, y fastest
    double t_s = 0;
};
bool accuracy_map(const Model &m, const FitReport &rep, const std::vector<PreparedPos> &pos, const Grid &G,
                  AccuracyMap &out, std::string &err);

// {"grid": {x_mm, y_mm, z_mm (per point), levels_mm, ny, nz}, "sigma_mm"
// [[x,y,z] per point], "radius95_mm" (the 95 % ellipsoid's longest
// semi-axis), "cov_mm2" [[xx,yy,zz,xy,xz,yz]], "inside", "placed", and
// "summary": {inside, outside: {sigma_mm {x,y,z} x {mean, max},
// radius95_mm {mean, max}}}, "method"}. Points the model cannot place are
// null.
nlohmann::json accuracy_json(const AccuracyMap &a);
// accuracy_map + accuracy_json for a fitted calibration (the fitted model
// and its fit), or {"error": why} when it cannot be computed.
nlohmann::json accuracy_map_json(const Model &m, const FitReport &rep, const std::vector<PreparedPos> &pos,
                                 const Grid &G);

// The covariance a calibration file carries (its "fit" block's
// "covariance"): {"parameters": ["effect.param", ... in ReadingEvaluator's
// order], "matrix": [[...]] (mm, rad, ... squared, as the parameters'
// units), "about"}. covariance_from_json checks it against the model: the
// same parameters in the same order, a finite symmetric matrix with a
// non-negative diagonal; false + err naming what differs.
nlohmann::json covariance_json(const Model &m, const Eigen::MatrixXd &cov);
bool covariance_from_json(const nlohmann::json &j, const Model &m, Eigen::MatrixXd &cov, std::string &err);

} // namespace diag
} // namespace cdm
