// The jig: the plan's order and the one error model both simulators use.
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <setjmp.h>

#include "jig/errors.h"
#include "jig/plan.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

static JigPlanOptions small_plan() {
    JigPlanOptions o;
    o.n = 4;
    o.pitch_mm = 10;
    o.heights_mm = {30, 50, 70};
    o.samples = 1;
    return o;
}

// Heights outer, rows (y), then columns (z); points numbered in that order.
static void plan_order_heights_rows_columns(void **) {
    const auto plan = make_jig_plan(small_plan());
    assert_int_equal(plan.size(), 48);
    assert_int_equal(plan[0].point, 0);
    assert_int_equal(plan[1].col, 1);
    assert_int_equal(plan[4].row, 1);
    assert_int_equal(plan[16].height_index, 1);
    assert_true(plan[16].ref[0] == 50.0);
    // centred: an even plate has no hole at the centre
    assert_true(plan[0].ref[1] == -15.0 && plan[0].ref[2] == -15.0);
}

// A hole's (y, z) error is the same at every height; a height's x error is
// the same at every hole; without a seat error nothing else varies.
static void hole_and_fixture_errors_repeat(void **) {
    const auto o = small_plan();
    const auto plan = make_jig_plan(o);
    JigErrorOptions e;
    e.hole_mm = 0.05;
    e.fixture_mm = 0.05;
    const auto t = jig_true_positions(plan, o.n, e);
    const size_t per_height = 16;
    bool any_hole = false, any_fixture = false;
    for (size_t k = 0; k < per_height; ++k)
        for (size_t h = 1; h < 3; ++h) {
            const size_t j = h * per_height + k;
            assert_true(t[j][1] - plan[j].ref[1] == t[k][1] - plan[k].ref[1]);
            assert_true(t[j][2] - plan[j].ref[2] == t[k][2] - plan[k].ref[2]);
            any_hole |= t[k][1] != plan[k].ref[1];
        }
    for (size_t h = 0; h < 3; ++h)
        for (size_t k = 1; k < per_height; ++k) {
            const size_t j = h * per_height + k;
            assert_true(t[j][0] - plan[j].ref[0] == t[h * per_height][0] - plan[h * per_height].ref[0]);
            any_fixture |= t[j][0] != plan[j].ref[0];
        }
    assert_true(any_hole && any_fixture);
}

// The seat error varies per visit, and switching it on leaves the hole and
// fixture draws as they were (each component has its own stream).
static void seat_error_is_per_visit_and_independent(void **) {
    const auto o = small_plan();
    const auto plan = make_jig_plan(o);
    JigErrorOptions e;
    e.hole_mm = 0.05;
    e.fixture_mm = 0.05;
    const auto a = jig_true_positions(plan, o.n, e);
    e.seat_mm = 1e-9;
    const auto b = jig_true_positions(plan, o.n, e);
    // 1e-9 mm std: differences stay below 1e-8 (10 sigma) yet are not all zero
    bool differ = false;
    for (size_t k = 0; k < plan.size(); ++k)
        for (int c = 0; c < 3; ++c) {
            assert_true(std::fabs(a[k][c] - b[k][c]) < 1e-8);
            differ |= a[k][c] != b[k][c];
        }
    assert_true(differ);
}

// Scattered positions stay in the plate's box and carry no hole or height.
static void scattered_plan_within_box(void **) {
    const auto o = small_plan();
    const auto plan = make_scattered_plan(o, 7);
    assert_int_equal(plan.size(), 48);
    for (const auto &p : plan) {
        assert_int_equal(p.row, -1);
        assert_int_equal(p.height_index, -1);
        assert_true(p.ref[0] >= 30 && p.ref[0] <= 70);
        assert_true(std::fabs(p.ref[1]) <= 15 && std::fabs(p.ref[2]) <= 15);
    }
}

static void bad_options_named(void **) {
    JigPlanOptions o = small_plan();
    std::string err;
    o.pitch_mm = -1;
    assert_false(check_jig_options(o, err));
    assert_non_null(std::strstr(err.c_str(), "jig_pitch"));
    o = small_plan();
    o.heights_mm = {30, 50, 30};
    assert_false(check_jig_options(o, err));
    assert_non_null(std::strstr(err.c_str(), "jig_heights lists 30 mm twice"));
    std::vector<double> h;
    assert_false(parse_heights("30,abc", h, err));
    assert_non_null(std::strstr(err.c_str(), "abc"));
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(plan_order_heights_rows_columns),
        cmocka_unit_test(hole_and_fixture_errors_repeat),
        cmocka_unit_test(seat_error_is_per_visit_and_independent),
        cmocka_unit_test(scattered_plan_within_box),
        cmocka_unit_test(bad_options_named),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
