// The model's readings and their derivatives with respect to every fitted
// parameter, for the fit (calib/fit.cpp). The Jacobian comes from the same
// templated kernel as the readings (effects/list.h): forward-mode automatic
// differentiation seeded only on the position and on the parameters each
// cable depends on, scattered into the full Jacobian by the layout; central
// differences through user effects.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Dense>

#include "model/model.h"

namespace cdm {

// The gauge of model effect `e` given the other effects in the model: the
// columns of the result span the parameter combinations the fit may move
// (full = start + basis * free); the identity when every parameter is free.
Eigen::MatrixXd effect_gauge_basis(const Model &m, size_t e);

class ReadingEvaluator {
public:
    // The model must outlive the evaluator; its effect list must not change
    // while the evaluator is used (parameter values are passed in).
    explicit ReadingEvaluator(const Model &m);
    ~ReadingEvaluator();
    ReadingEvaluator(const ReadingEvaluator &) = delete;
    ReadingEvaluator &operator=(const ReadingEvaluator &) = delete;

    // The fitted parameters: every parameter of every effect except
    // Position-stage ones (the ellipsoid is fitted in position space), in
    // model order. offset(e): first index of model effect e, -1 if not fitted.
    int size() const;
    int offset(size_t e) const;
    Eigen::VectorXd current() const; // from the model's values

    // Readings at jig reference position `ref` (mapped through the Jig
    // effects) at acquisition time t_s, with the parameters `full`. J
    // (4 x size()): d y / d full; dydP: d y / d device-frame position.
    // False + err naming the effect when a user effect's apply fails.
    bool eval(const Eigen::VectorXd &full, const double ref[3], double t_s, Eigen::Vector4d &y,
              Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> *dydP,
              std::string *err) const;

private:
    struct Impl;
    Impl *impl_;
};

} // namespace cdm
