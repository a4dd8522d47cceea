// Dataset CSV: grouping, ignored columns, and errors that name file, line, column.
#include <cmath>
#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <unistd.h>
#include <cstdlib>
#include <fcntl.h>
#include <string>
#include <vector>

#include "calib/dataset/dataset.h"

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

// A CSV saved "as UTF-8" by a spreadsheet starts with a byte order mark:
// read as if it were not there (it was "header lacks column \"point\"").
static void test_dataset_utf8_bom_read(void **) {
    const std::string t = "\xEF\xBB\xBFpoint,x_ref,y_ref,z_ref,l1,l2,l3,l4\r\n1,30,0,0,100,100,100,100\r\n";
    Dataset d;
    std::string err;
    if (!parse_dataset(t, "bom.csv", d, err)) fail_msg("%s", err.c_str());
    assert_int_equal(d.pos.size(), 1);
    assert_int_equal(d.pos[0].point, 1);
    assert_true(d.ignored_columns.empty());
    Dataset q; // the BOM before a quoted name too
    if (!parse_dataset("\xEF\xBB\xBF\"point\",x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,100,100,100\n", "q.csv", q, err))
        fail_msg("%s", err.c_str());
}

// Heights are the x_ref values positions share; a value no other position
// has (a tenth of the jig or fewer) is off its height, not a height. The
// decision is the first read's: setting positions aside (without_points)
// keeps it, though 3 of 29 would be more than a tenth.
static void test_dataset_off_height_references(void **) {
    std::string t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n";
    int id = 0;
    for (double h : {30.0, 50.0, 70.0})
        for (int k = 0; k < 9; ++k)
            t += std::to_string(++id) + "," + std::to_string(h) + "," + std::to_string(5 * k) + ",0,100,100,100,100\n";
    for (double x : {31.0, 50.004, 69.5}) t += std::to_string(++id) + "," + std::to_string(x) + ",7,7,100,100,100,100\n";
    Dataset d;
    std::string err;
    if (!parse_dataset(t, "off.csv", d, err)) fail_msg("%s", err.c_str());
    assert_int_equal(d.heights.size(), 3);
    assert_true(d.off_height_points == std::vector<long>({28, 29, 30}));
    Dataset w;
    if (!without_points(d, {1}, w, err)) fail_msg("%s", err.c_str());
    assert_int_equal(w.pos.size(), 29);
    assert_int_equal(w.heights.size(), 3);
    assert_true(w.off_height_points == std::vector<long>({28, 29, 30}));
    // Without one of them, the other two stay off their heights.
    if (!without_points(d, {29}, w, err)) fail_msg("%s", err.c_str());
    assert_true(w.off_height_points == std::vector<long>({28, 30}));
    // Scattered in x (every value once): every value is a height, as before.
    Dataset sc;
    if (!parse_dataset("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,1,1,1,1\n2,31,0,0,1,1,1,1\n3,32,0,0,1,1,1,1\n",
                       "sc.csv", sc, err))
        fail_msg("%s", err.c_str());
    assert_int_equal(sc.heights.size(), 3);
    assert_true(sc.off_height_points.empty());
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


// A temporary file holding `text`, removed by the destructor.
struct TempCsv {
    std::string path;
    explicit TempCsv(const std::string &text) {
        char p[] = "/tmp/cdm_ds_XXXXXX";
        const int fd = mkstemp(p);
        assert_true(fd >= 0);
        assert_int_equal(write(fd, text.data(), text.size()), ssize_t(text.size()));
        close(fd);
        path = p;
    }
    ~TempCsv() { unlink(path.c_str()); }
};

static void assert_same_dataset(const Dataset &a, const Dataset &b) {
    assert_int_equal(a.rows, b.rows);
    assert_int_equal(a.pos.size(), b.pos.size());
    for (size_t g = 0; g < a.pos.size(); ++g) {
        const JigHole &x = a.pos[g], &y = b.pos[g];
        assert_int_equal(x.point, y.point);
        assert_int_equal(x.n, y.n);
        assert_memory_equal(x.ref, y.ref, sizeof x.ref);
        assert_memory_equal(x.mean, y.mean, sizeof x.mean);
        assert_memory_equal(x.cov, y.cov, sizeof x.cov);
        assert_true(x.mean_row == y.mean_row && x.t_s == y.t_s);
    }
    assert_memory_equal(a.resolution, b.resolution, sizeof a.resolution);
    assert_true(a.heights == b.heights);
    assert_true(a.ignored_columns == b.ignored_columns);
}

// The file is read in 1 MiB pieces: lines cut by a piece's end, CRLF, a
// comment, and one line longer than a piece must give exactly what parsing
// the whole text gives, and an error after them must still name its line.
static void file_in_pieces_equals_whole_text(void **) {
    std::string t = "# a jig session\r\npoint,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s,note\r\n";
    char row[160];
    size_t lines = 2;
    for (int r = 0; r < 60000; ++r) {
        const int pt = r % 37; // positions interleaved: each is revisited
        std::snprintf(row, sizeof row, "%d,%d,%d,0,%.2f,%.2f,%.2f,%.2f,%.3f,x\r\n", pt, 30 + 10 * (pt % 5), pt,
                      300 + pt + 0.01 * (r % 7), 301 + 0.01 * (r % 11), 302 - 0.02 * (r % 5), 303 + 0.03 * (r % 3),
                      0.005 * r);
        t += row;
        ++lines;
        if (r == 30000) { // a 1.5 MiB field in an ignored column
            t += "5,30,5,0,305,301,302,303,150.0," + std::string(3 << 19, 'n') + "\r\n";
            ++lines;
        }
    }
    assert_true(t.size() > (size_t(3) << 20));
    Dataset whole, file;
    std::string err;
    assert_true(parse_dataset(t, "s.csv", whole, err));
    TempCsv f(t);
    assert_true(load_dataset(f.path, file, err));
    assert_same_dataset(whole, file);
    assert_int_equal(file.rows, 60001);
    assert_true(file.resolution[1] > 0.0099 && file.resolution[1] < 0.0101);

    TempCsv bad(t + "1,30,1,0,300,301,302,oops,1,x\r\n");
    assert_false(load_dataset(bad.path, file, err));
    const std::string where = bad.path + ":" + std::to_string(lines + 1) + ":8: l4 is not a finite number";
    if (!strstr(err.c_str(), where.c_str())) fail_msg("error \"%s\" does not name \"%s\"", err.c_str(), where.c_str());
}

// A file of many blocks (the reader's values are found for blocks ahead on
// a second thread, calib/dataset/read.cpp): every position's statistics are Welford's
// update in file order, bit for bit, as the test computes them here row by
// row; blank and comment lines between rows, CRLF ends and a last line
// without its '\n' change nothing but the line count.
static void many_blocks_sum_in_file_order(void **) {
    std::string t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s\r\n";
    struct Ref {
        long n = 0;
        double mean[4] = {}, m2[4][4] = {}, t = 0;
    };
    std::vector<Ref> ref(23);
    char row[160];
    const int rows = 120000; // ~5.5 MB: about twenty blocks
    for (int r = 0; r < rows; ++r) {
        const int pt = (r / 7) % 23; // runs of seven rows, each position revisited
        const double l[4] = {300 + pt + 0.01 * (r % 13), 301 - 0.001 * (r % 17), 302 + 0.02 * (r % 5), 303 + 0.1 * pt};
        const double ts = 0.01 * r;
        std::snprintf(row, sizeof row, "%d,%d,%d,0,%.3f,%.3f,%.3f,%.3f,%.2f", pt, 30 + 10 * (pt % 3), pt, l[0], l[1], l[2],
                      l[3], ts);
        t += row;
        if (r + 1 < rows) t += "\r\n";
        if (r % 9001 == 5) t += "\r\n# a comment between rows\r\n";
        // What the file says, as the reader converts it (the printed digits).
        double lv[4], tv;
        std::sscanf(row, "%*d,%*d,%*d,0,%lf,%lf,%lf,%lf,%lf", &lv[0], &lv[1], &lv[2], &lv[3], &tv);
        Ref &h = ref[size_t(pt)];
        const double n = double(++h.n);
        double dx[4];
        for (int c = 0; c < 4; ++c) {
            dx[c] = lv[c] - h.mean[c];
            h.mean[c] += dx[c] / n;
        }
        for (int a = 0; a < 4; ++a)
            for (int c = a; c < 4; ++c) h.m2[a][c] += dx[a] * (lv[c] - h.mean[c]);
        h.t += tv;
    }
    assert_true(t.size() > (size_t(5) << 20));
    TempCsv f(t);
    for (int from_file = 0; from_file < 2; ++from_file) {
        Dataset d;
        std::string err;
        if (!(from_file ? load_dataset(f.path, d, err) : parse_dataset(t, "m.csv", d, err))) fail_msg("%s", err.c_str());
        assert_int_equal(d.rows, rows);
        assert_int_equal(d.pos.size(), 23);
        for (size_t g = 0; g < d.pos.size(); ++g) {
            const Ref &h = ref[size_t(d.pos[g].point)];
            assert_int_equal(d.pos[g].n, h.n);
            for (int a = 0; a < 4; ++a) {
                if (d.pos[g].mean[a] != h.mean[a]) fail_msg("position %zu cable %d: mean %.17g, in turn %.17g", g, a,
                                                            d.pos[g].mean[a], h.mean[a]);
                for (int c = a; c < 4; ++c)
                    if (d.pos[g].cov[a][c] != h.m2[a][c] / double(h.n - 1)) fail_msg("position %zu: covariance differs", g);
            }
            assert_true(d.pos[g].t_s == h.t / double(h.n));
        }
        // Read again (for_each_sample): every row, in file order.
        size_t k = 0;
        bool in_order = true;
        assert_true(for_each_sample(d, [&](size_t g, const double *) {
            in_order = in_order && d.pos[g].point == long((k / 7) % 23);
            ++k;
        }, err));
        assert_int_equal(k, rows);
        assert_true(in_order);
    }
}

// Whichever block a fault is in, and whichever thread found its line's
// values, the error is the one a reading in turn meets first: its line and
// column, and an earlier fault of another kind (a reference that moved)
// before a later one (a value).
static void faults_in_later_blocks_name_their_line(void **) {
    std::vector<std::string> lines{"point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s"};
    char row[160];
    for (int r = 0; r < 100000; ++r) {
        const int pt = (r / 10) % 50;
        std::snprintf(row, sizeof row, "%d,%d,%d,0,%.3f,301,302,303,%.2f", pt, 30 + 10 * (pt % 5), pt,
                      300 + 0.001 * (r % 11), 0.01 * r);
        lines.push_back(row);
    }
    auto text = [&](const std::vector<std::string> &v) {
        std::string s;
        for (auto &l : v) s += l + "\n";
        return s;
    };
    struct Case {
        size_t line; // 1-based
        std::string with, where;
    };
    const std::vector<Case> cases{
        {60001, "7,40,7,0,300,301,302,303,1", ":60001:2: point 7 has x_ref 40"}, // 7 is at 50
        {70001, "7,50,7,0,300,301,302,303,oops", ":70001:9: t_s is not a finite number"},
        {80001, "7,50,7,0,300,301,302,abc,1", ":80001:8: l4 is not a finite number"},
        {90001, "7,50,7,0,300,301", ":90001:7: expected 9 fields"},
    };
    for (const auto &c : cases) {
        auto v = lines;
        v[c.line - 1] = c.with;
        Dataset d;
        std::string err;
        assert_false(parse_dataset(text(v), "late.csv", d, err));
        if (!strstr(err.c_str(), ("late.csv" + c.where).c_str())) fail_msg("error \"%s\" does not name \"%s\"", err.c_str(), c.where.c_str());
    }
    // Two faults: the first in the file is the one named, whichever kind.
    auto v = lines;
    v[80000] = cases[2].with; // line 80001, a value
    v[85000] = "7,40,7,0,300,301,302,303,1"; // line 85001, a moved reference
    Dataset d;
    std::string err;
    assert_false(parse_dataset(text(v), "two.csv", d, err));
    assert_non_null(strstr(err.c_str(), "two.csv:80001:8: l4"));
    v[80000] = lines[80000];
    v[60000] = "7,40,7,0,300,301,302,303,1"; // line 60001, a moved reference, before a value at 70001
    v[70000] = "7,50,7,0,300,301,302,abc,1";
    assert_false(parse_dataset(text(v), "two.csv", d, err));
    assert_non_null(strstr(err.c_str(), "two.csv:60001:2: point 7 has x_ref 40"));
}

// The resolution is the smallest step between distinct readings of a cable,
// whatever their order and repetitions; a cable with one value has none.
static void resolution_is_the_smallest_step(void **) {
    const char *t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n"
                    "1,30,0,0,100.03,200,300,400\n"
                    "1,30,0,0,100.00,200,300,400.5\n"
                    "2,30,5,0,100.03,200,300,401\n"
                    "2,30,5,0,100.01,200,300,400\n";
    Dataset d;
    std::string err;
    assert_true(parse_dataset(t, "r.csv", d, err));
    assert_true(d.resolution[0] == 100.01 - 100.00);
    assert_true(d.resolution[1] == 0.0 && d.resolution[2] == 0.0);
    assert_true(d.resolution[3] == 0.5);
}

// for_each_sample hands back every row's readings in file order with its
// position's index, from a file or from text.
static void samples_read_again_in_order(void **) {
    const std::string t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n"
                          "8,30,0,0,100,101,102,103\n"
                          "9,30,5,0,110,111,112,113\n"
                          "8,30,0,0,100.5,101,102,103\n";
    TempCsv f(t);
    Dataset a, b;
    std::string err;
    assert_true(parse_dataset(t, "t.csv", a, err));
    assert_true(load_dataset(f.path, b, err));
    for (const Dataset *d : {&a, &b}) {
        std::vector<std::pair<size_t, double>> seen;
        assert_true(for_each_sample(*d, [&](size_t g, const double *l) { seen.emplace_back(g, l[0]); }, err));
        assert_int_equal(seen.size(), 3);
        assert_true(seen[0] == std::make_pair(size_t(0), 100.0));
        assert_true(seen[1] == std::make_pair(size_t(1), 110.0));
        assert_true(seen[2] == std::make_pair(size_t(0), 100.5));
    }
    Dataset none;
    assert_false(for_each_sample(none, [](size_t, const double *) {}, err));
}

// A file replaced by rename after loading is still read through the
// descriptor opened; one rewritten in place is refused, naming where.
static void changed_file_is_refused(void **) {
    const std::string t = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n"
                          "1,30,0,0,100,101,102,103\n"
                          "2,30,5,0,110,111,112,113\n";
    TempCsv f(t);
    Dataset d;
    std::string err;
    assert_true(load_dataset(f.path, d, err));
    {
        TempCsv other("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n7,30,0,0,1,1,1,1\n");
        assert_int_equal(rename(other.path.c_str(), f.path.c_str()), 0);
        other.path = "/nonexistent-dir/x"; // renamed away: nothing to unlink
    }
    size_t rows = 0;
    assert_true(for_each_sample(d, [&](size_t, const double *) { ++rows; }, err));
    assert_int_equal(rows, 2);

    TempCsv g(t);
    Dataset e;
    assert_true(load_dataset(g.path, e, err));
    const int fd = open(g.path.c_str(), O_WRONLY | O_TRUNC);
    assert_true(fd >= 0);
    const std::string moved = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,101,102,103\n3,30,5,0,110,111,112,113\n";
    assert_int_equal(write(fd, moved.data(), moved.size()), ssize_t(moved.size()));
    close(fd);
    assert_false(for_each_sample(e, [](size_t, const double *) {}, err));
    const std::string where = g.path + ":3:1: the dataset changed since it was loaded";
    if (!strstr(err.c_str(), where.c_str())) fail_msg("error \"%s\" does not name \"%s\"", err.c_str(), where.c_str());

    const int fd2 = open(g.path.c_str(), O_WRONLY | O_TRUNC);
    assert_true(fd2 >= 0);
    const std::string other_value = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n1,30,0,0,100,101,102,103\n2,30,5,0,110,111,112,114\n";
    assert_int_equal(write(fd2, other_value.data(), other_value.size()), ssize_t(other_value.size()));
    close(fd2);
    assert_false(for_each_sample(e, [](size_t, const double *) {}, err));
    assert_non_null(strstr(err.c_str(), "the dataset changed since it was loaded"));
}

// The writer and the reader agree, value by value at the edges of the
// reader's rule: every row the writer accepts the reader reads, in the same
// count, and what it refuses is refused before anything of it is kept
// (around 0, 5000 and 10000 mm the file's four decimals decide, so the
// writer judges the value as printed). Time columns: the same on every row.
static void writer_accepts_exactly_what_the_reader_reads(void **) {
    const double edges[] = {0.0,     -0.0,      1e-5,      5e-5,      4999.99996, 5000.00004, 5000.00006,
                            -5000.00006, 9999.99996, 10000.00004, 10000.00006, 1e300,   NAN,       INFINITY,
                            -1.0,    150.0,     1e-300};
    const size_t n = sizeof edges / sizeof edges[0];
    char path[] = "/tmp/cdm_ds_agree_XXXXXX";
    const int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    for (int timed = 0; timed < 2; ++timed) {
        DatasetWriter w;
        std::string err;
        assert_true(w.open(path, {}, err));
        size_t accepted = 0;
        for (size_t a = 0; a < n; ++a)
            for (size_t b = 0; b < n; ++b) {
                // A point per (a, b): its reference never moves here.
                const long point = long(a * n + b);
                const double ref[3] = {edges[a], 0, 0}, len[4] = {150, edges[b], 150, 150};
                bool usage = false;
                if (w.add_row(point, ref, len, err, timed ? 0.001 * double(point) : NAN, &usage)) {
                    ++accepted;
                } else {
                    if (!usage) fail_msg("(%g, %g): refused as an I/O failure: %s", edges[a], edges[b], err.c_str());
                    if (!std::strstr(err.c_str(), ("point " + std::to_string(point)).c_str()))
                        fail_msg("\"%s\" does not name the point", err.c_str());
                }
            }
        assert_true(accepted > 0 && accepted < n * n);
        assert_true(w.commit(err));
        Dataset d;
        if (!load_dataset(path, d, err)) fail_msg("the reader refuses what the writer wrote: %s", err.c_str());
        assert_int_equal(d.rows, accepted);
    }
    unlink(path);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(groups_and_ignores),
        cmocka_unit_test(acquisition_order_per_position),
        cmocka_unit_test(errors_name_line_and_column),
        cmocka_unit_test(write_is_atomic),
        cmocka_unit_test(writer_accepts_exactly_what_the_reader_reads),
        cmocka_unit_test(test_dataset_duplicate_column_refused),
        cmocka_unit_test(test_dataset_utf8_bom_read),
        cmocka_unit_test(test_dataset_off_height_references),
        cmocka_unit_test(test_dataset_huge_field_not_echoed_whole),
        cmocka_unit_test(test_dataset_insane_magnitudes_refused),
        cmocka_unit_test(test_dataset_missing_file_is_io_failure),
        cmocka_unit_test(file_in_pieces_equals_whole_text),
        cmocka_unit_test(many_blocks_sum_in_file_order),
        cmocka_unit_test(faults_in_later_blocks_name_their_line),
        cmocka_unit_test(resolution_is_the_smallest_step),
        cmocka_unit_test(samples_read_again_in_order),
        cmocka_unit_test(changed_file_is_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
