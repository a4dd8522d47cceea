// Triangulation (eq. 1-3) and the effect model's forward kinematics.
#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <random>
#include <fstream>
#include <setjmp.h>
#include <unistd.h>
#include <sstream>
#include <vector>

#include "calib/fit/fit.h"
#include "model/effect.h"
#include "model/evaluator.h"
#include "model/model.h"
#include "io/calibration_json.h"
#include "io/device_json.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

// Counts heap allocations, for the driver-path test below.
static size_t g_allocations = 0;
void *operator new(size_t n) {
    ++g_allocations;
    if (void *p = std::malloc(n ? n : 1)) return p;
    throw std::bad_alloc();
}
// Every form a library may call (std::stable_sort's buffer uses the nothrow
// one): all on malloc/free, so no pair mixes allocators (AddressSanitizer
// checks that).
void *operator new(size_t n, const std::nothrow_t &) noexcept {
    ++g_allocations;
    return std::malloc(n ? n : 1);
}
void *operator new[](size_t n) { return operator new(n); }
void *operator new[](size_t n, const std::nothrow_t &t) noexcept { return operator new(n, t); }
void operator delete(void *p) noexcept { std::free(p); }
void operator delete(void *p, size_t) noexcept { std::free(p); }
void operator delete(void *p, const std::nothrow_t &) noexcept { std::free(p); }
void operator delete[](void *p) noexcept { std::free(p); }
void operator delete[](void *p, size_t) noexcept { std::free(p); }
void operator delete[](void *p, const std::nothrow_t &) noexcept { std::free(p); }

// The seed's triangulation inverts the ideal geometry exactly: over the
// whole workspace (y, z in +-60 mm, x 20..80 mm) the error is rounding
// only; 1e-9 mm is ~1e4 ulp of a 200 mm length.
static void triangulation_is_exact(void **) {
    DeviceGeometry g;
    double worst = 0;
    for (double x = 20; x <= 80; x += 2.5)
        for (double y = -60; y <= 60; y += 2.5)
            for (double z = -60; z <= 60; z += 2.5) {
                double p[3] = {x, y, z}, L[4], q[3];
                nominal_lengths(g, p, L);
                assert_true(triangulate(g, L, q));
                for (int k = 0; k < 3; ++k) worst = std::fmax(worst, std::fabs(q[k] - p[k]));
            }
    assert_true(worst < 1e-9);
}

// Another frame size, asymmetric a != b.
static void triangulation_other_geometry(void **) {
    DeviceGeometry g;
    g.a_mm = 210;
    g.b_mm = 120;
    g.m_mm = 24;
    double p[3] = {47.5, -33.2, 51.0}, L[4], q[3];
    nominal_lengths(g, p, L);
    assert_true(triangulate(g, L, q));
    for (int k = 0; k < 3; ++k) assert_true(std::fabs(q[k] - p[k]) < 1e-9);
}

// Lengths whose spheres do not meet (one cable far too short) give no
// position rather than a NaN; non-finite input likewise.
static void triangulation_rejects_impossible(void **) {
    DeviceGeometry g;
    double L[4] = {10, 300, 300, 300}, q[3] = {7, 7, 7};
    assert_false(triangulate(g, L, q));
    assert_true(q[0] == 7 && q[1] == 7 && q[2] == 7);
    double N[4] = {NAN, 200, 200, 200};
    assert_false(triangulate(g, N, q));
    Model m(g);
    assert_int_equal(m.position(L, q), -1);
}

// Forward kinematics with every effect on inverts the model's own readings
// (Gauss-Newton to 1e-9 mm steps; 1e-6 mm leaves room for the conditioning
// of x, ~4x worse than y and z).
static void forward_kinematics_inverts_each_effect(void **) {
    for (auto &e : all_effects()) {
        if (e->stage == Stage::User || e->stage == Stage::Position || e->stage == Stage::Jig) continue;
        for (uint64_t seed = 1; seed <= 3; ++seed) {
            Model m{DeviceGeometry{}};
            std::string err;
            assert_true(m.add_effect_random(e->name, seed, err));
            for (double x : {30.0, 55.0, 70.0})
                for (double y : {-60.0, 0.0, 45.0})
                    for (double z : {-60.0, 20.0, 60.0}) {
                        double p[3] = {x, y, z}, L[4], q[3];
                        m.readings(p, L);
                        assert_int_equal(m.position(L, q), 0);
                        for (int k = 0; k < 3; ++k) assert_true(std::fabs(q[k] - p[k]) < 1e-6);
                    }
        }
    }
}

// Every reading-stage built-in, switched on inside the model that holds all
// the others at random realistic values, changes the readings: an effect
// whose place in the list let another overwrite its work (a Path-stage hook
// that replaces the length after one that added to it) would leave them
// as they were. The threshold, 1e-6 mm, is a thousand times the round-off
// of a 300 mm reading and a thousandth of what each effect's smallest
// random magnitude moves a reading by somewhere on these positions.
static void every_effect_acts_inside_the_full_model(void **) {
    std::vector<std::string> names;
    for (auto &e : all_effects())
        if (e->builtin_id >= 0 && e->stage != Stage::Position && e->stage != Stage::Jig) names.push_back(e->name);
    for (size_t k = 0; k < names.size(); ++k) {
        Model with{DeviceGeometry{}}, without{DeviceGeometry{}};
        std::string err;
        for (size_t q = 0; q < names.size(); ++q) {
            assert_true(with.add_effect_random(names[q], 10 + q, err));
            if (q != k) assert_true(without.add_effect_random(names[q], 10 + q, err));
        }
        double most = 0;
        for (double x : {30.0, 70.0})
            for (double y : {-60.0, 0.0, 45.0})
                for (double z : {-60.0, 20.0, 60.0}) {
                    const double p[3] = {x, y, z};
                    double a[4], b[4];
                    assert_int_equal(with.readings(p, 1800.0, a), 0);
                    assert_int_equal(without.readings(p, 1800.0, b), 0);
                    for (int c = 0; c < 4; ++c) most = std::max(most, std::fabs(a[c] - b[c]));
                }
        if (!(most > 1e-6)) fail_msg("%s changes no reading inside the full model (%g mm)", names[k].c_str(), most);
    }
}

// The pulley's wrap: at r = 0 the path is the straight line, and the length
// grows with r by (beta - sin beta) per mm at first (d/dr at r = 0).
static void pulley_limits(void **) {
    Model straight{DeviceGeometry{}}, pulley{DeviceGeometry{}};
    std::string err;
    assert_true(pulley.add_effect("exit_pulley", ParamValues{{"radius_mm", 0.0}}, err));
    double p[3] = {50, 10, -20}, a[4], b[4];
    straight.readings(p, a);
    pulley.readings(p, b);
    for (int i = 0; i < 4; ++i) assert_true(std::fabs(a[i] - b[i]) < 1e-12);
    Model small{DeviceGeometry{}};
    assert_true(small.add_effect("exit_pulley", ParamValues{{"radius_mm", 1e-4}}, err));
    double c[4];
    small.readings(p, c);
    DeviceGeometry g;
    for (int i = 0; i < 4; ++i) {
        auto A = g.anchor(i);
        auto h = g.holder(i);
        double d[3] = {p[0] + h[0] - A[0], p[1] + h[1] - A[1], p[2] + h[2] - A[2]};
        double beta = std::atan2(std::hypot(d[1], d[2]), d[0]);
        double slope = (c[i] - a[i]) / 1e-4;
        assert_true(std::fabs(slope - (beta - std::sin(beta))) < 1e-3);
    }
}

static void json_round_trip_and_errors(void **) {
    Model m{DeviceGeometry{}};
    std::string err;
    assert_true(m.add_effect_random("cable_offset", 4, err));
    assert_true(m.add_effect_random("exit_pulley", 5, err));
    Model back{DeviceGeometry{}};
    assert_true(cdm::io::parse_calibration_json(cdm::io::model_to_json(m).dump(), "t", back, err));
    double p[3] = {40, 5, 5}, a[4], b[4];
    m.readings(p, a);
    back.readings(p, b);
    for (int i = 0; i < 4; ++i) assert_true(a[i] == b[i]);
    assert_false(m.add_effect("no_such_effect", {}, err));
    assert_non_null(strstr(err.c_str(), "no_such_effect"));
    assert_false(m.add_effect("cable_gain", ParamValues{{"zzz", 1.0}}, err));
    assert_non_null(strstr(err.c_str(), "zzz"));
    DeviceGeometry g;
    assert_false(cdm::io::parse_device_json("{\"a_mm\": 150,\n \"b_mm\": ,}", "dev.json", g, err));
    assert_non_null(strstr(err.c_str(), "dev.json:2:"));
    assert_false(cdm::io::parse_device_json("{\"a_mm\": 150, \"b_mm\": 150}", "dev.json", g, err));
    assert_non_null(strstr(err.c_str(), "m_mm"));
}

// A user effect whose apply fails (here: beyond a reach it models) must
// fail what uses it, never hand out a number computed without it.
static int fails_beyond_x80(void *, const double *, const double p[3], double r[4]) {
    if (p[0] > 80) return 7;
    for (int i = 0; i < 4; ++i) r[i] += 0.01;
    return 0;
}

static void apply_failure_is_reported(void **) {
    const char *names[] = {"o"};
    const double scale[] = {0.1};
    cdm_effect_def def{};
    def.struct_size = sizeof def;
    def.n_params = 1;
    def.name = "test_fails_far";
    def.param_names = names;
    def.param_scale = scale;
    def.apply = fails_beyond_x80;
    std::string err;
    assert_int_equal(register_user_effect(&def, err), CDM_OK);
    Model m{DeviceGeometry{}};
    assert_true(m.add_effect("test_fails_far", {}, err));
    double near[3] = {50, 0, 0}, far[3] = {100, 0, 0}, L[4], q[3];
    assert_int_equal(m.readings(near, L), 0);
    assert_int_equal(m.position(L, q), 0);
    assert_int_equal(m.readings(far, L), -1);
    Model nominal{DeviceGeometry{}};
    nominal.readings(far, L);
    assert_int_equal(m.position(L, q), -1); // Gauss-Newton starts near x = 100
    // The fit: one position beyond the reach.
    std::vector<PreparedPos> pos(2);
    for (int j = 0; j < 2; ++j) {
        pos[size_t(j)].ref = Eigen::Vector3d(j ? 100 : 50, 0, 0);
        double y[4];
        nominal.readings(pos[size_t(j)].ref.data(), y);
        for (int c = 0; c < 4; ++c) pos[size_t(j)].mean(c) = y[c];
        pos[size_t(j)].var_mean.setConstant(1e-4);
        pos[size_t(j)].n = 1;
    }
    FitReport rep;
    assert_false(fit_model(m, pos, FitOptions{}, rep));
    assert_non_null(strstr(rep.message.c_str(), "test_fails_far"));
    assert_true(std::isinf(model_chi2(m, pos, FitOptions{})));
    assert_int_equal(unregister_user_effect("test_fails_far", err), CDM_OK);
}

// Noise-free position means of `truth` at 5 x 13 x 13 jig positions, each
// with the variance of a 100-sample mean of 0.1 mm noise (0.01 mm).
static std::vector<PreparedPos> noise_free_jig(const Model &truth) {
    std::vector<PreparedPos> pos;
    for (double x = 30; x <= 70; x += 10)
        for (double y = -60; y <= 60; y += 10)
            for (double z = -60; z <= 60; z += 10) {
                PreparedPos pp;
                pp.ref = Eigen::Vector3d(x, y, z);
                double r[4];
                assert_int_equal(truth.readings(pp.ref.data(), r), 0);
                for (int c = 0; c < 4; ++c) pp.mean(c) = r[c];
                pp.var_mean.setConstant(1e-4);
                pp.n = 100;
                pos.push_back(pp);
            }
    return pos;
}

// The fixture heights' offsets (FitOptions::fixture), one free parameter
// per height, each bounded by kFixtureMaxMm. model_chi2 profiles them for
// the model as it stands; that must be the chi-square a fit of the offsets
// alone (the model has no parameter) reaches, not below it. On the nominal
// model with a 6 mm exit pulley in the data every height's best offset is
// past the bound. When the offsets summed to zero, clamping the free
// solution added a common offset no fit could have: model_chi2 came out
// about a tenth below the fit (candidates then read delta chi2 -629485);
// clamping coordinate by coordinate is not the box's optimum either.
// Agreement to 1e-6 relative: both minimise the same convex problem in 5
// unknowns, the fit to SLSQP's 1e-12 tolerance and the profile by three
// bounded Gauss-Newton steps on readings that are near-linear in an x
// offset of a tenth of a millimetre.
static void fixture_profile_on_its_gauge(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("exit_pulley", ParamValues{{"radius_mm", 6.0}}, err));
    const std::vector<PreparedPos> pos = noise_free_jig(truth);
    FitOptions fo;
    fo.fixture_count = 5;
    for (auto &pp : pos) fo.fixture.push_back(int(std::lround((pp.ref(0) - 30) / 10)));
    Model m{DeviceGeometry{}};
    const double profiled = model_chi2(m, pos, fo);
    FitReport rep;
    assert_true(fit_model(m, pos, fo, rep));
    assert_int_equal(rep.n_fixture, 5);
    double worst = 0;
    for (double v : rep.fixture_mm) worst = std::max(worst, std::fabs(v));
    if (!(worst > kFixtureMaxMm - 1e-6)) fail_msg("premise: no offset at the bound (largest %g mm)", worst);
    if (std::fabs(profiled - rep.chi2) > 1e-6 * rep.chi2)
        fail_msg("model_chi2 %.9g, the offsets' fit %.9g", profiled, rep.chi2);
}

// FitOptions::hold keeps a parameter where it is and fits the rest: the
// diagnosis profiles a ripple's period this way. Noise-free readings of a
// ripple (period 94.2 mm) at 5 x 13 x 13 positions: held at 90 mm the
// period stays bit for bit and has no standard error, the amplitudes
// still move (the chi-square falls); held at the truth the amplitudes are
// recovered to round-off (the fit is linear in them); a joint fit from the
// held result finds the period.
static void held_parameter_stays(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("drum_eccentricity",
                                 ParamValues{{"period", 94.2}, {"a1", 0.15}, {"b2", 0.1}, {"a3", -0.12}, {"b4", -0.08}},
                                 err));
    const std::vector<PreparedPos> pos = noise_free_jig(truth);
    FitOptions fo;
    fo.jig_sigma.setZero();
    fo.hold = {{0, 0}};
    for (double held : {90.0, 94.2}) {
        Model m{DeviceGeometry{}};
        assert_true(m.add_effect("drum_eccentricity", ParamValues{{"period", held}}, err));
        const double chi0 = model_chi2(m, pos, fo);
        FitReport rep;
        assert_true(fit_model(m, pos, fo, rep));
        assert_true(m.effect_params(0)[0] == held);
        assert_true(rep.std[0][0] == 0.0);
        assert_int_equal(rep.n_free, 8);
        if (!(rep.chi2 < 0.5 * chi0)) fail_msg("held at %g: chi2 %g from %g", held, rep.chi2, chi0);
        if (held == 94.2) {
            // Round-off and the weak prior (10x the typical amplitude) only.
            if (rep.chi2 > 1e-6) fail_msg("held at the truth: chi2 %g", rep.chi2);
            if (std::fabs(m.effect_params(0)[1] - 0.15) > 1e-6) fail_msg("a1 %g", m.effect_params(0)[1]);
        } else {
            FitOptions joint = fo;
            joint.hold.clear();
            assert_true(fit_model(m, pos, joint, rep));
            if (std::fabs(m.effect_params(0)[0] - 94.2) > 1e-4) fail_msg("joint period %g", m.effect_params(0)[0]);
        }
    }
}

// hold with a gauge that is not the identity: with jig_misalignment in the
// model, anchor_position moves only in the 6 directions a rigid motion of
// the four anchors does not (effect_gauge_basis). Holding a1_x there must
// keep it bit for bit at its start, take exactly one direction away (12
// free parameters become 11), and leave every move of the anchors within
// the gauge's span (no rigid part creeps back in through the elimination);
// the projection residual is round-off (the basis is orthonormal: 1e-12 of
// the move's size).
static void held_parameter_in_a_gauge(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("anchor_position", 3, err));
    const std::vector<PreparedPos> pos = noise_free_jig(truth);
    FitOptions fo;
    fo.jig_sigma.setZero();
    auto start = [&] {
        Model m{DeviceGeometry{}};
        assert_true(m.add_effect("jig_misalignment", {}, err));
        assert_true(m.add_effect("anchor_position", ParamValues{{"a1_x", 0.25}}, err));
        return m;
    };
    Model free_m = start();
    FitReport rfree;
    assert_true(fit_model(free_m, pos, fo, rfree));
    assert_int_equal(rfree.n_free, 12);

    Model m = start();
    const std::vector<double> a0 = m.effect_params(1);
    const double chi0 = model_chi2(m, pos, fo);
    FitOptions held = fo;
    held.hold = {{1, 0}};
    FitReport rep;
    assert_true(fit_model(m, pos, held, rep));
    assert_int_equal(rep.n_free, 11);
    assert_true(m.effect_params(1)[0] == 0.25);
    assert_true(rep.std[1][0] == 0.0);
    if (!(rep.chi2 < 0.5 * chi0)) fail_msg("chi2 %g from %g", rep.chi2, chi0);
    const Eigen::MatrixXd B = effect_gauge_basis(m, 1);
    assert_int_equal(int(B.cols()), 6);
    Eigen::VectorXd move(12);
    for (int k = 0; k < 12; ++k) move(k) = m.effect_params(1)[size_t(k)] - a0[size_t(k)];
    const double off_span = (move - B * (B.transpose() * move)).norm();
    if (!(move.norm() > 1e-3)) fail_msg("the anchors did not move (%g mm)", move.norm());
    if (!(off_span <= 1e-12 * std::max(1.0, move.norm())))
        fail_msg("the anchors' move leaves the gauge by %g mm of %g", off_span, move.norm());
}

// FitOptions::weigh_with: each reading's weight holds the jig tolerance
// mapped through a model's sensitivity to the position, and the model named
// there is the one whose sensitivity is used (the search compares every fit
// of a step on the weights of the model the step stands on). A ripple's
// amplitudes change that sensitivity by up to 2 pi A / T (3 % here) with a
// sign that follows the ripple's phase, so weighed as the truth (0.5 mm
// ripple) or as the model at its start (no ripple) the same residual gives
// chi-squares apart by 1e-4 to 1e-3 relative (the signs partly cancel: 8e-4
// seen at the start, 9e-5 after the fit);
// a difference above 1e-5 is the option at work, round-off (a sum of 3,380
// terms, ~1e-13) is eight orders below. Weighed as itself a model gives, bit
// for bit, what it gives without weigh_with (the same arithmetic). The
// fit's reported chi-square is on the named model's weights: it equals
// model_chi2 with the same option to round-off (1e-9) and differs from the
// one on its own weights.
static void weights_from_the_named_model(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("drum_eccentricity",
                                 ParamValues{{"period", 94.2}, {"a1", 0.5}, {"b2", 0.4}, {"a3", -0.45}, {"b4", -0.3}},
                                 err));
    const std::vector<PreparedPos> pos = noise_free_jig(truth);
    FitOptions own; // the jig tolerance at its default, 0.03 mm per axis
    Model start{DeviceGeometry{}};
    assert_true(start.add_effect("drum_eccentricity", ParamValues{{"period", 92.0}}, err));
    FitOptions as_self = own, as_truth = own;
    as_self.weigh_with = &start;
    as_truth.weigh_with = &truth;
    const double c_own = model_chi2(start, pos, own);
    assert_true(model_chi2(start, pos, as_self) == c_own);
    const double c_truth = model_chi2(start, pos, as_truth);
    if (!(std::fabs(c_truth - c_own) > 1e-5 * c_own)) fail_msg("weighed as the truth %.12g, as itself %.12g", c_truth, c_own);
    // A fit weighed as its own start is the fit without the option.
    Model m1 = start, m2 = start;
    FitReport r1, r2;
    assert_true(fit_model(m1, pos, own, r1));
    assert_true(fit_model(m2, pos, as_self, r2));
    assert_true(r1.chi2 == r2.chi2);
    for (size_t k = 0; k < m1.effect_params(0).size(); ++k) assert_true(m1.effect_params(0)[k] == m2.effect_params(0)[k]);
    // Weighed as another model: its chi-square is on that model's weights.
    FitOptions held = as_truth;
    held.hold = {{0, 0}}; // the period held off the truth: a residual is left
    Model m3 = start;
    FitReport r3;
    assert_true(fit_model(m3, pos, held, r3));
    const double named = model_chi2(m3, pos, as_truth), mine = model_chi2(m3, pos, own);
    if (!(std::fabs(r3.chi2 - named) <= 1e-9 * named)) fail_msg("fit %.15g, weighed as the truth %.15g", r3.chi2, named);
    if (!(std::fabs(mine - named) > 1e-5 * named)) fail_msg("own weights %.12g, the truth's %.12g", mine, named);
}

// The accessors the JSON codec and the diagnosis use.
// A fit ends where a fresh fit from its result finds nothing more: the
// pass's stall stop (three evaluations within 1e-4 of the best chi-square/2)
// must not end a fit on a slope. Means of 13 x 13 x 5 positions with
// Gaussian noise of 0.01 mm on each reading (the weights say so: chi2/dof
// near 1) hide anchor errors, an exit pulley, a stretch and a gain, fitted
// from the nominal start (18 free parameters). The refit may gain at most 0.01
// in chi-square: the diagnosis prints its chi-square changes and BIC to
// tenths, so 0.01 cannot move a printed figure by more than a unit of its
// last digit. A stop on a slope is far above that: with the stall
// threshold 1e7 times looser (1e3) this fit ended 1,169 above its minimum.
static void fit_ends_at_its_minimum(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    for (const char *e : {"anchor_position", "exit_pulley", "cable_stretch", "cable_gain"})
        assert_true(truth.add_effect_random(e, 5, err));
    std::vector<PreparedPos> pos = noise_free_jig(truth);
    std::mt19937_64 rng(11);
    std::normal_distribution<double> noise(0.0, 0.01);
    for (auto &pp : pos) {
        for (int c = 0; c < 4; ++c) pp.mean(c) += noise(rng);
        pp.var_mean.setConstant(0.01 * 0.01);
    }
    FitOptions fo;
    fo.jig_sigma.setZero();
    Model m{DeviceGeometry{}};
    for (const char *e : {"anchor_position", "exit_pulley", "cable_stretch", "cable_gain"})
        assert_true(m.add_effect(e, {}, err));
    FitReport rep;
    assert_true(fit_model(m, pos, fo, rep));
    if (!rep.converged) fail_msg("not converged: %s", rep.message.c_str());
    const double dof = double(rep.n_obs - rep.n_free);
    if (!(rep.chi2 < 2 * dof)) fail_msg("chi2 %g for %g dof: the fit did not find the truth's basin", rep.chi2, dof);
    Model again = m;
    FitReport rep2;
    assert_true(fit_model(again, pos, fo, rep2));
    if (!(rep.chi2 - rep2.chi2 <= 0.01))
        fail_msg("a refit from the result lowered chi2 from %.6f to %.6f", rep.chi2, rep2.chi2);
}

// A parameter whose best value lies past its bound ends on the bound, with
// the others at their best for it there: the fit's Gauss-Newton steps solve
// the linearised problem within the bounds (calib/fit/optimiser.cpp, bounded_gauss_newton),
// and must neither stop short of the bound nor leave a parameter off its
// best. The data hold pot 1's zero 23 mm off, past cable_offset's 20 mm
// bound, beside gain errors that share the readings' direction. The fit
// must end converged with o1 on 20 mm (to 1e-6 mm: SLSQP's constraint
// tolerance is 1e-9, and the end point is clamped), at the chi-square of the
// same fit with o1 held at 20 mm, and a refit from its result may gain no
// more than fit_ends_at_its_minimum allows (0.01: the diagnosis prints
// tenths).
static void fit_on_a_bound_is_the_constrained_minimum(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect("cable_gain", {{"g1", 0.004}, {"g2", -0.003}, {"g4", 0.002}}, err));
    std::vector<PreparedPos> pos = noise_free_jig(truth);
    for (auto &pp : pos) pp.mean(0) += 23.0;
    FitOptions fo;
    fo.jig_sigma.setZero();
    auto start = [&](double o1) {
        Model m{DeviceGeometry{}};
        assert_true(m.add_effect("cable_offset", {{"o1", o1}}, err));
        assert_true(m.add_effect("cable_gain", {}, err));
        return m;
    };
    Model m = start(0.0);
    size_t off = 0;
    while (m.effect_desc(off).name != "cable_offset") ++off;
    assert_true(m.effect_desc(off).params[0].upper == 20.0);
    FitReport rep;
    assert_true(fit_model(m, pos, fo, rep));
    if (!rep.converged) fail_msg("not converged: %s", rep.message.c_str());
    const double o1 = m.effect_params(off)[0];
    if (!(std::fabs(o1 - 20.0) <= 1e-6)) fail_msg("o1 ended at %.9f mm, not on its 20 mm bound", o1);
    Model held_m = start(20.0);
    FitOptions held = fo;
    held.hold = {{off, 0}};
    FitReport rh;
    assert_true(fit_model(held_m, pos, held, rh));
    if (!(std::fabs(rep.chi2 - rh.chi2) <= 0.01))
        fail_msg("chi2 %.6f with o1 on its bound, %.6f with it held there", rep.chi2, rh.chi2);
    Model again = m;
    FitReport r2;
    assert_true(fit_model(again, pos, fo, r2));
    if (!(rep.chi2 - r2.chi2 <= 0.01)) fail_msg("a refit from the result lowered chi2 from %.6f to %.6f", rep.chi2, r2.chi2);
}

// FitOptions::abandon_above: a fit stops once its best point lies past the
// value, ends on that point (so a reader sees the period past it) and says
// so, having spent fewer evaluations than the whole fit; set above anything
// the fit reaches, it changes nothing, bit for bit. The case is the
// diagnosis's: a ripple fitted to a smooth error (a pot gain) whose period
// runs off to a trend.
static void abandoned_fit_stops_at_its_bound(void **) {
    Model truth{DeviceGeometry{}};
    std::string err;
    assert_true(truth.add_effect_random("cable_gain", 5, err));
    const std::vector<PreparedPos> pos = noise_free_jig(truth);
    FitOptions fo;
    fo.jig_sigma.setZero();
    Model start{DeviceGeometry{}};
    assert_true(start.add_effect("drum_eccentricity", {{"period", 100.0}}, err));
    const size_t e = 0, q = 0; // drum_eccentricity's first parameter is its period
    assert_string_equal(start.effect_desc(e).params[q].name.c_str(), "period");
    Model free = start;
    FitReport r0;
    assert_true(fit_model(free, pos, fo, r0));
    const double went = free.effect_params(e)[q];
    if (!(went > 200)) fail_msg("premise: the unbounded period went to %g mm, not past 200", went);
    assert_false(r0.abandoned);
    // Past 150 mm: given up there.
    Model cut = start;
    FitOptions fa = fo;
    fa.abandon_above = {{{e, q}, 150.0}};
    FitReport r1;
    assert_true(fit_model(cut, pos, fa, r1));
    assert_true(r1.abandoned);
    assert_false(r1.converged);
    const double kept = cut.effect_params(e)[q];
    if (!(kept > 150.0)) fail_msg("ended on period %g mm, not past the 150 mm value", kept);
    if (!(r1.evals < r0.evals)) fail_msg("abandoned after %d evaluations, the whole fit took %d", r1.evals, r0.evals);
    // Never reached: the same fit bit for bit.
    Model same = start;
    FitOptions fn = fo;
    fn.abandon_above = {{{e, q}, 1e9}};
    FitReport r2;
    assert_true(fit_model(same, pos, fn, r2));
    assert_false(r2.abandoned);
    assert_int_equal(r2.evals, r0.evals);
    assert_true(std::memcmp(&r2.chi2, &r0.chi2, sizeof(double)) == 0);
    for (size_t k = 0; k < same.effect_params(e).size(); ++k)
        assert_true(std::memcmp(&same.effect_params(e)[k], &free.effect_params(e)[k], sizeof(double)) == 0);
}

static void effect_accessors(void **) {
    Model m{DeviceGeometry{}};
    std::string err;
    assert_true(m.add_effect("cable_gain", {{"g2", 0.01}}, err));
    assert_true(m.add_effect("jig_misalignment", {}, err));
    // Order of application: the jig first.
    assert_string_equal(m.effect_desc(0).name.c_str(), "jig_misalignment");
    assert_true(m.effect_params(1)[1] == 0.01);
    assert_false(m.set_effect_params(1, {0, 0, 0}, err));
    assert_non_null(strstr(err.c_str(), "4 parameters"));
    assert_false(m.set_effect_params(1, {0, 0.5, 0, 0}, err)); // bound 0.2
    assert_non_null(strstr(err.c_str(), "g2"));
    assert_false(m.set_effect_params(1, {0, NAN, 0, 0}, err));
    assert_true(m.set_effect_params(1, {0.001, 0.002, 0.003, 0.004}, err));
    assert_true(m.effect_params(1)[3] == 0.004);
    assert_false(m.add_effect("cable_gain", {{"g1", INFINITY}}, err));
}

// A generated table of a page: the text between `begin` and `end` must be
// `want`. With CDM_UPDATE_DOCS=1 in the environment the page is rewritten
// instead (an exclusive temporary beside it, then a rename), so a new
// effect's rows are generated, never pasted.
static void generated_table(const char *page, const std::string &begin, const std::string &end,
                            const std::string &want) {
    const std::string path = std::string(CDM_SOURCE_DIR "/") + page;
    std::ifstream f(path);
    assert_true(f.good());
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string doc = ss.str();
    const size_t a = doc.find(begin), b = doc.find(end);
    if (a == std::string::npos || b == std::string::npos || b < a) fail_msg("%s: no %s ... %s markers", page, begin.c_str(), end.c_str());
    if (doc.substr(a + begin.size(), b - a - begin.size()) == want) return;
    const char *update = std::getenv("CDM_UPDATE_DOCS");
    if (update && std::string(update) == "1") {
        const std::string out = doc.substr(0, a + begin.size()) + want + doc.substr(b);
        std::string tmp = path + ".XXXXXX";
        const int fd = mkstemp(&tmp[0]);
        assert_true(fd >= 0);
        const bool ok = write(fd, out.data(), out.size()) == ssize_t(out.size()) && fsync(fd) == 0;
        close(fd);
        if (!ok || rename(tmp.c_str(), path.c_str()) != 0) {
            unlink(tmp.c_str());
            fail_msg("%s: could not rewrite it", page);
        }
        std::printf("%s: rewrote the table between %s and %s\n", page, begin.c_str(), end.c_str());
        return;
    }
    std::printf("%s: the table between\n%s and %s\nmust read (CDM_UPDATE_DOCS=1 rewrites it):\n%s", page,
                begin.c_str(), end.c_str(), want.c_str());
    fail();
}

// The pages' tables are the registry's (the list in effects/list.h).
static void catalogue_table_matches_docs(void **) {
    generated_table("docs/calibration.md", "<!-- catalogue:begin (generated: tests/unit/model/test_model.cpp) -->\n",
                    "<!-- catalogue:end -->", catalogue_markdown());
    generated_table("docs/effects.md", "<!-- stages:begin (generated: tests/unit/model/test_model.cpp) -->\n",
                    "<!-- stages:end -->", stages_markdown());
}

// The driver's path (cdm_get_pose -> Model::position) does not allocate,
// with every built-in on, the seed's ellipsoid included; neither do the
// readings (the simulator's path) nor the jig map.
static void driver_path_does_not_allocate(void **) {
    Model m{DeviceGeometry{}};
    std::string err;
    for (const auto &d : all_effects())
        if (d->builtin_id >= 0 && d->stage != Stage::Position) assert_true(m.add_effect_random(d->name, 9, err));
    assert_true(m.add_effect("ellipsoid", {{"L", 5989.1}, {"M", 2950.2}, {"N", 3092.8}}, err));
    double p[3] = {55, 12, -30}, L[4], q[3], J[12], r[3];
    const size_t before = g_allocations;
    assert_int_equal(m.readings(p, L), 0);
    assert_int_equal(m.position(L, q), 0);
    assert_int_equal(m.position(L, 0.0, q, J), 0);
    m.jig_to_device(p, r);
    assert_int_equal(g_allocations - before, 0);
    // The counter sees allocations (a copy of the model allocates).
    Model copy = m;
    assert_true(g_allocations > before);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(triangulation_is_exact),
        cmocka_unit_test(triangulation_other_geometry),
        cmocka_unit_test(triangulation_rejects_impossible),
        cmocka_unit_test(forward_kinematics_inverts_each_effect),
        cmocka_unit_test(every_effect_acts_inside_the_full_model),
        cmocka_unit_test(pulley_limits),
        cmocka_unit_test(json_round_trip_and_errors),
        cmocka_unit_test(apply_failure_is_reported),
        cmocka_unit_test(fixture_profile_on_its_gauge),
        cmocka_unit_test(held_parameter_stays),
        cmocka_unit_test(held_parameter_in_a_gauge),
        cmocka_unit_test(weights_from_the_named_model),
        cmocka_unit_test(fit_ends_at_its_minimum),
        cmocka_unit_test(fit_on_a_bound_is_the_constrained_minimum),
        cmocka_unit_test(abandoned_fit_stops_at_its_bound),
        cmocka_unit_test(effect_accessors),
        cmocka_unit_test(catalogue_table_matches_docs),
        cmocka_unit_test(driver_path_does_not_allocate),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
