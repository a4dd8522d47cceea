// A user effect that works on arrays (cdm_effect_def.apply_batch, since 1.1)
// against the same effect given per position (apply): the evaluator's batch
// path gives the same readings and derivatives, the fit the same parameters
// and chi-square, with one call per central-difference step over all
// positions; a non-zero return fails the fit naming the effect; a
// batch-only effect is called with n = 1 where the model needs one position.
// The position solves over all positions (Model::positions, behind
// diag::evaluate) give what the per-position solve gives, fail where it
// fails, and leave a whole diagnosis without a call with n = 1.
//
// The effect is the worn spot of docs/calibration.md (a Gaussian dip of the
// reading around one cable length), with a position term so that the
// position derivatives are exercised too. The model around it has a
// built-in on the cables (cable_offset) and one on the jig
// (jig_misalignment), whose Jacobians the user effect's are chained onto.
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <setjmp.h>

#include "calib/evaluation/eval.h"
#include "calib/diagnosis/diagnose.h"
#include "calib/fit/fit.h"
#include "calib/dataset/simulate.h"
#include "model/effect.h"
#include "model/evaluator.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

namespace {

// depth (mm), centre (mm of cable), width (mm), tilt (mm of reading per mm of x)
int spot_row(const double *p, const double *P, double *r) {
    if (!(p[2] > 0)) return 1;
    for (int i = 0; i < 4; ++i) {
        const double u = (r[i] - p[1]) / p[2];
        r[i] += p[0] * std::exp(-u * u) + p[3] * 1e-3 * P[0];
    }
    return 0;
}

struct Counts {
    long one = 0, batch = 0, batch_n1 = 0;
    size_t batch_min_n = SIZE_MAX, batch_max_n = 0;
};
Counts g_count;

int spot_apply(void *, const double *p, const double P[3], double r[4]) {
    ++g_count.one;
    return spot_row(p, P, r);
}
int spot_apply_batch(void *, const double *p, size_t n, const double *P, double *r) {
    ++g_count.batch;
    if (n == 1) ++g_count.batch_n1;
    g_count.batch_min_n = std::min(g_count.batch_min_n, n);
    g_count.batch_max_n = std::max(g_count.batch_max_n, n);
    for (size_t i = 0; i < n; ++i)
        if (spot_row(p, P + 3 * i, r + 4 * i) != 0) return 1;
    return 0;
}
int failing_batch(void *, const double *, size_t, const double *, double *) { return 5; }
// Gives a NaN reading once the depth has moved away from its start (by more
// than any central-difference step, 1e-4 mm): a failure in the middle of
// the optimisation, as numpy's overflow (a warning, not an exception) gives.
long g_nan_calls = 0, g_nan_calls_after = 0;
int nan_when_moved(void *, const double *p, size_t n, const double *P, double *r) {
    for (size_t i = 0; i < n; ++i) spot_row(p, P + 3 * i, r + 4 * i);
    if (g_nan_calls > 0) ++g_nan_calls_after;
    if (std::fabs(p[0]) > 0.05 && n > 0) {
        r[4 * (n - 1) + 2] = std::nan("");
        ++g_nan_calls;
    }
    return 0;
}
// The spot, failing beyond y = 55 mm (the plate's outer column of holes, at
// y = 60 mm, and the nearby points of a solve).
int picky_apply(void *u, const double *p, const double P[3], double r[4]) {
    return P[1] > 55 ? 1 : spot_apply(u, p, P, r);
}
int picky_apply_batch(void *u, const double *p, size_t n, const double *P, double *r) {
    for (size_t i = 0; i < n; ++i)
        if (P[3 * i + 1] > 55) return 1;
    return spot_apply_batch(u, p, n, P, r);
}

const char *kNames[] = {"depth_mm", "centre_mm", "width_mm", "tilt"};
const double kScale[] = {0.1, 10.0, 2.0, 0.1};
const double kLower[] = {-5.0, 50.0, 1.0, -10.0};
const double kUpper[] = {5.0, 400.0, 50.0, 10.0};
const double kInitial[] = {0.0, 178.0, 5.0, 0.0};

int register_spot(const char *name, cdm_effect_apply_fn one, cdm_effect_apply_batch_fn batch,
                  uint32_t struct_size = sizeof(cdm_effect_def)) {
    cdm_effect_def d{};
    d.struct_size = struct_size;
    d.n_params = 4;
    d.name = name;
    d.doc = "a dip worn into the pot tracks around one cable length, and a tilt in x";
    d.param_names = kNames;
    d.param_scale = kScale;
    d.lower = kLower;
    d.upper = kUpper;
    d.initial = kInitial;
    d.apply = one;
    d.apply_batch = batch;
    return cdm_effect_register(&d);
}

Model model_with(const char *user_effect) {
    Model m{DeviceGeometry{}};
    std::string err;
    if (!m.add_effect("jig_misalignment", {}, err) || !m.add_effect("cable_offset", {}, err) ||
        !m.add_effect(user_effect, {}, err))
        fail_msg("model: %s", err.c_str());
    return m;
}

// Jig data from a truth with the spot (the per-position form) and the
// built-ins: the 13x13 plate at 10 mm on 5 heights, 20 samples.
Dataset jig_dataset() {
    Model truth{DeviceGeometry{}};
    std::string err;
    if (!truth.add_effect("cable_offset", {{"o1", 0.3}, {"o2", -0.2}, {"o3", 0.25}, {"o4", -0.3}}, err) ||
        !truth.add_effect("spot_one", {{"depth_mm", -0.25}, {"centre_mm", 180}, {"width_mm", 6}, {"tilt", 0.5}},
                          err))
        fail_msg("truth: %s", err.c_str());
    JigSimOptions o;
    o.n = 13;
    o.pitch_mm = 10;
    o.samples = 20;
    o.seed = 21;
    Dataset d;
    if (!simulate_jig(truth, o, d, err)) fail_msg("simulate: %s", err.c_str());
    return d;
}
std::vector<PreparedPos> jig_data() { return prepare(jig_dataset()); }

// Sets the user effect (the model's last) to v.
void set_spot(Model &m, const std::vector<double> &v) {
    std::string err;
    if (!m.set_effect_params(m.effect_count() - 1, v, err)) fail_msg("%s", err.c_str());
}

// evaluate() (FK of every position's mean readings, the reading Jacobians,
// the noise of the estimates) with the batch-only effect and with the same
// effect per position. Both solves take the same steps from the same start
// and stop at the same test (a step under 1e-9 mm); the batch rows go
// through spot_row on the same doubles, so the results are equal to the last
// bit here. The check allows what the convergence test leaves open: 1e-9 mm
// on a position (a solve stopped one step apart moves it by less than its
// last step, under 1e-9 mm), and 1e-9 relative on var_mean and Jp (their
// central differences at points 1e-9 mm apart). Returns the count of
// positions that failed.
size_t evaluate_same(const Model &mb, const Model &mo, const std::vector<PreparedPos> &pos) {
    g_count = Counts{};
    const diag::Eval Eb = diag::evaluate(mb, pos);
    const Counts cb = g_count;
    const diag::Eval Eo = diag::evaluate(mo, pos);
    // No call with one position: after a failed batch call the points are
    // redone with their 7 rows in one call each.
    assert_int_equal(cb.batch_n1, 0);
    assert_int_equal(cb.one, 0);
    size_t failed = 0;
    bool bit_identical = true;
    auto near = [&](double a, double b, double tol) {
        if (a != b) bit_identical = false;
        return std::fabs(a - b) <= tol;
    };
    for (size_t j = 0; j < pos.size(); ++j) {
        assert_int_equal(Eb.ok[j], Eo.ok[j]);
        if (!Eo.ok[j]) {
            ++failed;
            continue;
        }
        for (int a = 0; a < 3; ++a) {
            if (!near(Eb.est[j](a), Eo.est[j](a), 1e-9) || !near(Eb.res[j](a), Eo.res[j](a), 1e-9))
                fail_msg("position %zu axis %d: est %.17g vs %.17g", j, a, Eb.est[j](a), Eo.est[j](a));
            if (!near(Eb.var_mean[j](a), Eo.var_mean[j](a), 1e-9 * Eo.var_mean[j](a)))
                fail_msg("position %zu var_mean %d: %.17g vs %.17g", j, a, Eb.var_mean[j](a), Eo.var_mean[j](a));
            for (int c = 0; c < 4; ++c)
                assert_true(near(Eb.Jp[j](a, c), Eo.Jp[j](a, c), 1e-9 * std::max(1.0, std::fabs(Eo.Jp[j](a, c)))));
        }
    }
    assert_int_equal(Eb.bad_samples, Eo.bad_samples);
    for (int a = 0; a < 3; ++a) {
        assert_true(near(Eb.err[a].n, Eo.err[a].n, 0));
        // The sums over positions of the error and its square (mm, mm^2).
        assert_true(near(Eb.err[a].s, Eo.err[a].s, 1e-9 * Eo.err[a].n));
        assert_true(near(Eb.err[a].ss, Eo.err[a].ss, 1e-9 * std::max(1.0, Eo.err[a].ss)));
    }
    print_message("%zu positions, %zu failed, batch calls %ld (n = 1: %ld), per position %ld; %s\n", pos.size(),
                  failed, cb.batch, cb.batch_n1, g_count.one, bit_identical ? "bit-identical" : "within tolerance");
    return failed;
}

// Every test effect but spot_batch (the diagnosis test takes them out: its
// review tries every registered effect in the model).
const char *kOthers[] = {"spot_one", "spot_both", "spot_fail", "spot_nan", "picky_one", "picky_batch"};
int register_others() {
    if (register_spot("spot_one", spot_apply, nullptr) != CDM_OK) return -1;
    if (register_spot("spot_both", spot_apply, spot_apply_batch) != CDM_OK) return -1;
    if (register_spot("spot_fail", nullptr, failing_batch) != CDM_OK) return -1;
    if (register_spot("spot_nan", nullptr, nan_when_moved) != CDM_OK) return -1;
    if (register_spot("picky_one", picky_apply, nullptr) != CDM_OK) return -1;
    if (register_spot("picky_batch", nullptr, picky_apply_batch) != CDM_OK) return -1;
    return 0;
}
int setup(void **) {
    if (register_spot("spot_batch", nullptr, spot_apply_batch) != CDM_OK) return -1;
    return register_others();
}
int teardown(void **) {
    for (const char *n : {"spot_one", "spot_batch", "spot_both", "spot_fail", "spot_nan", "picky_one", "picky_batch"})
        cdm_effect_unregister(n);
    return 0;
}

} // namespace

// The evaluator: eval_batch over all positions against eval at each, for a
// batch-only effect and for the same effect per position. The batch rows go
// through the same arithmetic in the same order (spot_row on the same
// doubles, the same chaining code), so the results are equal to the last
// bit; the check allows 1e-12 relative for a compiler contracting the two
// call sites' arithmetic differently.
static void evaluator_batch_equals_per_position(void **) {
    const auto pos = jig_data();
    const Model mb = model_with("spot_batch"), mo = model_with("spot_one");
    ReadingEvaluator eb(mb), eo(mo);
    assert_true(eb.has_batch());
    assert_false(eo.has_batch());
    Eigen::VectorXd full = eb.current();
    for (int a = 0; a < full.size(); ++a) full(a) += 0.01 * std::sin(1.0 + a); // away from the starts
    std::vector<double> refs, ts;
    for (auto &p : pos) {
        refs.insert(refs.end(), {p.ref(0), p.ref(1), p.ref(2)});
        ts.push_back(p.t_s);
    }
    auto close = [](double a, double b) { return std::fabs(a - b) <= 1e-12 * std::max(1.0, std::fabs(b)); };
    for (bool want_J : {false, true}) {
        ReadingEvaluator::Batch B;
        std::string err;
        g_count = Counts{};
        assert_true(eb.eval_batch(full, pos.size(), refs.data(), ts.data(), want_J, true, B, &err));
        // One call per step (1, or 1 + 8 + 6 + 2 x 4 with derivatives), all positions each time.
        assert_int_equal(g_count.batch, want_J ? 23 : 1);
        assert_int_equal(g_count.batch_min_n, pos.size());
        assert_int_equal(g_count.batch_max_n, pos.size());
        for (size_t i = 0; i < pos.size(); ++i) {
            Eigen::Vector4d y;
            Eigen::Matrix<double, 4, Eigen::Dynamic> J;
            Eigen::Matrix<double, 4, 3> dP;
            assert_true(eo.eval(full, &refs[3 * i], ts[i], y, want_J ? &J : nullptr, &dP, &err));
            for (int c = 0; c < 4; ++c) {
                if (!close(B.y[i](c), y(c))) fail_msg("position %zu reading %d: %.17g vs %.17g", i, c, B.y[i](c), y(c));
                for (int k = 0; k < 3; ++k) assert_true(close(B.dydP[i](c, k), dP(c, k)));
                if (want_J)
                    for (int a = 0; a < J.cols(); ++a)
                        if (!close(B.J[i](c, a), J(c, a)))
                            fail_msg("position %zu dy%d/dp%d: %.17g vs %.17g", i, c, a, B.J[i](c, a), J(c, a));
            }
        }
    }
}

// The fit: the same parameters and chi-square (the same arithmetic as above,
// so the same path through SLSQP; the bound of 1e-9 of each parameter's
// scale and of chi2 is round-off grown through a few hundred solver steps,
// far below the fit's own standard errors), and the truth recovered.
static void fit_batch_equals_per_position(void **) {
    const auto pos = jig_data();
    FitOptions opt;
    Model mo = model_with("spot_one"), mb = model_with("spot_batch"), m2 = model_with("spot_both");
    FitReport ro, rb, r2;
    g_count = Counts{};
    assert_true(fit_model(mo, pos, opt, ro));
    const long per_position_calls = g_count.one;
    g_count = Counts{};
    assert_true(fit_model(mb, pos, opt, rb));
    // Every batch call is over every position: the fit never asks for one.
    assert_int_equal(g_count.batch_min_n, pos.size());
    assert_int_equal(g_count.one, 0);
    print_message("per-position calls %ld, batch calls %ld (%zu positions), evaluations %d and %d\n",
                  per_position_calls, g_count.batch, pos.size(), ro.evals, rb.evals);
    assert_true(g_count.batch * long(pos.size()) == per_position_calls);
    // Both given: the fit takes apply_batch.
    g_count = Counts{};
    assert_true(fit_model(m2, pos, opt, r2));
    assert_int_equal(g_count.one, 0);
    assert_true(g_count.batch > 0);
    assert_int_equal(ro.evals, rb.evals);
    assert_true(std::fabs(ro.chi2 - rb.chi2) <= 1e-9 * ro.chi2);
    assert_true(std::fabs(ro.chi2 - r2.chi2) <= 1e-9 * ro.chi2);
    for (size_t e = 0; e < mo.effect_count(); ++e) {
        const auto &po = mo.effect_params(e), &pb = mb.effect_params(e);
        for (size_t k = 0; k < po.size(); ++k) {
            const double tol = 1e-9 * mo.effect_desc(e).params[k].scale;
            if (std::fabs(po[k] - pb[k]) > tol)
                fail_msg("%s.%s: %.12g per position, %.12g batch", mo.effect_name(e).c_str(),
                         mo.effect_desc(e).params[k].name.c_str(), po[k], pb[k]);
        }
    }
    // The truth back (5 standard errors: the fit's own uncertainty).
    const double truth[] = {-0.25, 180, 6, 0.5};
    const size_t ue = mb.effect_count() - 1;
    assert_string_equal(mb.effect_name(ue).c_str(), "spot_batch");
    for (size_t k = 0; k < 4; ++k)
        if (std::fabs(mb.effect_params(ue)[k] - truth[k]) > 5 * rb.std[ue][k])
            fail_msg("%s %g +- %g, truth %g", kNames[k], mb.effect_params(ue)[k], rb.std[ue][k], truth[k]);
}

// A non-zero return from apply_batch fails the fit, the chi-square and the
// Jacobian with the effect's name.
static void failing_batch_fails_the_fit(void **) {
    const auto pos = jig_data();
    FitOptions opt;
    Model m = model_with("spot_fail");
    FitReport rep;
    assert_false(fit_model(m, pos, opt, rep));
    if (rep.message.find("\"spot_fail\"") == std::string::npos || rep.message.find("apply_batch") == std::string::npos)
        fail_msg("message: %s", rep.message.c_str());
    assert_true(std::isinf(model_chi2(m, pos, opt)));
    Eigen::VectorXd res;
    Eigen::MatrixXd J;
    std::string err;
    assert_false(fit_residual_jacobian(m, pos, opt, res, J, err));
    assert_true(err.find("spot_fail") != std::string::npos);
}

// A NaN reading from a user effect in the middle of a fit fails the fit,
// naming the effect and the cable, and stops the optimiser there: the
// effect is not called again (before, the stop was asked of a NULL handle
// and SLSQP went on calling the failing effect up to its evaluation limit).
static void nan_reading_fails_and_stops_the_fit(void **) {
    const auto pos = jig_data();
    FitOptions opt;
    Model m = model_with("spot_nan");
    FitReport rep;
    g_nan_calls = g_nan_calls_after = 0;
    assert_false(fit_model(m, pos, opt, rep));
    if (rep.message.find("\"spot_nan\"") == std::string::npos || rep.message.find("non-finite reading of cable 3") == std::string::npos)
        fail_msg("message: %s", rep.message.c_str());
    assert_int_equal(g_nan_calls, 1);
    if (g_nan_calls_after != 0) fail_msg("the effect was called %ld times after its NaN", g_nan_calls_after);
}

// One position (the pose, a position solve): a batch-only effect is called
// with n = 1 and gives the per-position effect's readings.
static void batch_only_at_one_position(void **) {
    Model mb = model_with("spot_batch"), mo = model_with("spot_one");
    std::string err;
    const std::vector<double> v = {-0.25, 180, 6, 0.5};
    assert_true(mb.set_effect_params(mb.effect_count() - 1, v, err));
    assert_true(mo.set_effect_params(mo.effect_count() - 1, v, err));
    const double p[3] = {50, 10, -20};
    double yb[4], yo[4];
    g_count = Counts{};
    assert_int_equal(mb.readings(p, 0.0, yb), 0);
    assert_int_equal(g_count.batch, 1);
    assert_int_equal(g_count.batch_max_n, 1);
    assert_int_equal(mo.readings(p, 0.0, yo), 0);
    for (int c = 0; c < 4; ++c) assert_true(yb[c] == yo[c]);
    double q[3];
    assert_int_equal(mb.position(yb, q), 0);
    for (int k = 0; k < 3; ++k) assert_true(std::fabs(q[k] - p[k]) < 1e-6);
}

// evaluate() over the jig: at the truth's spot every position converges; a
// spot steeper than the cable (-5 mm deep over 1 mm: the reading falls as the
// cable lengthens near its centre) leaves Gauss-Newton without convergence
// at some positions, which fail in the batch as they do one at a time.
static void evaluate_batch_equals_per_position(void **) {
    const auto pos = jig_data();
    Model mb = model_with("spot_batch"), mo = model_with("spot_one");
    for (Model *m : {&mb, &mo}) set_spot(*m, {-0.25, 180, 6, 0.5});
    assert_int_equal(evaluate_same(mb, mo, pos), 0);
    // At most one call per Gauss-Newton iteration and one for the Jacobians.
    g_count = Counts{};
    (void)diag::evaluate(mb, pos);
    assert_true(g_count.batch <= 30 + 1);
    for (Model *m : {&mb, &mo}) set_spot(*m, {-5, 190, 1, 0.5});
    assert_true(evaluate_same(mb, mo, pos) > 0);
}

// A user effect that fails at some positions (y > 55 mm): the batch call
// over all of them fails, that step is redone one position at a time, and
// the same positions fail as one at a time (the 65 holes of the y = 60 mm
// column at least), the others solved alike; the redo costs one call per
// position once, not a solve per position.
static void failing_positions_fail_alike(void **) {
    const auto pos = jig_data();
    Model mb = model_with("picky_batch"), mo = model_with("picky_one");
    for (Model *m : {&mb, &mo}) set_spot(*m, {-0.25, 180, 6, 0.5});
    const size_t failed = evaluate_same(mb, mo, pos);
    assert_true(failed >= 65);
    g_count = Counts{};
    (void)diag::evaluate(mb, pos);
    // Two failed batch calls (the first iteration, the Jacobians) each
    // redone per position, and the iterations' batch calls.
    assert_true(size_t(g_count.batch) <= 2 * (pos.size() + 1) + 30);
    assert_true(failed < pos.size());
}

// A whole diagnosis (the fit, its evaluations, the model review, the
// validation, the residual views; no candidates) with the batch-only effect:
// nothing calls the effect one position at a time. Before the batched solve
// every evaluate() made 7 calls with n = 1 per position and Gauss-Newton
// iteration and 7 for its Jacobian (over 20,000 for these 845 positions each
// time), and each residual view one per position.
static void diagnosis_calls_with_one_position(void **) {
    const Dataset d = jig_dataset();
    DiagnoseOptions o;
    o.effects = {"jig_misalignment", "cable_offset", "spot_batch"};
    o.candidates = false;
    o.search = false;
    nlohmann::json out;
    Model fitted{DeviceGeometry{}};
    std::string err;
    for (const char *n : kOthers) assert_int_equal(cdm_effect_unregister(n), CDM_OK);
    g_count = Counts{};
    const bool ok = diagnose(d, DeviceGeometry{}, o, out, fitted, err);
    const Counts c = g_count;
    assert_int_equal(register_others(), 0);
    if (!ok) fail_msg("diagnose: %s", err.c_str());
    const size_t P = prepare(d).size();
    print_message("diagnosis: %ld batch calls, %ld of them with n = 1, %ld per position (%zu positions)\n",
                  c.batch, c.batch_n1, c.one, P);
    assert_int_equal(c.one, 0);
    // None left: the residual views' readings are batched too (they made P
    // calls with n = 1 per view).
    assert_int_equal(c.batch_n1, 0);
}

// Registration: neither function is refused; a 1.0-sized struct has no
// apply_batch field, so one given there is not read.
static void registration(void **) {
    assert_int_equal(register_spot("spot_none", nullptr, nullptr), CDM_ERR_INVALID_ARG);
    assert_int_equal(register_spot("spot_old", nullptr, spot_apply_batch, uint32_t(offsetof(cdm_effect_def, initial))),
                     CDM_ERR_INVALID_ARG);
    assert_int_equal(register_spot("spot_old", spot_apply, spot_apply_batch,
                                   uint32_t(offsetof(cdm_effect_def, apply_batch))),
                     CDM_OK);
    assert_true(find_effect("spot_old")->apply_batch == nullptr);
    assert_int_equal(cdm_effect_unregister("spot_old"), CDM_OK);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(evaluator_batch_equals_per_position),
        cmocka_unit_test(fit_batch_equals_per_position),
        cmocka_unit_test(failing_batch_fails_the_fit),
        cmocka_unit_test(nan_reading_fails_and_stops_the_fit),
        cmocka_unit_test(batch_only_at_one_position),
        cmocka_unit_test(evaluate_batch_equals_per_position),
        cmocka_unit_test(failing_positions_fail_alike),
        cmocka_unit_test(diagnosis_calls_with_one_position),
        cmocka_unit_test(registration),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
