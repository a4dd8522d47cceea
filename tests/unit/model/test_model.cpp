// Triangulation (eq. 1-3) and the effect model's forward kinematics.
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <setjmp.h>

#include "model/effect.h"
#include "model/model.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

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

// The pulley's wrap: at r = 0 the path is the straight line, and the length
// grows with r by (beta - sin beta) per mm at first (d/dr at r = 0).
static void pulley_limits(void **) {
    Model straight{DeviceGeometry{}}, pulley{DeviceGeometry{}};
    std::string err;
    assert_true(pulley.add_effect("exit_pulley", Model::ParamValues{{"radius_mm", 0.0}}, err));
    double p[3] = {50, 10, -20}, a[4], b[4];
    straight.readings(p, a);
    pulley.readings(p, b);
    for (int i = 0; i < 4; ++i) assert_true(std::fabs(a[i] - b[i]) < 1e-12);
    Model small{DeviceGeometry{}};
    assert_true(small.add_effect("exit_pulley", Model::ParamValues{{"radius_mm", 1e-4}}, err));
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
    assert_true(Model::from_json(m.to_json(), "t", back, err));
    double p[3] = {40, 5, 5}, a[4], b[4];
    m.readings(p, a);
    back.readings(p, b);
    for (int i = 0; i < 4; ++i) assert_true(a[i] == b[i]);
    assert_false(m.add_effect("no_such_effect", nullptr, err));
    assert_non_null(strstr(err.c_str(), "no_such_effect"));
    assert_false(m.add_effect("cable_gain", Model::ParamValues{{"zzz", 1.0}}, err));
    assert_non_null(strstr(err.c_str(), "zzz"));
    DeviceGeometry g;
    assert_false(parse_device_json("{\"a_mm\": 150,\n \"b_mm\": ,}", "dev.json", g, err));
    assert_non_null(strstr(err.c_str(), "dev.json:2:"));
    assert_false(parse_device_json("{\"a_mm\": 150, \"b_mm\": 150}", "dev.json", g, err));
    assert_non_null(strstr(err.c_str(), "m_mm"));
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(triangulation_is_exact),
        cmocka_unit_test(triangulation_other_geometry),
        cmocka_unit_test(triangulation_rejects_impossible),
        cmocka_unit_test(forward_kinematics_inverts_each_effect),
        cmocka_unit_test(pulley_limits),
        cmocka_unit_test(json_round_trip_and_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
