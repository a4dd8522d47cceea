// hid: paths that are not a hidraw node: /dev/null, /dev/zero, a
// regular file, a directory, a FIFO without a writer, a missing path, and
// $CDM_DEVICE pointing at /dev/null. Through the real hidapi (no mock): each
// must fail with CDM_ERR_NO_DEVICE and a reason naming the path, quickly,
// without reaching hid_open_path (which crashes on several of them).
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "cdm/cdm.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

namespace {

std::string tmp(const char *name) {
    return std::string("/tmp/cdm_test_hidpaths_") + std::to_string(getpid()) + "_" + name;
}

// Opens "hid:PATH" (or NULL with $CDM_DEVICE set), expects a refusal whose
// text names PATH and contains `reason`, within 2 s (a blocking open would
// hang for ever).
void expect_refused(const std::string &path, const char *reason, bool via_env = false) {
    const auto t0 = std::chrono::steady_clock::now();
    cdm_device *dev = nullptr;
    int rc;
    if (via_env) {
        setenv("CDM_DEVICE", ("hid:" + path).c_str(), 1);
        rc = cdm_open(nullptr, &dev);
        unsetenv("CDM_DEVICE");
    } else {
        rc = cdm_open(("hid:" + path).c_str(), &dev);
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string text = cdm_thread_error();
    print_message("hid:%s -> %d \"%s\" (%.3f s)\n", path.c_str(), rc, text.c_str(), s);
    assert_int_equal(rc, CDM_ERR_NO_DEVICE);
    assert_null(dev);
    assert_true(text.find(path) != std::string::npos);
    if (text.find(reason) == std::string::npos) fail_msg("\"%s\" lacks \"%s\"", text.c_str(), reason);
    assert_true(s < 2.0);
}

void test_hid_dev_null_refused(void **) { expect_refused("/dev/null", "not a hidraw device"); }
void test_hid_dev_zero_refused(void **) { expect_refused("/dev/zero", "not a hidraw device"); }
void test_hid_env_dev_null_refused(void **) { expect_refused("/dev/null", "not a hidraw device", true); }
// $CDM_DEVICE=/dev/null, a bare path (which means hid:PATH).
void test_hid_env_bare_dev_null_refused(void **) {
    setenv("CDM_DEVICE", "/dev/null", 1);
    cdm_device *dev = nullptr;
    const int rc = cdm_open(nullptr, &dev);
    unsetenv("CDM_DEVICE");
    print_message("CDM_DEVICE=/dev/null -> %d \"%s\"\n", rc, cdm_thread_error());
    assert_int_equal(rc, CDM_ERR_NO_DEVICE);
    assert_null(dev);
    assert_non_null(std::strstr(cdm_thread_error(), "/dev/null"));
}

void test_hid_missing_path_refused(void **) { expect_refused("/nonexistent/hidraw0", "No such file"); }
void test_hid_directory_refused(void **) { expect_refused("/tmp", "a directory"); }

void test_hid_regular_file_refused(void **) {
    const std::string p = tmp("regular");
    std::FILE *f = std::fopen(p.c_str(), "wb");
    std::fputs("not a device", f);
    std::fclose(f);
    expect_refused(p, "a regular file");
    std::remove(p.c_str());
}

void test_hid_fifo_without_writer_refused(void **) {
    const std::string p = tmp("fifo");
    assert_int_equal(mkfifo(p.c_str(), 0600), 0);
    expect_refused(p, "a FIFO");
    std::remove(p.c_str());
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hid_dev_null_refused),     cmocka_unit_test(test_hid_dev_zero_refused),
        cmocka_unit_test(test_hid_env_dev_null_refused), cmocka_unit_test(test_hid_missing_path_refused),
        cmocka_unit_test(test_hid_directory_refused),    cmocka_unit_test(test_hid_regular_file_refused),
        cmocka_unit_test(test_hid_fifo_without_writer_refused),
        cmocka_unit_test(test_hid_env_bare_dev_null_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
