// The model's readings and their derivatives with respect to every fitted
// parameter, for the fit (calib/fit/optimiser.cpp). The Jacobian comes from the same
// templated kernel as the readings (effects/list.h): forward-mode automatic
// differentiation seeded only on the position and on the parameters each
// cable depends on, scattered into the full Jacobian by the layout; central
// differences through user effects (over all positions at once for those
// that work on arrays: eval_batch).
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
    // (4 x size()): d y / d full; dydP: d y / d device-frame position, its
    // first dydP_cols columns (1: x only, the others then zero; the
    // derivatives not asked for are not carried through the kernel).
    // False + err naming the effect when a user effect's apply fails.
    bool eval(const Eigen::VectorXd &full, const double ref[3], double t_s, Eigen::Vector4d &y,
              Eigen::Matrix<double, 4, Eigen::Dynamic> *J, Eigen::Matrix<double, 4, 3> *dydP,
              std::string *err, int dydP_cols = 3) const;

    // eval at n positions at once (refs: n x 3 row-major, t_s: n), with the
    // same values and derivatives, into out (its memory is reused from one
    // call to the next). A user effect with apply_batch is called once per
    // central-difference step over all positions instead of once per
    // position and step; one with only apply, per position as in eval.
    struct Batch {
        std::vector<Eigen::Vector4d> y;
        std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> J; // when want_J
        std::vector<Eigen::Matrix<double, 4, 3>> dydP;           // when want_dydP
        std::vector<double> scratch;                             // the batch calls' rows
    };
    bool eval_batch(const Eigen::VectorXd &full, size_t n, const double *refs, const double *t_s, bool want_J,
                    bool want_dydP, Batch &out, std::string *err) const;
    // A user effect of the model works on arrays: eval_batch saves calls.
    bool has_batch() const;
    // The model has a user effect: its callback may not be called from
    // several threads at once. Without one, eval may be (it is const and
    // keeps no state between calls).
    bool has_user() const;

private:
    struct Impl;
    Impl *impl_;
};

} // namespace cdm
