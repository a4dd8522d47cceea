// The one JSON loader and the device/calibration codecs: errors in words
// with file:line:column, and physically insane inputs refused.
#include <cmath>
#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <string>

#include "io/calibration_json.h"
#include "io/device_json.h"
#include "io/json.h"
#include "model/effect.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;
using cdm::io::JsonValue;
using cdm::io::parse_json;
using cdm::io::parse_calibration_json;
using cdm::io::model_to_json;

namespace {
void json_error(const std::string &text, const char *want) {
    JsonValue v;
    std::string err;
    assert_false(parse_json(text, "f.json", v, err));
    if (err.find(want) == std::string::npos) fail_msg("error \"%s\" lacks \"%s\"", err.c_str(), want);
    assert_null(strstr(err.c_str(), "[json.exception")); // in words, not a library's code
}
void device_error(const std::string &text, const char *want) {
    DeviceGeometry g;
    std::string err;
    assert_false(io::parse_device_json(text, "dev.json", g, err));
    if (err.find(want) == std::string::npos) fail_msg("error \"%s\" lacks \"%s\"", err.c_str(), want);
}
void calibration_error(const std::string &effects, const char *want) {
    const std::string text = "{\"format\": \"cdm-calibration\", \"version\": 1,\n"
                             " \"device\": {\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30},\n"
                             " \"effects\": " + effects + "}";
    Model m{DeviceGeometry{}};
    std::string err;
    assert_false(parse_calibration_json(text, "cal.json", m, err));
    if (err.find(want) == std::string::npos) fail_msg("error \"%s\" lacks \"%s\"", err.c_str(), want);
}
} // namespace

static void test_json_values_keep_line_and_column(void **) {
    JsonValue v;
    std::string err;
    assert_true(parse_json("{\"a\": [1, -2.5e1],\n  \"b\": \"x\\u00e9\\ud83d\\ude00\", \"c\": true, \"d\": null}", "f", v, err));
    assert_int_equal(v.members.size(), 4);
    const JsonValue *a = v.find("a");
    assert_true(a->items[1].number == -25.0);
    assert_int_equal(a->items[1].line, 1);
    assert_int_equal(a->items[1].col, 11);
    const JsonValue *b = v.find("b");
    assert_int_equal(b->line, 2);
    assert_int_equal(b->col, 8);
    assert_string_equal(b->str.c_str(), "x\xc3\xa9\xf0\x9f\x98\x80");
}

static void test_json_number_overflow_names_line(void **) {
    json_error("{\"a_mm\": 150,\n \"b_mm\": 1e999}", "f.json:2:10: number '1e999' is out of the range of a double");
    json_error("[-1e999]", "f.json:1:2: number");
    device_error("{\"a_mm\": 150,\n \"b_mm\": 1e999, \"m_mm\": 30}", "dev.json:2:10: number '1e999'");
}

static void test_json_trailing_bytes_refused(void **) {
    json_error("{\"a\": 1} x", "f.json:1:10: unexpected 'x' after the end of the JSON document");
    json_error("{\"a\": 1}{}", "f.json:1:9: unexpected");
}

static void test_json_duplicate_key_refused(void **) {
    json_error("{\"a_mm\": 1,\n \"a_mm\": 2}", "f.json:2:2: duplicate key \"a_mm\" (first at line 1)");
}

static void test_json_syntax_errors_in_words(void **) {
    json_error("{\"a_mm\": 150,\n \"b_mm\": ,}", "f.json:2:10: expected a JSON value, found ','");
    json_error("{\"a\": 01}", "f.json:1:8: expected ',' or '}'");
    json_error("{\"a\": \"x", "unterminated string");
    json_error("", "f.json:1:1: expected a JSON value, found the end of the file");
    json_error("[\"a\\u0000b\"]", "NUL");
}

static void test_json_deep_nesting_refused(void **) {
    json_error(std::string(100000, '['), "nested deeper than 64 levels"); // no stack overflow
}

static void test_json_huge_token_not_echoed_whole(void **) {
    JsonValue v;
    std::string err;
    assert_false(parse_json("[" + std::string(1000000, 'z') + "]", "f", v, err));
    assert_true(err.size() < 200);
}

static void test_device_json_insane_magnitudes_refused(void **) {
    device_error("{\"a_mm\": 1e300, \"b_mm\": 150, \"m_mm\": 30}",
                 "dev.json:1:10: field \"a_mm\" = 1e+300 mm is outside the sane range 10 to 5000 mm");
    device_error("{\"a_mm\": 150, \"b_mm\": 0.15, \"m_mm\": 0.03}", "\"b_mm\" = 0.15 mm is outside");
    device_error("{\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 400}", "m_mm must be smaller than 2*a_mm");
    device_error("{\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30, \"pulley_radius_mm\": -1e6}",
                 "\"pulley_radius_mm\" = -1e+06 mm is outside");
    device_error("{\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30, \"exit_axis\": [1000, 0, 0]}",
                 "exit_axis[0] has length 1000, expected a unit vector");
    device_error("{\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30, \"exit_axis\": [0, 0, 0]}", "has length 0");
    device_error("{\"a_mm\": 150, \"b_mm\": \"150\", \"m_mm\": 30}", "\"b_mm\" must be a number, got a string");
    device_error("{\"a_mm\": 150, \"m_mm\": 30}", "dev.json:1:1: missing required field \"b_mm\"");
    device_error("[]", "must be a JSON object");
}

static void test_calibration_pulley_radius_out_of_bounds_refused(void **) {
    calibration_error("[{\"name\": \"exit_pulley\", \"params\": {\"radius_mm\": -1e6}}]",
                      "cal.json:3:62: effect \"exit_pulley\": field \"radius_mm\" = -1e+06 mm is outside the sane range 0 to 40 mm");
}

static void test_calibration_effect_without_params_refused(void **) {
    calibration_error("[{\"name\": \"cable_offset\"}]", "effects[0] (\"cable_offset\") needs \"params\"");
    calibration_error("[{\"name\": \"cable_offset\", \"params\": {\"o1\": 0.1}}]", "missing required field \"o2\"");
    calibration_error("[{\"name\": \"cable_offset\", \"params\": {\"o1\": 0, \"o2\": 0, \"o3\": 0, \"o4\": 0, \"o5\": 1}}]",
                      "has no parameter \"o5\"");
    calibration_error("[{\"name\": \"no_such\", \"params\": {}}]", "unknown effect \"no_such\"");
}

static void test_calibration_trailing_bytes_and_overflow_are_parse_errors(void **) {
    Model m{DeviceGeometry{}};
    std::string err;
    assert_false(parse_calibration_json("{\"format\": \"cdm-calibration\"} trailing", "c", m, err));
    assert_non_null(strstr(err.c_str(), "c:1:31: unexpected"));
    calibration_error("[{\"name\": \"cable_offset\", \"params\": {\"o1\": 1e999}}]", "cal.json:3:56: number '1e999'");
}

static void test_calibration_roundtrip_through_codec(void **) {
    Model m{DeviceGeometry{}};
    std::string err;
    ParamValues off = {{"o1", 0.4}, {"o2", -0.3}, {"o3", 0.2}, {"o4", -0.5}};
    assert_true(m.add_effect("cable_offset", off, err));
    const std::string text = model_to_json(m).dump(2);
    Model back{DeviceGeometry{}};
    assert_true(parse_calibration_json(text, "rt", back, err));
    assert_int_equal(back.effect_count(), 1);
    assert_true(back.effect_params(0) == m.effect_params(0)); // JSON doubles round-trip exactly
    assert_true(back.geometry().a_mm == m.geometry().a_mm);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_json_values_keep_line_and_column),
        cmocka_unit_test(test_json_number_overflow_names_line),
        cmocka_unit_test(test_json_trailing_bytes_refused),
        cmocka_unit_test(test_json_duplicate_key_refused),
        cmocka_unit_test(test_json_syntax_errors_in_words),
        cmocka_unit_test(test_json_deep_nesting_refused),
        cmocka_unit_test(test_json_huge_token_not_echoed_whole),
        cmocka_unit_test(test_device_json_insane_magnitudes_refused),
        cmocka_unit_test(test_calibration_pulley_radius_out_of_bounds_refused),
        cmocka_unit_test(test_calibration_effect_without_params_refused),
        cmocka_unit_test(test_calibration_trailing_bytes_and_overflow_are_parse_errors),
        cmocka_unit_test(test_calibration_roundtrip_through_codec),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
