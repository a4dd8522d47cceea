// Dataset CSV: grouping, ignored columns, and errors that name file, line, column.
#include <cmath>
#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <unistd.h>
#include <cstdlib>

#include "calib/dataset.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm;

static void groups_and_ignores(void **) {
    Dataset d;
    std::string err;
    const char *t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,temp\n"
                    "3,30,0,0,100,101,102,103,21.5\n"
                    "7,40,5,0,110,111,112,113,21.5\n"
                    "3,30,0,0,100.2,101.2,102.2,103.2,21.6\n";
    assert_true(parse_dataset(t, "a.csv", d, err));
    assert_int_equal(d.rows, 3);
    assert_int_equal(d.pos.size(), 2);
    assert_int_equal(d.pos[0].point, 3);
    assert_int_equal(d.pos[0].n, 2);
    assert_true(std::fabs(d.pos[0].mean[0] - 100.1) < 1e-12);
    assert_true(std::fabs(d.pos[0].cov[0][0] - 0.02) < 1e-12);
    assert_int_equal(d.ignored_columns.size(), 1);
    assert_string_equal(d.ignored_columns[0].c_str(), "temp");
    assert_int_equal(d.heights.size(), 2);
}

// Rows are in acquisition order: a position's time is the mean index of its
// rows (exact in binary for these small integers and halves).
static void acquisition_order_per_position(void **) {
    const char *t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n"
                    "1,0,0,0,100,100,100,100\n"
                    "2,0,10,0,100,100,100,100\n"
                    "1,0,0,0,100,100,100,100\n"
                    "2,0,10,0,100,100,100,100\n"
                    "2,0,10,0,100,100,100,100\n";
    Dataset d;
    std::string err;
    assert_true(parse_dataset(t, "o.csv", d, err));
    assert_int_equal(d.pos.size(), 2);
    assert_true(d.pos[0].mean_row == 1.0);           // rows 0 and 2
    assert_true(d.pos[1].mean_row == 8.0 / 3.0);     // rows 1, 3, 4
    assert_true(d.pos[1].t_s == d.pos[1].mean_row * kDatasetNominalRowPeriodS);

    // With a t_s column the time is its per-position mean, not the row index.
    const char *tt = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s\n"
                     "1,0,0,0,100,100,100,100,2\n"
                     "1,0,0,0,100,100,100,100,4\n";
    Dataset e;
    assert_true(parse_dataset(tt, "t.csv", e, err));
    assert_true(e.ignored_columns.empty());
    assert_true(e.pos[0].t_s == 3.0);
    Dataset b;
    assert_false(parse_dataset("point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s\n1,0,0,0,100,100,100,100,nan\n", "bad.csv", b, err));
    assert_non_null(strstr(err.c_str(), "bad.csv:2:9: t_s"));
}

static void expect_error(const char *text, const char *where) {
    Dataset d;
    std::string err;
    assert_false(parse_dataset(text, "bad.csv", d, err));
    if (!strstr(err.c_str(), where)) fail_msg("error \"%s\" does not name \"%s\"", err.c_str(), where);
}

static void errors_name_line_and_column(void **) {
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3\n1,2,3,4,5,6,7\n", "bad.csv:1:1: header lacks column \"l4\"");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,abc,100,100\n", "bad.csv:2:6: l2 is not a finite number");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,100,100\n", "bad.csv:2:");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,100,100,-1\n", "bad.csv:2:8: l4 must be a positive");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1.5,30,0,0,100,100,100,100\n", "bad.csv:2:1: point must be an integer");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,1,1,1,1\n1,40,0,0,1,1,1,1\n",
                 "bad.csv:3:2: point 1 has x_ref 40");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,nan,0,0,1,1,1,1\n", "bad.csv:2:2");
    expect_error("", "empty file");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n", "no data rows");
}

static void test_dataset_duplicate_column_refused(void **) {
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4,l2\n1,30,0,0,100,100,100,100,5\n",
                 "bad.csv:1:9: duplicate column \"l2\" (also column 6)");
}

static void test_dataset_huge_field_not_echoed_whole(void **) {
    std::string t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,";
    t += std::string(1000000, '7') + "x,100,100\n";
    Dataset d;
    std::string err;
    assert_false(parse_dataset(t, "big.csv", d, err));
    assert_non_null(strstr(err.c_str(), "big.csv:2:6: l2 is not a finite number"));
    assert_non_null(strstr(err.c_str(), "more characters)"));
    assert_true(err.size() < 200); // ~40 characters of the field, not 10^6
}

static void test_dataset_insane_magnitudes_refused(void **) {
    // lengths of 1e-300 are "positive" but reach nothing; refused by the solvability check in
    // cdm_diagnose (tests/unit/io/test_api_boundary.cpp); these are refused at parse time.
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,1e300,0,0,100,100,100,100\n", "bad.csv:2:2: x_ref = 1e300 mm is beyond");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,1.7e308,100,100,100\n", "bad.csv:2:5: l1 must be a positive");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,100,inf,100\n", "bad.csv:2:7: l3 is not a finite number");
    expect_error("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,100,100,0\n", "bad.csv:2:8: l4 must be a positive");
}

static void test_dataset_missing_file_is_io_failure(void **) {
    Dataset d;
    std::string err;
    bool io = false;
    assert_false(load_dataset("/nonexistent-dir/none.csv", d, err, &io));
    assert_true(io);
    assert_non_null(strstr(err.c_str(), "/nonexistent-dir/none.csv: cannot open the dataset: No such file or directory"));
    assert_false(load_dataset("/dev/zero", d, err, &io));
    assert_true(io);
    assert_non_null(strstr(err.c_str(), "character device"));
}

static void write_is_atomic(void **) {
    std::string err;
    char path[] = "/tmp/cdm_ds_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    const double ref[3] = {30, 0, 0}, len[4] = {1, 2, 3, 4};
    {
        DatasetWriter w;
        assert_true(w.open(path, {}, err));
        assert_true(w.add_row(1, ref, len, err) && w.add_row(1, ref, len, err));
        // Not committed yet: the target is still the old (empty) file.
        Dataset d;
        assert_false(load_dataset(path, d, err));
        assert_true(w.commit(err));
    }
    Dataset d;
    assert_true(load_dataset(path, d, err));
    assert_int_equal(d.rows, 2);
    {
        DatasetWriter w;
        assert_false(w.open("/nonexistent-dir/x.csv", {}, err));
        assert_non_null(strstr(err.c_str(), "No such file or directory"));
    }
    {
        // Abandoned (destroyed without commit): the committed file is intact.
        DatasetWriter w;
        assert_true(w.open(path, {}, err));
        assert_true(w.add_row(2, ref, len, err));
    }
    assert_true(load_dataset(path, d, err));
    assert_int_equal(d.rows, 2);
    unlink(path);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(groups_and_ignores),
        cmocka_unit_test(acquisition_order_per_position),
        cmocka_unit_test(errors_name_line_and_column),
        cmocka_unit_test(write_is_atomic),
        cmocka_unit_test(test_dataset_duplicate_column_refused),
        cmocka_unit_test(test_dataset_huge_field_not_echoed_whole),
        cmocka_unit_test(test_dataset_insane_magnitudes_refused),
        cmocka_unit_test(test_dataset_missing_file_is_io_failure),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
