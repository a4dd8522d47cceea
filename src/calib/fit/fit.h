// Fitting a model's effect parameters to jig data with NLopt.
//
// The fit works on per-position means of the four readings (100 samples at a
// position average to one mean; the model is evaluated at the jig position,
// so nothing is lost), each weighted by the variance of that mean: the
// repeatability measured from the samples plus the jig's own tolerance mapped
// onto the cable direction. Residuals are in reading space (mm of cable),
// where the noise is simple; position errors are computed afterwards.
#pragma once

#include <functional>
#include <memory>
#include <utility>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "calib/dataset/dataset.h"
#include "model/model.h"

namespace cdm {

struct PreparedPos {
    Eigen::Vector3d ref;
    Eigen::Vector4d mean;
    Eigen::Vector4d var_mean; // variance of the mean reading from the repeatability alone
    Eigen::Matrix4d cov;      // sample covariance of the readings
    // Covariance of the mean readings the statistics use: the sample one
    // shrunk toward the pooled (prepare()), over n; its diagonal is var_mean.
    Eigen::Matrix4d cov_mean = Eigen::Matrix4d::Zero();
    int n = 0;
    double t_s = 0; // acquisition time of the position (s), for effects that drift in time
    // The part of var_mean (and of cov_mean's diagonal) that is each
    // reading's own white error (fit_calibration's estimate from the cables'
    // misclosure: a pot's hysteresis), not the pots' averaging: mm^2.
    double reading_var = 0;
};

std::vector<PreparedPos> prepare(const Dataset &d);

// A fit's whitening of the readings (problem.h), fixed by the model it
// is weighed with and the options' noise model: fit_weights.
struct FitWeights;

struct FitOptions {
    Eigen::Vector3d jig_sigma{0.03, 0.03, 0.03}; // mm, per axis, std of each position's own error
    // The plate's error per hole (mm, per axis), shared by the hole's
    // positions at every height: a random effect, so that the fit is
    // generalised least squares with each hole's readings as one block
    // (problem.h). hole[j]: position j's hole (-1: a hole of its own;
    // empty: no hole model); jig_sigma is then what is left per position.
    // Treating those errors as independent gave a candidate able to follow
    // part of a plate's pattern several times the chi-square independent
    // errors would (docs/calibration.md, "The holes in the fit").
    std::vector<int> hole;
    Eigen::Vector3d hole_sigma = Eigen::Vector3d::Zero();
    std::vector<char> use;                       // positions that take part (empty: all)
    // The jig as it is: each fixture height's own x error (jig frame, the
    // axis the spacer sets), fitted as nuisance offsets beside the model's
    // parameters, one free offset per height (their common part is the
    // spacers' mean error, i.e. the jig's placement along x; a model with a
    // translation of its own shares that direction with them, and the
    // priors give it to the model). fixture[j]: position j's height index; empty, or
    // fewer than two heights: none. Bounded by kFixtureMaxMm: a larger
    // per-height error is not a machined spacer's and is left to the model.
    std::vector<int> fixture;
    int fixture_count = 0;
    // Start the fixture offsets where they fit the starting model best (as
    // model_chi2 profiles them) instead of at zero. A candidate's start is
    // then exactly the model it extends, and the fit cannot end above it.
    // The diagnosis uses it for a candidate that ended above its base
    // (calib/search/candidates.cpp); every other fit starts them at zero, as the
    // results measured in docs/ were.
    bool profile_fixture_start = false;
    int max_evals = 400;
    std::function<bool(double)> progress;        // fraction done; false cancels
    // Parameters held at their current values (not fitted): {effect index in
    // the model, parameter index in the effect}. The diagnosis profiles a
    // seeded period this way (diag::fit_all) before one joint fit.
    std::vector<std::pair<size_t, size_t>> hold;
    // The model whose sensitivity to the position maps the jig tolerance
    // onto the readings' weights (null: the fitted model at its start). A
    // fit continued from another's result weighs the data as the first did:
    // a ripple's amplitudes change that sensitivity, so weights taken at a
    // fitted ripple would give a chi-square on another scale than the same
    // model fitted from zero amplitudes.
    const Model *weigh_with = nullptr;
    // weigh_with's whitening under these same options (fit_weights),
    // computed once for fits that share it (a period's profile search, each
    // point a fit): null, each fit computes its own. Whoever sets it keeps
    // it in step with weigh_with and the noise model.
    std::shared_ptr<const FitWeights> weights;
    // The parameters' standard errors in FitReport::std (the covariance at
    // the end of the fit: one more Hessian and its inverse). A fit compared
    // by its chi-square alone (a profile's point) goes without (zeros).
    bool statistics = true;
    // A single Gauss-Newton step (within the bounds) from the start, kept
    // when it lowers the objective, and its chi-square without a second
    // Jacobian: for a fit warm-started next to its minimum and nearly
    // linear in what it fits (a period profile's points, the period held).
    bool single_step = false;
    // A fit whose result is not wanted once a parameter passes a value:
    // {{effect index, parameter index}, value}. The fit stops as soon as its
    // best point so far lies beyond (a line-search trial beyond that does
    // not improve on the best is not enough), ends on that point, and says
    // so in FitReport::abandoned. The diagnosis gives up a joint fit of a
    // seeded period that has gone past twice the span of the measured
    // lengths (calib/search/batch.cpp): its result, ending there, is not shown.
    std::vector<std::pair<std::pair<size_t, size_t>, double>> abandon_above;
    // The positions' readings, Jacobian and weights evaluated on this many
    // threads (each position's on one: the results are the same bit for bit
    // on any number). For a fit that runs alone (the diagnosis's refits;
    // early on, the nominal pass may still run beside it); a model with a
    // user effect is evaluated on the calling thread whatever this says (its
    // callback need not be reentrant).
    int threads = 1;
};

struct FitReport {
    bool converged = false;
    int evals = 0;
    double seconds = 0;
    double chi2 = 0;   // weighted reading-space sum of squares (data part)
    int n_obs = 0;     // readings used (4 per position)
    int n_free = 0;    // free parameters after the gauge
    std::string algorithm;
    // per effect (model order), per parameter
    std::vector<std::vector<double>> std;
    // The fitted parameters' covariance (FitOptions::statistics; empty
    // without), robust to errors a plate hole's positions share beyond the
    // weights (a sandwich clustered by FitOptions::hole; fit/covariance.cpp):
    // what the accuracy map propagates. Rows and columns in the order of
    // ReadingEvaluator's full vector (every effect in model order but the
    // Position-stage ones, each effect's parameters in order); a parameter
    // fixed by the gauge or held has zero variance; the fixture offsets
    // marginalised out (their block left off the whole covariance).
    Eigen::MatrixXd cov_by_hole;
    std::string message;
    std::vector<double> fixture_mm; // fitted per-height x offsets (FitOptions::fixture)
    int n_fixture = 0;              // their free parameters (not in n_free: the same in every model)
    bool abandoned = false;         // stopped by FitOptions::abandon_above (not converged)
};

// The largest per-height error taken as the height fixture's (mm): five
// standard deviations of the spacers' tolerance below, which a Gaussian
// spacer error passes once in 1.7 million heights. The prior does the
// regularising; the cap is a sanity bound. At three (0.15 mm) one height in
// 370 would pass it, so one 5-height jig in 74: a plate with a height at
// 0.153 mm then reads "not explained" with two spurious effects recommended
// (test_diagnose.cpp, a_three_sigma_fixture_height_is_the_jigs). The judge
// (calib/evaluation/spatial.cpp, fixture_offsets) takes the per-height means up to the same
// bound, so a mean past it is clamped there as the fit's offset is.
constexpr double kFixtureMaxMm = 0.25;
// The fixture heights' offsets are a random effect with this standard
// deviation (a machined spacer's tolerance): the fit's prior on them
// (problem.h, prior_sd).
constexpr double kFixturePriorSdMm = 0.05;

// Fits every parameter of every effect in `m` except the ellipsoid's, from
// their current values. Gauge freedoms are fixed explicitly (see optimiser.cpp).
// False with rep.message when cancelled or when a user effect's apply
// returns non-zero (the message names the effect).
bool fit_model(Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt, FitReport &rep);

// The reading-space effects of a model, in its order (Position-stage
// effects, the ellipsoid, left out: they are not fitted on the readings).
std::vector<std::string> reading_effects(const Model &m);
// A copy of `from` keeping only its reading-space effects named in `keep`
// (with their fitted values), plus `add` (if not empty) at `add_init`: the
// sub-models and extensions a fit is compared with.
Model model_with(const Model &from, const std::vector<std::string> &keep, const std::string &add,
                 const ParamValues &add_init = {});

// The whitening a fit of `weigh` under opt computes (weigh_with and weights
// in opt are ignored): for FitOptions::weights. failure names a user
// effect that failed while weighing (its fits then fail with it).
std::shared_ptr<const FitWeights> fit_weights(const Model &weigh, const std::vector<PreparedPos> &pos,
                                              const FitOptions &opt);

// How much of effect `name`'s action on the readings (its Jacobian columns,
// each normalised, weighted like the fit) lies in the span of each other
// effect of `m`, and of all of them together: 1 = the others reproduce it
// exactly (indistinguishable from the data's point of view), 0 = orthogonal.
struct Overlap {
    std::vector<std::pair<std::string, double>> per_effect;
    double all = 0;
};
Overlap effect_overlap(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                       const std::string &name);

// Reading-space weighted chi-square of a model (no fitting); +infinity when
// a user effect's apply fails.
double model_chi2(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt, int *n_obs = nullptr);

// The fit's weighted residuals sqrt(w) * (mean - y) at the model's current
// parameters, and their Jacobian with respect to every fitted parameter
// (columns: the effects in model order, each effect's parameters in order,
// Position-stage effects left out; then, with FitOptions::fixture, one per
// fixture height) — what the NLopt objective uses. Rows: 4 per used
// position, in position order; with a hole model (FitOptions::hole_sigma)
// the positions are grouped by hole and each hole's rows decorrelated, so
// row 4r is no longer position r's alone. False +
// err naming the effect when a user effect's apply fails.
bool fit_residual_jacobian(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                           Eigen::VectorXd &res, Eigen::MatrixXd &J, std::string &err);

// fit_residual_jacobian's residuals and Jacobian, and beside them `extra`
// (per position: a 4 x k block, what k terms added to the model's readings
// would add, raw mm) whitened and decorrelated as the fit treats the
// readings, so that X's rows match res's: regressing res on [J X] is the
// model refitted, linearised, with the k terms beside it.
bool fit_residual_jacobian_with(const Model &m, const std::vector<PreparedPos> &pos, const FitOptions &opt,
                                const std::vector<Eigen::Matrix<double, 4, Eigen::Dynamic>> &extra,
                                Eigen::VectorXd &res, Eigen::MatrixXd &J, Eigen::MatrixXd &X, std::string &err);

// The seed's ellipsoid (eq. 4-5): fitted to per-position x errors over the
// estimated (y, z), least squares weighted by sample count. Returns L, M, N.
struct Ellipsoid {
    double L = 0, M = 1e6, N = 1e6;
    double xc(double y, double z) const;
};
Ellipsoid fit_ellipsoid(const std::vector<double> &ye, const std::vector<double> &ze,
                        const std::vector<double> &xerr, const std::vector<double> &w);

} // namespace cdm
