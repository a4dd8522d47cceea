// The C boundary: error codes and cdm_thread_error for file failures,
// unsolvable data refused before any verdict, outputs never over inputs,
// and no exception escaping (cdm::guarded).
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <new>
#include <stdexcept>
#include <string>

#include "api/errors.h"
#include "cdm/cdm.h"

extern "C" {
#include <cmocka.h>
}

namespace {
std::string g_dir;
void put(const std::string &p, const std::string &s) {
    int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    assert_true(fd >= 0);
    assert_int_equal(::write(fd, s.data(), s.size()), ssize_t(s.size()));
    ::close(fd);
}
void expect_text(const char *want) {
    const char *t = cdm_thread_error();
    if (!strstr(t, want)) fail_msg("cdm_thread_error \"%s\" lacks \"%s\"", t, want);
}
const char *kDevice = "{\"a_mm\": 150, \"b_mm\": 150, \"m_mm\": 30}";
} // namespace

static void test_missing_dataset_and_calibration_same_code(void **) {
    cdm_calibration *cal = nullptr;
    assert_int_equal(cdm_calibration_load((g_dir + "/none.json").c_str(), &cal), CDM_ERR_IO);
    expect_text("none.json: cannot open the calibration: No such file or directory");
    put(g_dir + "/dev.json", kDevice);
    char *r = nullptr;
    assert_int_equal(cdm_diagnose((g_dir + "/none.csv").c_str(), (g_dir + "/dev.json").c_str(), nullptr, nullptr,
                                  nullptr, &r),
                     CDM_ERR_IO);
    expect_text("none.csv: cannot open the dataset: No such file or directory");
    assert_null(r);
}

static void test_calibration_load_refuses_special_files(void **) {
    cdm_calibration *cal = nullptr;
    assert_int_equal(cdm_calibration_load("/dev/zero", &cal), CDM_ERR_IO);
    expect_text("/dev/zero: the calibration is a character device");
    assert_int_equal(cdm_calibration_load(g_dir.c_str(), &cal), CDM_ERR_IO);
    expect_text("is a directory");
}

static void test_calibration_overflow_is_parse_error_with_location(void **) {
    const std::string t = "{\"format\": \"cdm-calibration\", \"version\": 1,\n \"device\": {\"a_mm\": 1e999}}";
    cdm_calibration *cal = nullptr;
    assert_int_equal(cdm_calibration_parse(t.data(), t.size(), &cal), CDM_ERR_PARSE);
    expect_text("(calibration text):2:21: number '1e999'");
    assert_null(cal);
}

static void test_thread_error_set_on_failure_cleared_on_success(void **) {
    cdm_calibration *cal = nullptr;
    assert_int_equal(cdm_calibration_parse("{", 1, &cal), CDM_ERR_PARSE);
    const std::string first = cdm_thread_error();
    assert_false(first.empty());
    // a later, different failure replaces the text
    assert_int_equal(cdm_calibration_load("/dev/null", &cal), CDM_ERR_IO);
    expect_text("/dev/null");
    assert_null(strstr(cdm_thread_error(), first.c_str()));
    // a success clears it
    const std::string ok = std::string("{\"format\": \"cdm-calibration\", \"version\": 1, \"device\": ") + kDevice + "}";
    assert_int_equal(cdm_calibration_parse(ok.data(), ok.size(), &cal), CDM_OK);
    assert_string_equal(cdm_thread_error(), "");
    // position failures set a text too
    double len[4] = {1e-300, 1e-300, 1e-300, 1e-300}, p[3];
    assert_int_equal(cdm_calibration_position(cal, len, p), CDM_ERR_NUMERIC);
    expect_text("cdm_calibration_position");
    double good[4], pos[3] = {50, 10, -5};
    assert_int_equal(cdm_calibration_lengths(cal, pos, good), CDM_OK);
    assert_string_equal(cdm_thread_error(), "");
    cdm_calibration_free(cal);
}

static void test_guarded_turns_exceptions_into_codes(void **) {
    assert_int_equal(cdm::guarded("f", []() -> int { throw std::bad_alloc(); }), CDM_ERR_NO_MEM);
    expect_text("f: out of memory");
    assert_int_equal(cdm::guarded("g", []() -> int { throw std::out_of_range("number overflow 406"); }),
                     CDM_ERR_INTERNAL);
    expect_text("g: internal error: number overflow 406");
    assert_int_equal(cdm::guarded("h", []() -> int { throw 42; }), CDM_ERR_INTERNAL);
    expect_text("h: internal error: unknown exception");
}

static void test_diagnose_unsolvable_data_fails_with_count(void **) {
    // lengths of 1e-300 pass the dataset's "positive" check but no position has them
    std::string csv = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
    for (int k = 0; k < 6; ++k)
        csv += std::to_string(k) + ",50," + std::to_string(10 * k) + ",0,1e-300,1e-300,1e-300,1e-300\n";
    put(g_dir + "/tiny.csv", csv);
    put(g_dir + "/dev.json", kDevice);
    char *r = nullptr;
    assert_int_equal(cdm_diagnose((g_dir + "/tiny.csv").c_str(), (g_dir + "/dev.json").c_str(), nullptr, nullptr,
                                  nullptr, &r),
                     CDM_ERR_NUMERIC);
    expect_text("6 of 6 positions (6 samples) cannot be placed");
    assert_null(r);
}

static void test_diagnose_calibration_out_refuses_input_and_device_node(void **) {
    put(g_dir + "/dev.json", kDevice);
    put(g_dir + "/d.csv", "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,50,0,0,100,100,100,100\n");
    char *r = nullptr;
    const std::string opt_in = "{\"calibration_out\": \"" + g_dir + "/./dev.json\"}";
    assert_int_equal(cdm_diagnose((g_dir + "/d.csv").c_str(), (g_dir + "/dev.json").c_str(), opt_in.c_str(), nullptr,
                                  nullptr, &r),
                     CDM_ERR_IO);
    expect_text("an input of this command");
    const std::string opt_dev = "{\"calibration_out\": \"/dev/null\"}";
    assert_int_equal(cdm_diagnose((g_dir + "/d.csv").c_str(), (g_dir + "/dev.json").c_str(), opt_dev.c_str(), nullptr,
                                  nullptr, &r),
                     CDM_ERR_IO);
    expect_text("character device");
    // the device description is intact
    cdm_calibration *cal = nullptr;
    const std::string ok = std::string("{\"format\": \"cdm-calibration\", \"version\": 1, \"device\": ") + kDevice + "}";
    assert_int_equal(cdm_calibration_parse(ok.data(), ok.size(), &cal), CDM_OK);
    cdm_calibration_free(cal);
}

static void test_diagnose_bad_option_type_names_column(void **) {
    put(g_dir + "/dev.json", kDevice);
    put(g_dir + "/d.csv", "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,50,0,0,100,100,100,100\n");
    char *r = nullptr;
    assert_int_equal(cdm_diagnose((g_dir + "/d.csv").c_str(), (g_dir + "/dev.json").c_str(),
                                  "{\"candidates\": 3}", nullptr, nullptr, &r),
                     CDM_ERR_INVALID_ARG);
    expect_text("cdm_diagnose options:1:16: option \"candidates\" must be true or false, got a number");
    assert_int_equal(cdm_diagnose((g_dir + "/d.csv").c_str(), (g_dir + "/dev.json").c_str(),
                                  "{\"jig_tolerance_mm\": 1e999}", nullptr, nullptr, &r),
                     CDM_ERR_INVALID_ARG);
    expect_text("number '1e999'");
}

static void test_dataset_writer_c_api_atomic(void **) {
    const std::string p = g_dir + "/rec.csv", in = g_dir + "/dev.json";
    put(p, "old");
    put(in, kDevice);
    cdm_dataset_writer *w = nullptr;
    const char *protect[] = {in.c_str()};
    assert_int_equal(cdm_dataset_writer_open(in.c_str(), protect, 1, &w), CDM_ERR_IO);
    expect_text("an input of this command");
    assert_int_equal(cdm_dataset_writer_open("/dev/null", nullptr, 0, &w), CDM_ERR_IO);
    expect_text("character device");
    assert_int_equal(cdm_dataset_writer_open(p.c_str(), protect, 1, &w), CDM_OK);
    const double ref[3] = {50, 0, 0}, len[4] = {160, 161, 162, 163};
    assert_int_equal(cdm_dataset_writer_add(w, 7, ref, len), CDM_OK);
    cdm_dataset_writer_free(w); // no commit: the old file stays
    int fd = ::open(p.c_str(), O_RDONLY);
    char b[8] = {};
    assert_int_equal(::read(fd, b, sizeof b), 3);
    ::close(fd);
    assert_int_equal(cdm_dataset_writer_open(p.c_str(), nullptr, 0, &w), CDM_OK);
    assert_int_equal(cdm_dataset_writer_add(w, 7, ref, len), CDM_OK);
    assert_int_equal(cdm_dataset_writer_commit(w), CDM_OK);
    cdm_dataset_writer_free(w);
    fd = ::open(p.c_str(), O_RDONLY);
    char t[128] = {};
    assert_true(::read(fd, t, sizeof t - 1) > 0);
    ::close(fd);
    assert_string_equal(t, "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n7,50.0000,0.0000,0.0000,160.0000,161.0000,162.0000,163.0000\n");
}

int main(void) {
    char t[] = "/tmp/cdm_api_XXXXXX";
    g_dir = mkdtemp(t);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_missing_dataset_and_calibration_same_code),
        cmocka_unit_test(test_calibration_load_refuses_special_files),
        cmocka_unit_test(test_calibration_overflow_is_parse_error_with_location),
        cmocka_unit_test(test_thread_error_set_on_failure_cleared_on_success),
        cmocka_unit_test(test_guarded_turns_exceptions_into_codes),
        cmocka_unit_test(test_diagnose_unsolvable_data_fails_with_count),
        cmocka_unit_test(test_diagnose_calibration_out_refuses_input_and_device_node),
        cmocka_unit_test(test_diagnose_bad_option_type_names_column),
        cmocka_unit_test(test_dataset_writer_c_api_atomic),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
