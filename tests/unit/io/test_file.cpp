// io::read_file and io::write_file_atomic against special files, hostile
// paths and a full disk.
#include <dirent.h>
#include <fcntl.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "io/file.h"

extern "C" {
#include <cmocka.h>
}

using namespace cdm::io;

namespace {
std::string g_dir;
std::vector<std::string> g_made; // removed when every test passed (kept to look at otherwise)

std::string tmpdir() {
    char t[] = "/tmp/cdm_io_XXXXXX";
    assert_non_null(mkdtemp(t));
    g_made.push_back(t);
    return t;
}
void put(const std::string &p, const std::string &s) {
    int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    assert_true(fd >= 0);
    assert_int_equal(::write(fd, s.data(), s.size()), ssize_t(s.size()));
    ::close(fd);
}
std::string get(const std::string &p) {
    std::string s, e;
    assert_true(read_file(p, 1 << 20, s, e));
    return s;
}
// Entries of a directory other than . and ..: a temporary left behind shows here.
int entries(const std::string &d) {
    DIR *dp = opendir(d.c_str());
    int n = 0;
    while (auto *e = readdir(dp))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) ++n;
    closedir(dp);
    return n;
}
void expect_has(const std::string &err, const char *what) {
    if (err.find(what) == std::string::npos) fail_msg("error \"%s\" lacks \"%s\"", err.c_str(), what);
}
} // namespace

static void test_read_refuses_directory(void **) {
    std::string s, e;
    assert_false(read_file(g_dir, 100, s, e, "dataset"));
    expect_has(e, (g_dir + ": the dataset is a directory").c_str());
}

static void test_read_refuses_fifo_without_hang(void **) {
    const std::string f = g_dir + "/fifo";
    assert_int_equal(mkfifo(f.c_str(), 0600), 0);
    std::string s, e;
    const auto t0 = std::chrono::steady_clock::now();
    assert_false(read_file(f, 100, s, e)); // no writer: a blocking open would hang here forever
    assert_true(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(2));
    expect_has(e, "FIFO");
    unlink(f.c_str());
}

static void test_read_refuses_dev_zero(void **) {
    std::string s, e;
    assert_false(read_file("/dev/zero", 1 << 20, s, e, "device description"));
    expect_has(e, "/dev/zero: the device description is a character device, not a regular file");
}

static void test_read_refuses_socket(void **) {
    const std::string p = g_dir + "/sock";
    int fd = socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strncpy(a.sun_path, p.c_str(), sizeof a.sun_path - 1);
    assert_int_equal(bind(fd, reinterpret_cast<sockaddr *>(&a), sizeof a), 0);
    std::string s, e;
    assert_false(read_file(p, 100, s, e));
    // open(2) of a socket fails with ENXIO before fstat: either way the path and the reason are named.
    expect_has(e, p.c_str());
    close(fd);
    unlink(p.c_str());
}

static void test_read_missing_names_strerror(void **) {
    std::string s, e;
    assert_false(read_file(g_dir + "/none.json", 100, s, e, "calibration"));
    expect_has(e, "none.json: cannot open the calibration: No such file or directory");
}

static void test_read_size_cap(void **) {
    const std::string p = g_dir + "/big";
    put(p, std::string(1001, 'x'));
    std::string s, e;
    assert_false(read_file(p, 1000, s, e));
    expect_has(e, "1001 bytes, more than the 1000-byte limit");
    assert_true(read_file(p, 1001, s, e));
    assert_int_equal(s.size(), 1001);
    unlink(p.c_str());
}

static void test_write_replaces_and_leaves_no_temporary(void **) {
    const std::string d = tmpdir(), p = d + "/out.json";
    put(p, "old");
    std::string e;
    assert_true(write_file_atomic(p, "new", {}, e));
    assert_string_equal(get(p).c_str(), "new");
    assert_int_equal(entries(d), 1);
}

static void test_write_symlink_target_replaces_link_not_victim(void **) {
    const std::string d = tmpdir(), victim = d + "/victim", link = d + "/out";
    put(victim, "precious");
    assert_int_equal(symlink(victim.c_str(), link.c_str()), 0);
    std::string e;
    assert_true(write_file_atomic(link, "new", {}, e));
    assert_string_equal(get(victim).c_str(), "precious"); // the write went to the link's name, not through it
    struct stat st;
    assert_int_equal(lstat(link.c_str(), &st), 0);
    assert_true(S_ISREG(st.st_mode));
}

static void test_write_ignores_planted_fixed_tmp_link(void **) {
    // A link planted at X.tmp (a fixed temporary name) must not be followed.
    const std::string d = tmpdir(), victim = d + "/victim", out = d + "/out";
    put(victim, "precious");
    assert_int_equal(symlink(victim.c_str(), (out + ".tmp").c_str()), 0);
    std::string e;
    assert_true(write_file_atomic(out, "new", {}, e));
    assert_string_equal(get(victim).c_str(), "precious");
    assert_string_equal(get(out).c_str(), "new");
}

static void test_write_refuses_device_node(void **) {
    std::string e;
    assert_false(write_file_atomic("/dev/null", "x", {}, e));
    expect_has(e, "/dev/null: refusing to write over a character device");
    struct stat st;
    assert_int_equal(stat("/dev/null", &st), 0);
    assert_true(S_ISCHR(st.st_mode));
    // through a link too
    const std::string d = tmpdir(), link = d + "/out";
    assert_int_equal(symlink("/dev/null", link.c_str()), 0);
    assert_false(write_file_atomic(link, "x", {}, e));
    expect_has(e, "character device");
    assert_int_equal(entries(d), 1);
}

static void test_write_refuses_directory_and_fifo(void **) {
    const std::string d = tmpdir(), sub = d + "/sub", fifo = d + "/fifo";
    assert_int_equal(mkdir(sub.c_str(), 0755), 0);
    assert_int_equal(mkfifo(fifo.c_str(), 0600), 0);
    std::string e;
    assert_false(write_file_atomic(sub, "x", {}, e));
    expect_has(e, "a directory");
    assert_false(write_file_atomic(fifo, "x", {}, e));
    expect_has(e, "FIFO");
    assert_int_equal(entries(d), 2);
}

static void test_write_refuses_own_input_any_spelling(void **) {
    const std::string d = tmpdir(), in = d + "/data.csv", link = d + "/alias.csv";
    put(in, "input");
    assert_int_equal(symlink(in.c_str(), link.c_str()), 0);
    std::string e;
    // another spelling of the same path, and a link to it: both the same st_dev/st_ino
    assert_false(write_file_atomic(d + "/./data.csv", "x", {in}, e));
    expect_has(e, "an input of this command");
    assert_false(write_file_atomic(d + "//data.csv", "x", {link}, e));
    expect_has(e, "an input of this command");
    assert_false(write_file_atomic(link, "x", {d + "/../" + d.substr(5) + "/data.csv"}, e));
    expect_has(e, "an input of this command");
    assert_string_equal(get(in).c_str(), "input");
    assert_int_equal(entries(d), 2);
}

static void test_write_unwritable_dir_keeps_nothing(void **) {
    std::string e;
    assert_false(write_file_atomic("/nonexistent-dir/out.json", "x", {}, e));
    expect_has(e, "cannot create a temporary file in /nonexistent-dir: No such file or directory");
    // /proc refuses new files even to root
    assert_false(write_file_atomic("/proc/cdm_out.json", "x", {}, e));
    expect_has(e, "/proc/cdm_out.json");
}

static void test_write_full_disk_says_enospc_and_keeps_old(void **) {
    const std::string d = tmpdir();
    if (mount("tmpfs", d.c_str(), "tmpfs", 0, "size=64k") != 0) {
        // Not root or no CAP_SYS_ADMIN in this sandbox: the ENOSPC path cannot be produced.
        rmdir(d.c_str());
        skip();
    }
    const std::string p = d + "/cal.json";
    put(p, "old calibration");
    std::string e;
    assert_false(write_file_atomic(p, std::string(256 * 1024, 'x'), {}, e));
    expect_has(e, "No space left on device");
    assert_string_equal(get(p).c_str(), "old calibration");
    assert_int_equal(entries(d), 1); // no temporary left
    umount(d.c_str());
    rmdir(d.c_str());
}

static void test_atomic_file_abandoned_leaves_nothing(void **) {
    const std::string d = tmpdir(), p = d + "/out";
    put(p, "old");
    std::string e;
    {
        AtomicFile f;
        assert_true(f.open(p, {}, e));
        assert_true(f.write("half", e));
        assert_int_equal(entries(d), 2);
    } // destroyed without commit: the computation failed
    assert_int_equal(entries(d), 1);
    assert_string_equal(get(p).c_str(), "old");
}

int main(void) {
    g_dir = tmpdir();
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_read_refuses_directory),
        cmocka_unit_test(test_read_refuses_fifo_without_hang),
        cmocka_unit_test(test_read_refuses_dev_zero),
        cmocka_unit_test(test_read_refuses_socket),
        cmocka_unit_test(test_read_missing_names_strerror),
        cmocka_unit_test(test_read_size_cap),
        cmocka_unit_test(test_write_replaces_and_leaves_no_temporary),
        cmocka_unit_test(test_write_symlink_target_replaces_link_not_victim),
        cmocka_unit_test(test_write_ignores_planted_fixed_tmp_link),
        cmocka_unit_test(test_write_refuses_device_node),
        cmocka_unit_test(test_write_refuses_directory_and_fifo),
        cmocka_unit_test(test_write_refuses_own_input_any_spelling),
        cmocka_unit_test(test_write_unwritable_dir_keeps_nothing),
        cmocka_unit_test(test_write_full_disk_says_enospc_and_keeps_old),
        cmocka_unit_test(test_atomic_file_abandoned_leaves_nothing),
    };
    const int failed = cmocka_run_group_tests(tests, NULL, NULL);
    if (failed == 0)
        for (auto &d : g_made) {
            std::error_code ec;
            std::filesystem::remove_all(d, ec);
        }
    return failed;
}
