// The C boundary: error codes and cdm_thread_error for file failures,
// unsolvable data refused before any verdict, outputs never over inputs,
// and no exception escaping (cdm::guarded).
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <csignal>

#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <new>
#include <stdexcept>
#include <string>

#include "api/errors.h"
#include "calib/dataset/dataset.h"
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
    expect_text("cdm_diagnose options:1:16: option \"candidates\" must be true or false, got 3");
    // A number out of range is shown as given.
    assert_int_equal(cdm_diagnose((g_dir + "/d.csv").c_str(), (g_dir + "/dev.json").c_str(),
                                  "{\"jig_tolerance_mm\": -1}", nullptr, nullptr, &r),
                     CDM_ERR_INVALID_ARG);
    expect_text("got -1");
    // An empty calibration_out would write nothing though a file was asked for.
    assert_int_equal(cdm_diagnose((g_dir + "/d.csv").c_str(), (g_dir + "/dev.json").c_str(),
                                  "{\"calibration_out\": \"\"}", nullptr, nullptr, &r),
                     CDM_ERR_INVALID_ARG);
    expect_text("not an empty string");
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
    // A commit with no row would replace the old file with one the reader
    // refuses: refused, nothing written, the writer still takes rows.
    assert_int_equal(cdm_dataset_writer_commit(w), CDM_ERR_INVALID_ARG);
    expect_text("no row was added");
    fd = ::open(p.c_str(), O_RDONLY);
    assert_int_equal(::read(fd, b, sizeof b), 3);
    ::close(fd);
    assert_int_equal(cdm_dataset_writer_add(w, 7, ref, len), CDM_OK);
    assert_int_equal(cdm_dataset_writer_commit(w), CDM_OK);
    cdm_dataset_writer_free(w);
    fd = ::open(p.c_str(), O_RDONLY);
    char t[128] = {};
    assert_true(::read(fd, t, sizeof t - 1) > 0);
    ::close(fd);
    assert_string_equal(t, "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n7,50.0000,0.0000,0.0000,160.0000,161.0000,162.0000,163.0000\n");
}

// load_dataset's verdict on the file at `p`: its rows, or a failure naming why.
static size_t rows_read_back(const std::string &p, size_t positions) {
    cdm::Dataset d;
    std::string err;
    if (!cdm::load_dataset(p, d, err)) fail_msg("the writer's file is refused by the reader: %s", err.c_str());
    assert_int_equal(d.pos.size(), positions);
    return d.rows;
}

// The writer refuses, when the row is added, every row load_dataset would
// refuse (NaN, infinite, negative and zero lengths, a point whose reference
// moves: written, they would make the reader refuse the file whole), and a
// refused row leaves nothing behind: the writer goes on, and the file holds
// the accepted rows only (a 1e300 must not abandon the file while later adds
// say CDM_OK).
static void test_dataset_writer_refuses_what_the_reader_refuses(void **) {
    const std::string p = g_dir + "/refused_rows.csv";
    cdm_dataset_writer *w = nullptr;
    assert_int_equal(cdm_dataset_writer_open(p.c_str(), nullptr, 0, &w), CDM_OK);
    struct Bad {
        double ref[3];
        double len[4];
        const char *arg, *value;
    };
    const Bad bad[] = {
        {{30, 0, 0}, {NAN, 200, 200, 200}, "lengths_mm[0] (l1)", "nan"},
        {{INFINITY, 0, 0}, {200, 200, 200, 200}, "ref_mm[0] (x_ref)", "inf"},
        {{30, 0, 0}, {200, -1, 200, 200}, "lengths_mm[1] (l2)", "got -1"},
        {{30, 0, 0}, {200, 200, 0, 200}, "lengths_mm[2] (l3)", "got 0"},
        // Positive, but the file's four decimals hold it as 0.0000.
        {{30, 0, 0}, {200, 200, 200, 1e-5}, "lengths_mm[3] (l4)", "0.0000 in the file"},
        {{30, 0, 0}, {1e300, 200, 200, 200}, "lengths_mm[0] (l1)", "1e+300"},
        {{30, 6000, 0}, {200, 200, 200, 200}, "ref_mm[1] (y_ref)", "6000"},
        {{30, 0, -1e300}, {200, 200, 200, 200}, "ref_mm[2] (z_ref)", "-1e+300"},
    };
    for (const Bad &b : bad) {
        assert_int_equal(cdm_dataset_writer_add(w, 3, b.ref, b.len), CDM_ERR_INVALID_ARG);
        expect_text("point 3");
        expect_text(b.arg);
        expect_text(b.value);
        assert_int_equal(cdm_dataset_writer_add_at(w, 3, b.ref, b.len, 0.5), CDM_ERR_INVALID_ARG);
        expect_text(b.arg);
    }
    // The refused timed rows decided nothing: the first accepted row has no
    // time, and the file no t_s column.
    const double ref[3] = {30, 0, 0}, len[4] = {200, 201, 202, 203};
    assert_int_equal(cdm_dataset_writer_add(w, 3, ref, len), CDM_OK);
    // A point's reference is the one its first row gave, as the file holds it.
    const double moved[3] = {40, 0, 0}, same_in_file[3] = {30.00001, 0, 0};
    assert_int_equal(cdm_dataset_writer_add(w, 3, moved, len), CDM_ERR_INVALID_ARG);
    expect_text("point 3");
    expect_text("ref_mm[0] (x_ref)");
    expect_text("40");
    expect_text("first row gave 30");
    assert_int_equal(cdm_dataset_writer_add(w, 3, same_in_file, len), CDM_OK);
    assert_int_equal(cdm_dataset_writer_add(w, 4, moved, len), CDM_OK);
    assert_int_equal(cdm_dataset_writer_commit(w), CDM_OK);
    cdm_dataset_writer_free(w);
    assert_int_equal(rows_read_back(p, 2), 3);
}

// After commit the file is complete: more rows would be lost, so they are
// refused, and so is a second commit (neither may say CDM_OK into a buffer
// nobody will write, nor be an "internal" error).
static void test_dataset_writer_refuses_rows_after_commit(void **) {
    const std::string p = g_dir + "/committed.csv";
    cdm_dataset_writer *w = nullptr;
    assert_int_equal(cdm_dataset_writer_open(p.c_str(), nullptr, 0, &w), CDM_OK);
    const double ref[3] = {30, 0, 0}, len[4] = {200, 201, 202, 203};
    assert_int_equal(cdm_dataset_writer_add(w, 1, ref, len), CDM_OK);
    assert_int_equal(cdm_dataset_writer_commit(w), CDM_OK);
    for (int i = 0; i < 3000; ++i) {
        if (cdm_dataset_writer_add(w, i, ref, len) != CDM_ERR_INVALID_ARG)
            fail_msg("add %d after commit: not CDM_ERR_INVALID_ARG (%s)", i, cdm_thread_error());
        expect_text("already committed");
    }
    assert_int_equal(cdm_dataset_writer_add_at(w, 1, ref, len, 1.0), CDM_ERR_INVALID_ARG);
    expect_text("already committed");
    assert_int_equal(cdm_dataset_writer_commit(w), CDM_ERR_INVALID_ARG);
    expect_text("already committed");
    cdm_dataset_writer_free(w);
    assert_int_equal(rows_read_back(p, 1), 1);
}

// A write that fails (here a file-size limit: EFBIG, the same path as
// ENOSPC) ends the file: every later add and the commit fail with that
// cause, never CDM_OK, and nothing replaces the target.
static void test_dataset_writer_write_failure_is_sticky(void **) {
    const std::string p = g_dir + "/full.csv";
    const pid_t pid = fork();
    if (pid == 0) {
        signal(SIGXFSZ, SIG_IGN);
        rlimit lim{10000, 10000}; // the first 64 KiB flush does not fit
        setrlimit(RLIMIT_FSIZE, &lim);
        cdm_dataset_writer *w = nullptr;
        if (cdm_dataset_writer_open(p.c_str(), nullptr, 0, &w) != CDM_OK) _exit(2);
        const double ref[3] = {30, 0, 0}, len[4] = {200, 201, 202, 203};
        int rc = CDM_OK, i = 0;
        for (; i < 5000 && rc == CDM_OK; ++i) rc = cdm_dataset_writer_add(w, 1, ref, len);
        if (rc != CDM_ERR_IO || !strstr(cdm_thread_error(), "File too large")) _exit(3);
        for (int k = 0; k < 3000; ++k)
            if (cdm_dataset_writer_add(w, 1, ref, len) != CDM_ERR_IO || !strstr(cdm_thread_error(), "File too large"))
                _exit(4);
        if (cdm_dataset_writer_add_at(w, 1, ref, len, 1.0) != CDM_ERR_IO) _exit(5);
        if (cdm_dataset_writer_commit(w) != CDM_ERR_IO || !strstr(cdm_thread_error(), "File too large")) _exit(6);
        cdm_dataset_writer_free(w);
        _exit(0);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    assert_true(WIFEXITED(status));
    assert_int_equal(WEXITSTATUS(status), 0);
    assert_int_equal(::access(p.c_str(), F_OK), -1);
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
        cmocka_unit_test(test_dataset_writer_refuses_what_the_reader_refuses),
        cmocka_unit_test(test_dataset_writer_refuses_rows_after_commit),
        cmocka_unit_test(test_dataset_writer_write_failure_is_sticky),
    };
    const int failed = cmocka_run_group_tests(tests, NULL, NULL);
    if (failed == 0) { // (kept to look at when a test failed)
        std::error_code ec;
        std::filesystem::remove_all(g_dir, ec);
    }
    return failed;
}
