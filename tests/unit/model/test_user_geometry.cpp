// Geometry-aware user effects (cdm_effect_def.apply_geom, since 1.2): what
// the callback is given, the evaluator's Jacobian for an effect on the
// cable's path against central differences of the values (as
// test_gradients.cpp does for the built-ins), the batch against one position
// at a time, and the forward kinematics through such an effect.
//
// Tolerance of the Jacobian checks: test_gradients.cpp's (truncation from a
// third difference + rounding of the two evaluations), plus, where the
// evaluator's derivative is itself a central difference through a user
// effect, that difference's own truncation and rounding. The effects here
// are at most cubic in the chord and smooth in the position, so at the
// evaluator's steps (1e-5 mm on a value, 1e-4 mm on the position) the
// truncation is ~h^2 c L < 1e-15 of the derivative; the rounding of
// (f(+h) - f(-h)) / 2h on values below 400 mm is at most 32 eps x 400 / h
// (2.8e-7 per step of 1e-5 mm, 2.8e-8 per step of 1e-4 mm), once per user
// effect. The documented omission (the frames are not stepped with the
// Geometry-stage parameters) is bounded separately, in
// path_effect_jacobian_matches_central_differences.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <random>
#include <setjmp.h>
#include <string>
#include <vector>

#include "model/effect.h"
#include "model/evaluator.h"
#include "model/model.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

namespace {

constexpr double kEps = 2.220446049250313e-16;
constexpr double kRound = 32 * kEps;
constexpr double kGravity[3] = {0, 0, -1};

// The cable-sag example's physics (examples/c/cable_sag.c): c L^3 (1 - (u.g)^2).
int sag(void *, const double *p, size_t n, const cdm_effect_context *c, double *v) {
    for (size_t i = 0; i < n; ++i)
        for (size_t k = 0; k < 4; ++k) {
            const double *u = c->unit + 3 * (4 * i + k);
            const double L = c->chord_mm[4 * i + k];
            const double ug = u[0] * kGravity[0] + u[1] * kGravity[1] + u[2] * kGravity[2];
            v[4 * i + k] += p[0] * L * L * L * (1 - ug * ug);
        }
    return 0;
}

// A reading-stage effect that reads the holder points and the position: a
// pickup whose reading shifts with the holder point's height above the
// position, and with the time.
int pickup(void *, const double *p, size_t n, const cdm_effect_context *c, double *v) {
    for (size_t i = 0; i < n; ++i)
        for (size_t k = 0; k < 4; ++k) {
            const double dz = c->holders_mm[3 * (4 * i + k) + 2] - c->positions_mm[3 * i + 2];
            v[4 * i + k] += p[0] * dz + p[1] * std::sin(0.01 * c->anchors_mm[3 * (4 * i + k) + 1] + c->t_s[i]);
        }
    return 0;
}

void register_effects() {
    static const char *const sn[] = {"c"}, *const su[] = {"1/mm^2"};
    static const double ss[] = {1e-8}, sl[] = {0}, sh[] = {1e-6}, si[] = {3e-8};
    cdm_effect_def d{};
    d.struct_size = sizeof d;
    d.n_params = 1;
    d.name = "test_sag";
    d.param_names = sn;
    d.param_units = su;
    d.param_scale = ss;
    d.lower = sl;
    d.upper = sh;
    d.initial = si;
    d.apply_geom = sag;
    d.stage = CDM_EFFECT_STAGE_PATH;
    std::string err;
    assert_int_equal(register_user_effect(&d, err), CDM_OK);
    static const char *const pn[] = {"k", "amp"};
    static const double ps[] = {0.01, 0.05}, pi[] = {0.02, 0.04};
    cdm_effect_def r{};
    r.struct_size = sizeof r;
    r.n_params = 2;
    r.name = "test_pickup";
    r.param_names = pn;
    r.param_scale = ps;
    r.initial = pi;
    r.apply_geom = pickup;
    assert_int_equal(register_user_effect(&r, err), CDM_OK);
}

// The built-ins around the path, a Geometry-stage effect that moves the
// anchors and the holder points, and both user effects.
Model geom_model() {
    Model m{DeviceGeometry{}};
    std::string err;
    for (const char *e : {"jig_misalignment", "anchor_position", "holder_geometry", "exit_pulley", "cable_stretch",
                          "cable_gain", "cable_offset", "pot_drift"})
        assert_true(m.add_effect_random(e, 5 + uint64_t(e[0]), err));
    assert_true(m.add_effect("test_sag", {}, err));
    assert_true(m.add_effect("test_pickup", {}, err));
    return m;
}

std::mt19937_64 &rng() {
    static std::mt19937_64 r(20261128);
    return r;
}
void random_position(double p[3]) {
    std::uniform_real_distribution<double> ux(30, 90), uyz(-60, 60);
    p[0] = ux(rng());
    p[1] = uyz(rng());
    p[2] = uyz(rng());
}

// |a - b| within tol, else print and count.
int near(const std::string &what, double a, double b, double tol) {
    if (std::fabs(a - b) <= tol) return 0;
    std::printf("%s: evaluator %.12g, central difference %.12g, |diff| %.3g > %.3g\n", what.c_str(), a, b,
                std::fabs(a - b), tol);
    return 1;
}

// Central difference of the model's readings along t (f(t) -> 4 readings)
// with test_gradients.cpp's truncation and rounding bound.
int check4(const std::string &what, const std::function<bool(double, double *)> &f, double h, const double *ad,
           double extra, double rel = 0) {
    double p[4], m[4], a[4], b[4], c[4], d[4];
    const double H = 10 * h;
    if (!f(h, p) || !f(-h, m) || !f(2 * H, a) || !f(H, b) || !f(-H, c) || !f(-2 * H, d)) {
        std::printf("%s: evaluation failed\n", what.c_str());
        return 1;
    }
    int bad = 0;
    for (int i = 0; i < 4; ++i) {
        const double cd = (p[i] - m[i]) / (2 * h);
        const double f3 = std::fabs(a[i] - 2 * b[i] + 2 * c[i] - d[i]) / (2 * H * H * H);
        const double tol = h * h * f3 / 6 + kRound * std::fmax(std::fabs(p[i]), std::fabs(m[i])) / h +
                           (kRound + rel) * std::fabs(ad[i]) + extra;
        bad += near(what + " [" + std::to_string(i) + "]", ad[i], cd, tol);
    }
    return bad;
}

bool with_param(Model &m, size_t e, size_t k, double base, double t) {
    std::vector<double> v = m.effect_params(e);
    v[k] = base + t;
    std::string err;
    return m.set_effect_params(e, v, err);
}

// The largest chord of the model at a position: for the omission's bound.
double max_chord(const double P[3]) {
    double L = 0;
    for (int i = 0; i < 4; ++i) {
        const auto A = DeviceGeometry{}.anchor(i), h = DeviceGeometry{}.holder(i);
        double s = 0;
        for (int k = 0; k < 3; ++k) s += (P[k] + h[k] - A[k]) * (P[k] + h[k] - A[k]);
        L = std::fmax(L, std::sqrt(s));
    }
    return L + 5; // the geometry effects move it by a few mm at most
}

} // namespace

// What the callback is given: at n = 1 (Model::readings), the holder
// position, the time, the anchors and holder points after the Geometry
// stage (here anchor_position and holder_geometry at set values), their
// unit vectors and chords, and at the path stage the lengths (no Path-stage
// built-in: the chords themselves).
static cdm_effect_context g_seen;
static double g_values[4], g_anchor[12], g_holder[12], g_unit[12], g_chord[4], g_pos[3], g_t;
static int probe(void *, const double *, size_t n, const cdm_effect_context *c, double *v) {
    if (n != 1) return -1;
    g_seen = *c;
    for (int k = 0; k < 12; ++k) {
        g_anchor[k] = c->anchors_mm[k];
        g_holder[k] = c->holders_mm[k];
        g_unit[k] = c->unit[k];
    }
    for (int k = 0; k < 4; ++k) {
        g_chord[k] = c->chord_mm[k];
        g_values[k] = v[k];
    }
    for (int k = 0; k < 3; ++k) g_pos[k] = c->positions_mm[k];
    g_t = c->t_s[0];
    return 0;
}

static void context_is_the_models_geometry(void **) {
    cdm_effect_def d{};
    d.struct_size = sizeof d;
    d.name = "test_probe";
    d.apply_geom = probe;
    d.stage = CDM_EFFECT_STAGE_PATH;
    std::string err;
    assert_int_equal(register_user_effect(&d, err), CDM_OK);
    Model m{DeviceGeometry{}};
    ParamValues a, h;
    for (int i = 1; i <= 4; ++i)
        for (const char *x : {"_x", "_y", "_z"}) {
            a.emplace_back("a" + std::to_string(i) + x, 0.1 * i + (x[1] == 'y' ? 0.5 : 0));
            h.emplace_back("h" + std::to_string(i) + x, -0.05 * i + (x[1] == 'z' ? 0.3 : 0));
        }
    assert_true(m.add_effect("anchor_position", a, err));
    assert_true(m.add_effect("holder_geometry", h, err));
    assert_true(m.add_effect("test_probe", {}, err));
    const double P[3] = {55, 12, -20};
    double y[4];
    assert_int_equal(m.readings(P, 3.5, y), 0);
    assert_int_equal(g_seen.struct_size, sizeof(cdm_effect_context));
    assert_int_equal(g_seen.stage, CDM_EFFECT_STAGE_PATH);
    assert_int_equal(g_seen.n, 1);
    assert_true(g_t == 3.5);
    const DeviceGeometry g;
    for (int i = 0; i < 4; ++i) {
        double d2 = 0;
        for (int k = 0; k < 3; ++k) {
            const double A = g.anchor(i)[size_t(k)] + a[size_t(3 * i + k)].second;
            const double H = P[k] + g.holder(i)[size_t(k)] + h[size_t(3 * i + k)].second;
            assert_true(g_pos[k] == P[k]);
            // One rounding each way (a sum of two or three numbers < 200 mm).
            assert_true(std::fabs(g_anchor[3 * i + k] - A) < 1e-13);
            assert_true(std::fabs(g_holder[3 * i + k] - H) < 1e-13);
            d2 += (H - A) * (H - A);
        }
        const double L = std::sqrt(d2);
        assert_true(std::fabs(g_chord[i] - L) < 1e-12);
        for (int k = 0; k < 3; ++k) {
            const double u = (g_holder[3 * i + k] - g_anchor[3 * i + k]) / L;
            assert_true(std::fabs(g_unit[3 * i + k] - u) < 1e-12);
        }
        // No Path-stage built-in: the length is the chord; no Transfer-stage
        // one: the reading is the length.
        assert_true(g_values[i] == g_chord[i]);
        assert_true(y[i] == g_values[i]);
    }
    std::string e2;
    assert_int_equal(unregister_user_effect("test_probe", e2), CDM_OK);
}

// The evaluator (the fit's Jacobian) on a model with a path-stage and a
// reading-stage geometry-aware effect among the built-ins: its values are
// Model::readings' to the bit, and each column of d reading / d parameter
// and d reading / d position agrees with central differences of
// Model::readings. Columns of the Geometry-stage effects (anchor_position,
// holder_geometry) leave out the user effects' derivative through the
// frames (evaluator_user.cpp says why): there the difference must stay
// within that term's bound, for the sag 5 c L^2 per mm (3 c L^2 through
// the chord, 2 c L^2 through the direction, |d u / d a| <= 1/L), for the
// pickup |k| + 0.01 |amp| per mm; elsewhere it is exact but for rounding.
// The evaluator's own central differences through the two user effects
// round by at most 2 x 32 eps x 400 mm / h (h = 1e-5 mm on a length or
// reading: 5.7e-7 times the entry carried through them) and, for their own
// parameters, 32 eps x 400 mm / their step.
static void path_effect_jacobian_matches_central_differences(void **) {
    register_effects();
    Model m = geom_model();
    ReadingEvaluator ev(m);
    const Eigen::VectorXd full = ev.current();
    int bad = 0, cols = 0;
    size_t sag_e = 0, pick_e = 0;
    for (size_t e = 0; e < m.effect_count(); ++e) {
        if (m.effect_name(e) == "test_sag") sag_e = e;
        if (m.effect_name(e) == "test_pickup") pick_e = e;
    }
    const double c = m.effect_params(sag_e)[0], kp = m.effect_params(pick_e)[0], amp = m.effect_params(pick_e)[1];
    for (int j = 0; j < 4; ++j) {
        double ref[3], P[3], yr[4];
        random_position(ref);
        const double t = 60.0 * j;
        m.jig_to_device(ref, P);
        Eigen::Vector4d y;
        Eigen::Matrix<double, 4, Eigen::Dynamic> J;
        Eigen::Matrix<double, 4, 3> dP;
        std::string err;
        assert_true(ev.eval(full, ref, t, y, &J, &dP, &err));
        assert_int_equal(m.readings(P, t, yr), 0);
        for (int i = 0; i < 4; ++i) assert_true(y(i) == yr[i]);
        const double Lm = max_chord(P);
        for (size_t e = 0; e < m.effect_count(); ++e) {
            const EffectDesc &d = m.effect_desc(e);
            const bool geo = d.name == "anchor_position" || d.name == "holder_geometry";
            for (size_t k = 0; k < d.params.size(); ++k, ++cols) {
                const double base = m.effect_params(e)[k];
                Model mp = m;
                auto f = [&](double s, double *out) {
                    double Q[3];
                    return with_param(mp, e, k, base, s) && (mp.jig_to_device(ref, Q), mp.readings(Q, t, out) == 0);
                };
                double ad[4];
                for (int i = 0; i < 4; ++i) ad[i] = J(i, ev.offset(e) + int(k));
                const double omitted = geo ? 1.1 * (5 * c * Lm * Lm + std::fabs(kp) + 0.01 * std::fabs(amp)) : 0;
                // A user effect's own parameter: the difference over its step
                // (1e-6 of max(1, 1e3 scale)) rounds by 32 eps x 400 mm / step.
                const double own = d.is_user() ? kRound * 400 / (1e-6 * std::fmax(1.0, d.params[k].scale * 1e3)) : 0;
                bad += check4(d.name + "." + d.params[k].name, f, 1e-3 * d.params[k].scale, ad, omitted + own, 5.7e-7);
            }
        }
        for (int k = 0; k < 3; ++k) {
            auto f = [&](double s, double *out) {
                double Q[3] = {P[0], P[1], P[2]};
                Q[k] += s;
                return m.readings(Q, t, out) == 0;
            };
            const double ad[4] = {dP(0, k), dP(1, k), dP(2, k), dP(3, k)};
            // The evaluator's position derivative: the incoming one (|d reading
            // / d P| <= 1 + the gain, 1.1) through each effect's value
            // difference (5.7e-7 relative, above) plus each effect's own
            // position difference (32 eps x 400 mm / 1e-4 mm, 2.8e-8, twice).
            bad += check4("d/dP" + std::to_string(k), f, 1e-3, ad, 5.7e-7 * 1.1 + 5.7e-8);
        }
    }
    std::printf("%d parameter columns checked\n", cols);
    assert_true(cols > 40);
    assert_int_equal(bad, 0);
}

// The same evaluations over many positions at once (each effect called once
// per central-difference step with every position's rows) give the same
// numbers, to the bit, as one position at a time.
static void batch_equals_one_at_a_time(void **) {
    register_effects();
    Model m = geom_model();
    ReadingEvaluator ev(m);
    assert_true(ev.has_batch());
    const Eigen::VectorXd full = ev.current();
    const size_t n = 25;
    std::vector<double> refs(3 * n), ts(n);
    for (size_t j = 0; j < n; ++j) {
        random_position(&refs[3 * j]);
        ts[j] = 10.0 * double(j);
    }
    ReadingEvaluator::Batch b;
    std::string err;
    assert_true(ev.eval_batch(full, n, refs.data(), ts.data(), true, true, b, &err));
    for (size_t j = 0; j < n; ++j) {
        Eigen::Vector4d y;
        Eigen::Matrix<double, 4, Eigen::Dynamic> J;
        Eigen::Matrix<double, 4, 3> dP;
        assert_true(ev.eval(full, &refs[3 * j], ts[j], y, &J, &dP, &err));
        assert_true(y == b.y[j]);
        assert_true(J == b.J[j]);
        assert_true(dP == b.dydP[j]);
    }
    // Values only.
    assert_true(ev.eval_batch(full, n, refs.data(), ts.data(), false, false, b, &err));
    for (size_t j = 0; j < n; ++j) {
        Eigen::Vector4d y;
        assert_true(ev.eval(full, &refs[3 * j], ts[j], y, nullptr, nullptr, &err));
        assert_true(y == b.y[j]);
    }
}

// Forward kinematics through the effects: the position whose readings they
// are comes back (Gauss-Newton stops below 1e-9 mm), one at a time and in
// lockstep over many (the same bits).
static void position_solves_through_path_effect(void **) {
    register_effects();
    Model m = geom_model();
    const size_t n = 12;
    std::vector<double> L(4 * n), t(n, 0.0), p(3 * n), truth(3 * n);
    for (size_t j = 0; j < n; ++j) {
        random_position(&truth[3 * j]);
        assert_int_equal(m.readings(&truth[3 * j], 0.0, &L[4 * j]), 0);
    }
    std::vector<int> st(n);
    m.positions(n, L.data(), t.data(), p.data(), st.data());
    for (size_t j = 0; j < n; ++j) {
        double q[3];
        assert_int_equal(m.position(&L[4 * j], 0.0, q, nullptr), 0);
        assert_int_equal(st[j], 0);
        for (int k = 0; k < 3; ++k) {
            assert_true(std::fabs(q[k] - truth[3 * j + size_t(k)]) < 1e-6);
            assert_true(q[k] == p[3 * j + size_t(k)]);
        }
    }
}

// Registration since 1.2: a path-stage effect needs apply_geom; parameter
// names are identifiers, each once; units printable; an unknown stage is
// refused. A 1.1-sized struct is read as before (no such checks), and the
// fingerprint follows the names, units and stage.
static void registration_checks(void **) {
    static const char *const dup[] = {"a", "a"}, *const bad[] = {"a b"}, *const ok[] = {"a"};
    static const char *const quote[] = {"m\"m"}, *const mm[] = {"mm"}, *const um[] = {"um"};
    static const double s2[] = {1, 1};
    cdm_effect_def d{};
    d.struct_size = sizeof d;
    d.name = "test_reg";
    d.param_scale = s2;
    d.apply_geom = sag;
    std::string err;
    d.stage = CDM_EFFECT_STAGE_PATH;
    d.apply_geom = nullptr;
    d.apply_batch = [](void *, const double *, size_t, const double *, double *) { return 0; };
    assert_int_equal(register_user_effect(&d, err), CDM_ERR_INVALID_ARG);
    assert_true(err.find("needs apply_geom") != std::string::npos);
    d.apply_geom = sag;
    d.stage = 2;
    assert_int_equal(register_user_effect(&d, err), CDM_ERR_INVALID_ARG);
    assert_true(err.find("stage 2") != std::string::npos);
    d.stage = CDM_EFFECT_STAGE_PATH;
    d.n_params = 2;
    d.param_names = dup;
    assert_int_equal(register_user_effect(&d, err), CDM_ERR_INVALID_ARG);
    assert_true(err.find("two parameters named \"a\"") != std::string::npos);
    d.n_params = 1;
    d.param_names = bad;
    assert_int_equal(register_user_effect(&d, err), CDM_ERR_INVALID_ARG);
    assert_true(err.find("identifier") != std::string::npos);
    d.param_names = ok;
    d.param_units = quote;
    assert_int_equal(register_user_effect(&d, err), CDM_ERR_INVALID_ARG);
    d.param_units = mm;
    assert_int_equal(register_user_effect(&d, err), CDM_OK);
    const std::string fp_mm = find_effect("test_reg")->fingerprint;
    assert_int_equal(fp_mm.size(), 16);
    assert_int_equal(register_user_effect(&d, err), CDM_OK); // the same again: the same fingerprint
    assert_string_equal(find_effect("test_reg")->fingerprint.c_str(), fp_mm.c_str());
    d.param_units = um;
    assert_int_equal(register_user_effect(&d, err), CDM_OK);
    assert_string_not_equal(find_effect("test_reg")->fingerprint.c_str(), fp_mm.c_str());
    d.param_units = mm;
    d.stage = CDM_EFFECT_STAGE_READING;
    assert_int_equal(register_user_effect(&d, err), CDM_OK);
    assert_string_not_equal(find_effect("test_reg")->fingerprint.c_str(), fp_mm.c_str());
    // 1.1's struct: names need not be identifiers and carry no unit, but a
    // repeated one is refused there too (a calibration's "params" object
    // cannot hold both: its reload would be another model).
    cdm_effect_def old{};
    old.struct_size = uint32_t(offsetof(cdm_effect_def, apply_batch) + sizeof old.apply_batch);
    old.name = "test_reg_old";
    old.n_params = 2;
    old.param_names = dup;
    old.param_scale = s2;
    old.apply = [](void *, const double *, const double *, double *) { return 0; };
    old.stage = CDM_EFFECT_STAGE_PATH; // beyond its struct_size: not read
    assert_int_equal(register_user_effect(&old, err), CDM_ERR_INVALID_ARG);
    assert_non_null(std::strstr(err.c_str(), "two parameters named \"a\""));
    static const char *const spaced[] = {"a b", "c"}; // not identifiers: fine for 1.1
    old.param_names = spaced;
    assert_int_equal(register_user_effect(&old, err), CDM_OK);
    assert_false(find_effect("test_reg_old")->on_path);
    assert_true(find_effect("test_reg_old")->params[0].unit.empty());
    assert_int_equal(unregister_user_effect("test_reg", err), CDM_OK);
    assert_int_equal(unregister_user_effect("test_reg_old", err), CDM_OK);
}

int main() {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(context_is_the_models_geometry),
        cmocka_unit_test(path_effect_jacobian_matches_central_differences),
        cmocka_unit_test(batch_equals_one_at_a_time),
        cmocka_unit_test(position_solves_through_path_effect),
        cmocka_unit_test(registration_checks),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
