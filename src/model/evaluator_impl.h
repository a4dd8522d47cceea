// The evaluator's internals (evaluator.h), shared by its three files:
// evaluator.cpp the built-in kernel with its automatic differentiation,
// evaluator_user.cpp the user effects' central differences and the batches,
// evaluator_path.cpp the split of the kernel around user effects on the
// cable's path (CDM_EFFECT_STAGE_PATH). Private to src/model.
#pragma once

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "model/evaluator.h"
#include "model/model_impl.h"

namespace cdm {

namespace ev {
// Derivative vectors: at most 3 position + every cable parameter; fixed
// maximum size, so no heap allocation per evaluation.
constexpr int kMaxLocal = 3 + kMaxCableSlots;
constexpr int kMaxJig = 16; // Jig-stage parameters of all built-ins together
using ADJ = Eigen::AutoDiffScalar<Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxJig, 1>>;
using DPdj = Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxJig>; // d P / d (jig parameters)
using Jac = Eigen::Matrix<double, 4, Eigen::Dynamic>;
using Jac3 = Eigen::Matrix<double, 4, 3>;

// Central differences through a user effect: call k's input is the state
// (parameters, position, values) with at most one entry moved. k = 0: the
// value; then + and - a step on each incoming value (4), each position
// coordinate (3) and each parameter, so the difference for entry j is
// (out[1 + 2j] - out[2 + 2j]) / (2 h). Steps (those the per-position path
// has always used): 1e-5 mm on a value, 1e-4 mm on the position, the
// larger of 1e-6 and 1e-3 of a parameter's typical size: well above the
// round-off of a value near 100-300 mm (~3e-14 mm).
enum class Moved { None, Reading, Position, Param };
struct UserStep {
    Moved what;
    int idx;
    double h; // signed
};
constexpr double kReadingStep = 1e-5, kPositionStep = 1e-4;
inline double param_step(const EffectDesc &d, int k) { return 1e-6 * std::max(1.0, d.params[size_t(k)].scale * 1e3); }
inline int user_calls(const EffectDesc &d, bool deriv) { return deriv ? 15 + 2 * int(d.params.size()) : 1; }
inline UserStep user_step(const EffectDesc &d, int k) {
    if (k == 0) return {Moved::None, 0, 0.0};
    const int j = (k - 1) / 2;
    const double sign = (k - 1) % 2 == 0 ? 1.0 : -1.0;
    if (j < 4) return {Moved::Reading, j, sign * kReadingStep};
    if (j < 7) return {Moved::Position, j - 4, sign * kPositionStep};
    return {Moved::Param, j - 7, sign * param_step(d, j - 7)};
}
constexpr int kMaxUserCalls = 15 + 2 * kMaxUserParams; // the most calls one user effect needs

// A user effect's values must be numbers: a NaN or an infinity (numpy
// overflows warn, they do not raise) would reach the optimiser's gradient
// and end a fit on a misleading status. Names the effect, cable and position.
bool finite_values(const EffectDesc &d, const double *Y, size_t n, const double *P, std::string *err);
} // namespace ev

struct ReadingEvaluator::Impl {
    const Model &m;
    std::vector<const EffectDesc *> desc;
    ModelLayout lay;
    std::vector<int> off; // per model effect
    int n = 0;
    // Jig-stage effects: model effect index and first slot in the jig AD vector.
    std::vector<std::pair<int, int>> jig;
    int njig = 0;
    // Per cable, per slot: column in the full parameter vector.
    std::array<std::array<int, kMaxCableSlots>, 4> col{};

    explicit Impl(const Model &m_);

    // P = jig map of ref, with dP/d(jig parameters) in dPdj (3 x njig).
    void jig_position(const Eigen::VectorXd &full, const double ref[3], double P[3], ev::DPdj &dPdj) const;
    // The built-in effects' part of eval: the device-frame position P (and
    // dPdj), the readings y, and when `values_only` is false J (if given)
    // and dP.
    // npos: the position derivatives the caller wants in dP (0, 1: x, or 3).
    // path_only: the kernel's first half, y the lengths after the Path
    // stage (builtin_path).
    void builtin(const Eigen::VectorXd &full, const double ref[3], double t_s, double P[3], ev::DPdj &dPdj,
                 Eigen::Vector4d &y, ev::Jac *J, ev::Jac3 &dP, bool values_only, int npos = 3,
                 bool path_only = false) const;
    // User effect e at one position: the outputs of its user_calls calls
    // (apply, or apply_batch on one row, or apply_geom with the cables'
    // frame F at P). False on a non-zero return.
    bool user_one(size_t e, const Eigen::VectorXd &full, const double P[3], double t_s, const CableFrame *F,
                  const Eigen::Vector4d &y, bool deriv, Eigen::Vector4d *out, std::string *err) const;
    // Chains user effect e's central differences (out: its calls' outputs)
    // onto y, J and dP.
    void chain(size_t e, const Eigen::Vector4d *out, const ev::DPdj &dPdj, Eigen::Vector4d &y, ev::Jac *J,
               ev::Jac3 &dP) const;
    // User effect e over n positions (P n x 3, T n, F their frames when it
    // is geometry-aware): its calls over every row at once, chained onto
    // y[i], J[i] (when J is not null) and dP[i]. False on a non-zero return.
    bool user_rows(size_t e, const Eigen::VectorXd &full, size_t n, const double *P, const double *T,
                   const CableFrame *F, const ev::DPdj *dPdj, Eigen::Vector4d *y, ev::Jac *J, ev::Jac3 *dP,
                   bool deriv, std::vector<double> &scratch, std::string *err) const;

    // evaluator_path.cpp. The frames of the four cables at P with the
    // parameters `full` (values only), and their lengths after the Path
    // stage into len when it is not null.
    void frame_at(const Eigen::VectorXd &full, const double P[3], double t_s, CableFrame &F,
                  double *len = nullptr) const;
    // The kernel's first half (Jig, Geometry, Path): P, dPdj, the lengths
    // and, when deriv, their Jacobian Jl (4 x size()) and dl/dP; F the
    // frames at P.
    void builtin_path(const Eigen::VectorXd &full, const double ref[3], double t_s, double P[3], ev::DPdj &dPdj,
                      Eigen::Vector4d &len, ev::Jac &Jl, ev::Jac3 &dPl, CableFrame &F, bool deriv) const;
    // The second half (Transfer) on the lengths, their derivatives carried
    // through it: y, and when deriv, J (if given) and dP.
    void transfer(const Eigen::VectorXd &full, const double P[3], double t_s, const ev::DPdj &dPdj,
                  const Eigen::Vector4d &len, const ev::Jac &Jl, const ev::Jac3 &dPl, Eigen::Vector4d &y,
                  ev::Jac *J, ev::Jac3 &dP, bool deriv) const;
    // eval and eval_batch for a model with a user effect on the path.
    bool eval_path(const Eigen::VectorXd &full, const double ref[3], double t_s, Eigen::Vector4d &y, ev::Jac *J,
                   ev::Jac3 *dydP, std::string *err) const;
    bool eval_batch_path(const Eigen::VectorXd &full, size_t n, const double *refs, const double *t_s, bool want_J,
                         bool want_dydP, Batch &out, std::string *err) const;
    // The user effects of the readings' stage (all user effects but those on
    // the path) after the built-ins, one position.
    bool reading_users(const Eigen::VectorXd &full, const double P[3], double t_s, const CableFrame *F,
                       const ev::DPdj &dPdj, Eigen::Vector4d &y, ev::Jac *J, ev::Jac3 &dP, std::string *err) const;
};

} // namespace cdm
