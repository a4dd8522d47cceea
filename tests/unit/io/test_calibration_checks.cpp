// A calibration checked on load and against the device (docs/calibration.md,
// "Checks on load"): unknown keys refused at their line and column, a model
// that moves the workspace refused whatever its parameters' bounds, a
// calibration for another frame refused by cdm_set_calibration, a user
// effect's parameter names unique and valid UTF-8. Through the public API.
#include <cstddef>
#include <cstring>
#include <string>

#include "cdm/cdm.h"

extern "C" {
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>

#include <cmocka.h>
}

namespace {

int parse(const std::string &text, cdm_calibration **cal = nullptr) {
    cdm_calibration *c = nullptr;
    const int rc = cdm_calibration_parse(text.data(), text.size(), &c);
    if (cal)
        *cal = c;
    else
        cdm_calibration_free(c);
    return rc;
}

void expect_text(const char *want) {
    const char *t = cdm_thread_error();
    if (!std::strstr(t, want)) fail_msg("cdm_thread_error \"%s\" lacks \"%s\"", t, want);
}

const char *kHead = "{\"format\": \"cdm-calibration\", \"version\": 1,\n";
const char *kDevice = " \"device\": {\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30}";

std::string with_ellipsoid(const char *l, const char *m, const char *n, const char *device = kDevice) {
    return std::string(kHead) + device + ",\n \"effects\": [{\"name\": \"ellipsoid\", \"params\": {\"L\": " + l +
           ", \"M\": " + m + ", \"N\": " + n + "}}]}";
}

// "effect" for "effects": the calibration would load as the nominal model
// and its poses be flagged COMPENSATED.
void test_misspelt_top_level_key_refused_at_its_position(void **) {
    const std::string t = std::string(kHead) + kDevice + ",\n \"effect\": []}";
    assert_int_equal(parse(t), CDM_ERR_PARSE);
    expect_text("(calibration text):3:12: unknown key \"effect\" in a calibration (cdm-calibration version 1)");
    expect_text("did you mean \"effects\"?");
}

// "pulley_radius_m": the default radius would be used silently.
void test_misspelt_device_key_refused(void **) {
    const std::string t = std::string(kHead) +
                          " \"device\": {\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30, \"pulley_radius_m\": 4}}";
    assert_int_equal(parse(t), CDM_ERR_PARSE);
    expect_text(":2:70: unknown key \"pulley_radius_m\" in a device description");
    expect_text("did you mean \"pulley_radius_mm\"?");
    // The optional schema markers are accepted when right, refused when wrong.
    const std::string ok = std::string(kHead) +
                           " \"device\": {\"format\": \"cdm-device\", \"version\": 1, \"a_mm\": 150, \"b_mm\": 150, "
                           "\"m_mm\": 30}}";
    assert_int_equal(parse(ok), CDM_OK);
    const std::string v2 = std::string(kHead) +
                           " \"device\": {\"version\": 2, \"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30}}";
    assert_int_equal(parse(v2), CDM_ERR_PARSE);
    expect_text("unsupported device description version");
}

void test_misspelt_effect_entry_key_refused(void **) {
    const std::string t = std::string(kHead) + kDevice +
                          ",\n \"effects\": [{\"name\": \"ellipsoid\", \"parms\": {}}]}";
    assert_int_equal(parse(t), CDM_ERR_PARSE);
    expect_text("unknown key \"parms\" in effects[0]");
    expect_text("did you mean \"params\"?");
}

// The example: every parameter inside the ellipsoid's bounds (L up
// to 1e9, M and N from 1), poses at x = 2.9e10 mm. Refused with the shift.
void test_ellipsoid_moving_the_workspace_refused(void **) {
    assert_int_equal(parse(with_ellipsoid("1e9", "1", "1")), CDM_ERR_PARSE);
    expect_text("the calibration moves the holder by ");
    expect_text("a calibration may move it by at most 30 mm (20 % of min(a_mm, b_mm))");
    // Past the bound: at y = z = 75 mm, x_c = L (1 - sqrt(1 + 2 (75/M)^2));
    // with M = N = 1000 mm, L = -10000 mm shifts x by 10000 * 0.005609 = 56.09 mm.
    assert_int_equal(parse(with_ellipsoid("-10000", "1000", "1000")), CDM_ERR_PARSE);
    expect_text("moves the holder by 56.09 mm at the workspace point");
}

// The seed's own values (L = 5989.1, M = 2950.2, N = 3092.8 mm) move the
// corners of the grid by 3.7 mm: accepted.
void test_seed_ellipsoid_accepted(void **) {
    cdm_calibration *cal = nullptr;
    assert_int_equal(parse(with_ellipsoid("5989.1", "2950.2", "3092.8"), &cal), CDM_OK);
    assert_non_null(cal);
    cdm_calibration_free(cal);
}

// A 300 mm calibration on the 150 mm sim: refused with both numbers; the
// device's own frame accepted.
void test_calibration_for_another_frame_refused(void **) {
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open("sim:", &dev), CDM_OK);
    cdm_calibration *other = nullptr, *own = nullptr;
    assert_int_equal(parse(with_ellipsoid("5989.1", "2950.2", "3092.8",
                                          " \"device\": {\"a_mm\": 300, \"b_mm\": 300, \"m_mm\": 30}"),
                           &other),
                     CDM_OK);
    assert_int_equal(cdm_set_calibration(dev, other), CDM_ERR_INVALID_ARG);
    expect_text("a_mm 300 (calibration) vs 150 (device");
    expect_text("b_mm 300 (calibration) vs 150");
    expect_text("more than the 1 mm tolerance");
    assert_int_equal(parse(with_ellipsoid("5989.1", "2950.2", "3092.8",
                                          " \"device\": {\"a_mm\": 150.5, \"b_mm\": 149.5, \"m_mm\": 30}"),
                           &own),
                     CDM_OK);
    assert_int_equal(cdm_set_calibration(dev, own), CDM_OK); // within 1 mm
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_int_equal(cdm_wait_pose(dev, 2000, &p), CDM_OK);
    cdm_calibration_free(other);
    cdm_calibration_free(own);
    cdm_close(dev);
}

int apply_nothing(void *, const double *, const double *, double *) { return 0; }

cdm_effect_def def_of(const char *name, const char *const *names, const double *scale, uint32_t n) {
    cdm_effect_def d{};
    d.struct_size = sizeof d;
    d.n_params = n;
    d.name = name;
    d.doc = "test";
    d.param_names = names;
    d.param_scale = scale;
    d.apply = apply_nothing;
    return d;
}

// A repeated name is refused for a 1.1-size registration too (a
// calibration's "params" object cannot hold both: the reloaded model would
// be another one).
void test_user_effect_repeated_parameter_names_refused(void **) {
    const char *names[] = {"k", "k"};
    const double scale[] = {1, 1};
    cdm_effect_def d = def_of("test_repeat", names, scale, 2);
    assert_int_equal(cdm_effect_register(&d), CDM_ERR_INVALID_ARG);
    expect_text("two parameters named \"k\"");
    d.struct_size = uint32_t(offsetof(cdm_effect_def, param_units)); // 1.1
    assert_int_equal(cdm_effect_register(&d), CDM_ERR_INVALID_ARG);
    expect_text("two parameters named \"k\"");
}

void test_user_effect_invalid_utf8_refused(void **) {
    const char *names[] = {"ok", "bad\xff"};
    const double scale[] = {1, 1};
    cdm_effect_def d = def_of("test_utf8", names, scale, 2);
    d.struct_size = uint32_t(offsetof(cdm_effect_def, param_units)); // 1.1: names are not identifiers there
    assert_int_equal(cdm_effect_register(&d), CDM_ERR_INVALID_ARG);
    expect_text("not valid UTF-8");
    const char *cut[] = {"ok", "\xc3"};             // a two-byte sequence cut short
    const char *surrogate[] = {"ok", "\xed\xa0\x80"}; // U+D800
    const char *overlong[] = {"ok", "\xc0\xaf"};     // '/' in two bytes
    for (const char *const *n : {cut, surrogate, overlong}) {
        d.param_names = n;
        assert_int_equal(cdm_effect_register(&d), CDM_ERR_INVALID_ARG);
        expect_text("not valid UTF-8");
    }
    const char *good[] = {"ok", "\xce\xb1"}; // alpha: valid UTF-8, accepted by a 1.1 registration
    d.param_names = good;
    assert_int_equal(cdm_effect_register(&d), CDM_OK);
    assert_int_equal(cdm_effect_unregister("test_utf8"), CDM_OK);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_misspelt_top_level_key_refused_at_its_position),
        cmocka_unit_test(test_misspelt_device_key_refused),
        cmocka_unit_test(test_misspelt_effect_entry_key_refused),
        cmocka_unit_test(test_ellipsoid_moving_the_workspace_refused),
        cmocka_unit_test(test_seed_ellipsoid_accepted),
        cmocka_unit_test(test_calibration_for_another_frame_refused),
        cmocka_unit_test(test_user_effect_repeated_parameter_names_refused),
        cmocka_unit_test(test_user_effect_invalid_utf8_refused),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
