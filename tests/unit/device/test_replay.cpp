// Replay: a sim session recorded through the sample callback (as `cdm
// record` does) plays back to the very same poses; pacing; corrupt files;
// the recorder (cdm_recorder_*) refusing what replay: would refuse.
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "cdm/cdm.h"
#include "device/device.h"
#include "device/protocol.h"
#include "device/recording/replay_format.h"
#include "test_util.h"

// cmocka last: its fail() macro must not meet the C++ headers.
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

namespace {

std::string tmp_path(const char *name) {
    return std::string("/tmp/cdm_test_replay_") + std::to_string(getpid()) + "_" + name;
}

struct Rec {
    std::mutex mu;
    std::vector<std::pair<uint64_t, std::vector<uint8_t>>> reports;
    std::map<uint32_t, cdm_pose> poses;
    size_t limit = 0;
};

void rec_cb(void *user, const cdm_sample *s) {
    auto *r = static_cast<Rec *>(user);
    std::lock_guard<std::mutex> lock(r->mu);
    if (r->limit && r->reports.size() >= r->limit) return;
    r->reports.emplace_back(s->raw->host_time_ns, std::vector<uint8_t>(s->report, s->report + s->report_len));
    r->poses[s->pose->sequence] = *s->pose;
}

// Records `n` reports of `uri` into `path`; returns the poses seen.
std::map<uint32_t, cdm_pose> record(const char *uri, const std::string &path, size_t n) {
    Rec rec;
    rec.limit = n;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = rec_cb;
    o.user = &rec;
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open_ex(uri, &o, &dev), CDM_OK);
    assert_true(cdm_test::wait_until([&] { std::lock_guard<std::mutex> l(rec.mu); return rec.reports.size() >= n; },
                                     20000));
    // The device-info report byte for byte, as `cdm record` takes it.
    uint8_t ib[256] = {cdm::proto::kDeviceInfoReportId};
    std::string err;
    const int info_len = dev->transport().get_feature(ib, sizeof ib, err);
    assert_int_equal(info_len, 128);
    cdm_close(dev);
    cdm::replay::Writer w;
    assert_int_equal(w.open(path, ib, size_t(info_len), err), CDM_OK);
    for (const auto &x : rec.reports) assert_int_equal(w.write(x.first, x.second.data(), x.second.size(), err), CDM_OK);
    assert_int_equal(w.close(err), CDM_OK);
    return rec.poses;
}

void test_round_trip(void **) {
    const std::string path = tmp_path("rt.cdmrec");
    const auto original = record("sim:?realtime=0&seed=11&motion=random", path, 2000);
    Rec back;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = rec_cb;
    o.user = &back;
    cdm_device *dev = nullptr;
    const std::string uri = "replay:" + path + "?speed=0";
    assert_int_equal(cdm_open_ex(uri.c_str(), &o, &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM; }, 10000));
    assert_true(p.flags & CDM_POSE_END_OF_STREAM);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    cdm_get_info(dev, &info);
    assert_string_equal(info.transport, "replay");
    char buf[64];
    size_t len;
    assert_int_equal(cdm_device_calibration_read(dev, buf, sizeof buf, &len), CDM_ERR_UNSUPPORTED);
    assert_int_equal(cdm_device_calibration_write(dev, "x", 1), CDM_ERR_UNSUPPORTED);
    cdm_close(dev);
    assert_int_equal(back.poses.size(), original.size());
    for (const auto &kv : original) {
        const auto it = back.poses.find(kv.first);
        assert_true(it != back.poses.end());
        const cdm_pose &a = kv.second, &b = it->second;
        // The same bytes through the same parser and model: bit-identical.
        assert_memory_equal(a.position, b.position, sizeof a.position);
        assert_memory_equal(a.orientation, b.orientation, sizeof a.orientation);
        assert_true(a.grip == b.grip);
        assert_int_equal(a.buttons, b.buttons);
        assert_true(a.device_time_us == b.device_time_us);
    }
    std::remove(path.c_str());
}

void test_pacing(void **) {
    const std::string path = tmp_path("pace.cdmrec");
    // 300 reports at 1 kHz: 0.3 s of device time.
    record("sim:?realtime=1&seed=2&motion=circle", path, 300);
    auto play = [&](const char *opt) {
        cdm_device *dev = nullptr;
        const std::string uri = "replay:" + path + opt;
        const auto t0 = std::chrono::steady_clock::now();
        assert_int_equal(cdm_open(uri.c_str(), &dev), CDM_OK);
        cdm_pose p{};
        p.struct_size = sizeof p;
        assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM; }, 10000));
        cdm_close(dev);
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    const double paced = play(""), fast = play("?speed=0"), double_speed = play("?speed=2");
    print_message("replay of 0.3 s: speed=1 %.3f s, speed=2 %.3f s, speed=0 %.3f s\n", paced, double_speed, fast);
    assert_true(paced > 0.27 && paced < 1.0);
    assert_true(double_speed > 0.13 && double_speed < paced);
    assert_true(fast < 0.2);
    std::remove(path.c_str());
}

void expect_parse_error(const std::string &path, const char *needle) {
    cdm_device *dev = nullptr;
    const std::string uri = "replay:" + path;
    const int rc = cdm_open(uri.c_str(), &dev);
    if (rc != CDM_ERR_PARSE) fail_msg("%s: %d (%s)", uri.c_str(), rc, cdm_thread_error());
    assert_null(dev);
    if (!std::strstr(cdm_thread_error(), needle) || !std::strstr(cdm_thread_error(), path.c_str()))
        fail_msg("detail \"%s\" should name the file and \"%s\"", cdm_thread_error(), needle);
}

void test_corrupt_files(void **) {
    const std::string good = tmp_path("good.cdmrec"), bad = tmp_path("bad.cdmrec");
    record("sim:?realtime=0&motion=still", good, 5);
    std::vector<uint8_t> bytes;
    {
        std::FILE *f = std::fopen(good.c_str(), "rb");
        int c;
        while ((c = std::fgetc(f)) != EOF) bytes.push_back(uint8_t(c));
        std::fclose(f);
    }
    assert_int_equal(bytes.size(), 12 + 128 + 5 * (10 + 64));
    auto write = [&](const std::vector<uint8_t> &b) {
        std::FILE *f = std::fopen(bad.c_str(), "wb");
        std::fwrite(b.data(), 1, b.size(), f);
        std::fclose(f);
    };
    // Cut inside the header or device info: refused, with the byte offset.
    // Cut anywhere after (a killed recorder): every complete record plays,
    // the tail is dropped with a warning and counted in the stats.
    for (size_t cut = 1; cut < bytes.size(); ++cut) {
        write(std::vector<uint8_t>(bytes.begin(), bytes.begin() + cut));
        cdm_device *dev = nullptr;
        const std::string uri = "replay:" + bad + "?speed=0";
        const int rc = cdm_open(uri.c_str(), &dev);
        if (cut < 140) {
            if (rc != CDM_ERR_PARSE) fail_msg("cut at %zu: %d", cut, rc);
            assert_non_null(std::strstr(cdm_thread_error(), "byte"));
            continue;
        }
        if (rc != CDM_OK) fail_msg("cut at %zu: %d (%s)", cut, rc, cdm_thread_error());
        const size_t tail = (cut - 140) % 74, complete = (cut - 140) / 74;
        cdm_stats st{};
        st.struct_size = sizeof st;
        assert_int_equal(cdm_get_stats(dev, &st), CDM_OK);
        assert_int_equal(st.replay_truncated_bytes, tail);
        char text[512];
        cdm_device_error(dev, text, sizeof text);
        if (tail) assert_non_null(std::strstr(text, "trailing bytes dropped"));
        cdm_pose p{};
        p.struct_size = sizeof p;
        assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM; }, 5000));
        assert_int_equal(p.host_sequence, complete);
        // An ended replay never hands out the zero quaternion.
        assert_true(p.orientation[0] != 0 || p.orientation[1] != 0 || p.orientation[2] != 0 || p.orientation[3] != 0);
        cdm_close(dev);
    }
    auto b = bytes;
    b[0] = 'X';
    write(b);
    expect_parse_error(bad, "magic");
    // A jig CSV given to replay: by mistake is said to be a text file, and
    // where it belongs.
    {
        const std::string csv = "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n0,30,0,0,1,2,3,4\n";
        write(std::vector<uint8_t>(csv.begin(), csv.end()));
        expect_parse_error(bad, "a text file, not a cdm recording");
        expect_parse_error(bad, "cdm calib diagnose");
    }
    b = bytes;
    b[8] = 2;
    write(b);
    expect_parse_error(bad, "version");
    b = bytes;
    b[140 + 8] = 0; // first record length 0
    b[140 + 9] = 0;
    write(b);
    expect_parse_error(bad, "byte 148");
    b = bytes;
    b[140 + 74 + 7] = 0; // second record's host time far before the first's
    b[140 + 7] = 0x7F;
    write(b);
    expect_parse_error(bad, "backwards");
    b = bytes;
    b[12 + 6] = 0; // adc_bits 0 in the device-info report
    write(b);
    expect_parse_error(bad, "adc_bits");
    std::remove(good.c_str());
    std::remove(bad.c_str());
}

// Records of the format's maximum size (1024 bytes) overflowed a 512-byte
// read buffer into a permanent DISCONNECTED.
void test_replay_record_of_1024_bytes_plays(void **) {
    const std::string good = tmp_path("small.cdmrec"), big = tmp_path("big.cdmrec");
    record("sim:?realtime=0&motion=still", good, 1);
    cdm::replay::File f;
    std::string err;
    assert_int_equal(cdm::replay::load(good, f, err), CDM_OK);
    std::vector<uint8_t> report(cdm::replay::kMaxReport, 0); // a longer report of a newer firmware
    std::memcpy(report.data(), f.bytes.data() + f.records[0].offset, f.records[0].length);
    cdm::replay::Writer w;
    assert_int_equal(w.open(big, f.info.data(), f.info.size(), err), CDM_OK);
    for (int i = 0; i < 3; ++i) {
        cdm::proto::put_u32(report.data() + 4, uint32_t(i + 1)); // sequence
        assert_int_equal(w.write(uint64_t(i) * 1000000, report.data(), report.size(), err), CDM_OK);
    }
    assert_int_equal(w.close(err), CDM_OK);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open(("replay:" + big + "?speed=0").c_str(), &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM; }, 5000));
    assert_int_equal(p.host_sequence, 3);
    assert_false(p.flags & CDM_POSE_DISCONNECTED);
    cdm_close(dev);
    std::remove(good.c_str());
    std::remove(big.c_str());
}

void expect_open_error(const std::string &uri, int code, const char *needle) {
    cdm_device *dev = nullptr;
    const auto t0 = std::chrono::steady_clock::now();
    const int rc = cdm_open(uri.c_str(), &dev);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    print_message("%s -> %d \"%s\"\n", uri.c_str(), rc, cdm_thread_error());
    if (rc != code) fail_msg("%s: %d, expected %d (%s)", uri.c_str(), rc, code, cdm_thread_error());
    assert_null(dev);
    if (!std::strstr(cdm_thread_error(), needle)) fail_msg("\"%s\" lacks \"%s\"", cdm_thread_error(), needle);
    assert_true(s < 2.0); // never a hang
}

// speed=1e-300 overflowed a double-to-integer conversion (undefined).
void test_replay_speed_out_of_range_refused(void **) {
    const std::string good = tmp_path("speed.cdmrec");
    record("sim:?realtime=0&motion=still", good, 2);
    expect_open_error("replay:" + good + "?speed=1e-300", CDM_ERR_INVALID_ARG, "0.001");
    expect_open_error("replay:" + good + "?speed=1e300", CDM_ERR_INVALID_ARG, "speed");
    expect_open_error("replay:" + good + "?speed=nan", CDM_ERR_INVALID_ARG, "speed");
    std::remove(good.c_str());
}

// replay:DIR was an "internal error", a FIFO without a writer hung, an
// unreadable file's message lacked its reason.
void test_replay_special_files_refused(void **) {
    expect_open_error("replay:/tmp", CDM_ERR_INVALID_ARG, "a directory");
    const std::string fifo = tmp_path("fifo");
    assert_int_equal(mkfifo(fifo.c_str(), 0600), 0);
    expect_open_error("replay:" + fifo, CDM_ERR_INVALID_ARG, "a FIFO");
    std::remove(fifo.c_str());
    expect_open_error("replay:/dev/zero", CDM_ERR_INVALID_ARG, "not a regular file");
    expect_open_error("replay:" + tmp_path("missing"), CDM_ERR_NO_DEVICE, "No such file");
    if (geteuid() != 0) {
        const std::string locked = tmp_path("locked.cdmrec");
        record("sim:?realtime=0&motion=still", locked, 1);
        chmod(locked.c_str(), 0);
        expect_open_error("replay:" + locked, CDM_ERR_IO, "Permission denied");
        std::remove(locked.c_str());
    } else {
        print_message("running as root: the unreadable-file case cannot be made\n");
    }
}

// A recorder killed by SIGKILL keeps every record it wrote: the writer hands
// each to the kernel at once, and the reader plays them all.
void test_replay_recording_survives_sigkill(void **) {
    const std::string good = tmp_path("k.cdmrec"), killed = tmp_path("killed.cdmrec");
    record("sim:?realtime=0&motion=still", good, 1);
    cdm::replay::File f;
    std::string err;
    assert_int_equal(cdm::replay::load(good, f, err), CDM_OK);
    const pid_t pid = fork();
    if (pid == 0) {
        cdm::replay::Writer w;
        std::string e;
        if (w.open(killed, f.info.data(), f.info.size(), e) != CDM_OK) _exit(2);
        std::vector<uint8_t> rep(f.bytes.begin() + long(f.records[0].offset),
                                 f.bytes.begin() + long(f.records[0].offset + f.records[0].length));
        for (uint32_t i = 0; i < 50; ++i) {
            cdm::proto::put_u32(rep.data() + 4, i + 1);
            if (w.write(uint64_t(i) * 1000000, rep.data(), rep.size(), e) != CDM_OK) _exit(3);
        }
        raise(SIGKILL); // no close, no flush, no destructor
        _exit(4);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    assert_true(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
    cdm_device *dev = nullptr;
    assert_int_equal(cdm_open(("replay:" + killed + "?speed=0").c_str(), &dev), CDM_OK);
    cdm_pose p{};
    p.struct_size = sizeof p;
    assert_true(cdm_test::wait_until([&] { return cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM; }, 5000));
    assert_int_equal(p.host_sequence, 50);
    cdm_close(dev);
    std::remove(good.c_str());
    std::remove(killed.c_str());
}

// A full disk (here: a file-size limit, same failure path as ENOSPC) keeps
// every complete record and names the errno. An existing path (/dev/full,
// an earlier recording) is refused: the writer only creates new files.
void test_replay_writer_full_disk_keeps_records(void **) {
    const std::string good = tmp_path("fd.cdmrec"), out = tmp_path("full.cdmrec");
    record("sim:?realtime=0&motion=still", good, 1);
    cdm::replay::File f;
    std::string err;
    assert_int_equal(cdm::replay::load(good, f, err), CDM_OK);
    {
        cdm::replay::Writer w;
        assert_int_equal(w.open("/dev/full", f.info.data(), f.info.size(), err), CDM_ERR_IO);
        assert_non_null(std::strstr(err.c_str(), "File exists"));
        assert_int_equal(w.open(good, f.info.data(), f.info.size(), err), CDM_ERR_IO);
        assert_non_null(std::strstr(err.c_str(), "not writing over an existing file"));
    }
    const pid_t pid = fork();
    if (pid == 0) {
        signal(SIGXFSZ, SIG_IGN);
        rlimit lim{1000, 1000}; // header 140 + 11 records of 74 = 954; the 12th does not fit
        setrlimit(RLIMIT_FSIZE, &lim);
        cdm::replay::Writer w;
        std::string e;
        if (w.open(out, f.info.data(), f.info.size(), e) != CDM_OK) _exit(2);
        const uint8_t *rep = f.bytes.data() + f.records[0].offset;
        int rc = CDM_OK;
        uint32_t i = 0;
        for (; i < 100 && rc == CDM_OK; ++i) rc = w.write(uint64_t(i) * 1000000, rep, f.records[0].length, e);
        if (rc != CDM_ERR_IO || i != 12 || e.find("File too large") == std::string::npos ||
            e.find("11 records") == std::string::npos)
            _exit(5);
        if (w.write(0, rep, f.records[0].length, e) != CDM_ERR_IO) _exit(6); // stays failed
        w.close(e);
        _exit(0);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    assert_true(WIFEXITED(status));
    assert_int_equal(WEXITSTATUS(status), 0);
    cdm::replay::File back;
    assert_int_equal(cdm::replay::load(out, back, err), CDM_OK);
    assert_int_equal(back.records.size(), 11);
    assert_int_equal(back.truncated_bytes, 0);
    std::remove(good.c_str());
    std::remove(out.c_str());
}

// The sim's device-info report and one of its input reports, as `cdm
// record` takes them.
void sim_reports(std::vector<uint8_t> &info, std::vector<uint8_t> &report) {
    const std::string good = tmp_path("one.cdmrec");
    record("sim:?realtime=0&motion=still", good, 1);
    cdm::replay::File f;
    std::string err;
    assert_int_equal(cdm::replay::load(good, f, err), CDM_OK);
    info = f.info;
    report.assign(f.bytes.begin() + long(f.records[0].offset),
                  f.bytes.begin() + long(f.records[0].offset + f.records[0].length));
    std::remove(good.c_str());
}

void expect_thread_error(const char *needle) {
    if (!std::strstr(cdm_thread_error(), needle)) fail_msg("\"%s\" lacks \"%s\"", cdm_thread_error(), needle);
}

// A host time before the previous record's is refused when written, naming
// both, and writes nothing: replay: refuses such a file whole ("host time
// goes backwards"), so the recording would be lost. Equal
// times are fine. The recording goes on and plays, in both replayable
// formats; the CSV keeps the same order.
void test_recorder_refuses_time_going_back(void **) {
    std::vector<uint8_t> info, rep;
    sim_reports(info, rep);
    for (const char *ext : {".cdmrec", ".mcap"}) {
        const std::string path = tmp_path("back") + ext;
        cdm_recorder *rec = nullptr;
        assert_int_equal(cdm_recorder_open(path.c_str(), info.data(), info.size(), &rec), CDM_OK);
        assert_int_equal(cdm_recorder_write(rec, 2000, rep.data(), rep.size()), CDM_OK);
        assert_int_equal(cdm_recorder_write(rec, 1000, rep.data(), rep.size()), CDM_ERR_INVALID_ARG);
        expect_thread_error("host time 1000 ns");
        expect_thread_error("2000 ns");
        assert_int_equal(cdm_recorder_write(rec, 2000, rep.data(), rep.size()), CDM_OK);
        assert_int_equal(cdm_recorder_write(rec, 3000, rep.data(), rep.size()), CDM_OK);
        assert_int_equal(cdm_recorder_close(rec), CDM_OK);
        cdm::replay::File f;
        std::string err;
        if (cdm::replay::load(path, f, err) != CDM_OK) fail_msg("%s: %s", ext, err.c_str());
        assert_int_equal(f.records.size(), 3);
        assert_true(f.records[0].host_ns == 2000 && f.records[1].host_ns == 2000 && f.records[2].host_ns == 3000);
        cdm_device *dev = nullptr;
        if (cdm_open(("replay:" + path + "?speed=0").c_str(), &dev) != CDM_OK)
            fail_msg("%s: %s", ext, cdm_thread_error());
        cdm_close(dev);
        std::remove(path.c_str());
    }
    const std::string csv = tmp_path("back.csv");
    cdm_recorder *rec = nullptr;
    assert_int_equal(cdm_recorder_open(csv.c_str(), info.data(), info.size(), &rec), CDM_OK);
    cdm_raw raw{};
    raw.struct_size = sizeof raw;
    cdm_pose pose{};
    pose.struct_size = sizeof pose;
    pose.orientation[0] = 1;
    cdm_sample s{};
    s.struct_size = sizeof s;
    s.report = rep.data();
    s.report_len = uint32_t(rep.size());
    s.raw = &raw;
    s.pose = &pose;
    s.source_time_ns = 5000;
    assert_int_equal(cdm_recorder_write_sample(rec, &s), CDM_OK);
    s.source_time_ns = 4000;
    assert_int_equal(cdm_recorder_write_sample(rec, &s), CDM_ERR_INVALID_ARG);
    expect_thread_error("host time 4000 ns");
    assert_int_equal(cdm_recorder_close(rec), CDM_OK);
    std::remove(csv.c_str());
}

// The device-info report is checked when the recorder opens, by the parser
// replay: checks it with, so a recording replay: would refuse is never
// started (e.g. 128 bytes of 0x55 as the info report); the file is not
// created. A zero length is an empty report, not a NULL one.
void test_recorder_refuses_a_bad_device_info(void **) {
    std::vector<uint8_t> info, rep;
    sim_reports(info, rep);
    std::vector<uint8_t> junk(128, 0x55), version = info;
    version[1] = 9;
    for (const char *ext : {".cdmrec", ".mcap", ".csv"}) {
        const std::string path = tmp_path("info") + ext;
        cdm_recorder *rec = nullptr;
        assert_int_equal(cdm_recorder_open(path.c_str(), junk.data(), junk.size(), &rec), CDM_ERR_INVALID_ARG);
        expect_thread_error("wrong report ID");
        expect_thread_error("0x55");
        assert_null(rec);
        assert_int_equal(cdm_recorder_open(path.c_str(), info.data(), 5, &rec), CDM_ERR_INVALID_ARG);
        expect_thread_error("short report");
        expect_thread_error("5 bytes");
        assert_int_equal(cdm_recorder_open(path.c_str(), version.data(), version.size(), &rec), CDM_ERR_INVALID_ARG);
        expect_thread_error("wrong protocol version");
        assert_int_equal(cdm_recorder_open(path.c_str(), info.data(), 0, &rec), CDM_ERR_INVALID_ARG);
        expect_thread_error("info_report is empty");
        assert_int_equal(cdm_recorder_open(path.c_str(), nullptr, info.size(), &rec), CDM_ERR_INVALID_ARG);
        expect_thread_error("info_report is NULL");
        assert_int_equal(::access(path.c_str(), F_OK), -1); // nothing created
        assert_int_equal(cdm_recorder_open(path.c_str(), info.data(), info.size(), &rec), CDM_OK);
        assert_int_equal(cdm_recorder_close(rec), CDM_OK);
        std::remove(path.c_str());
    }
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_pacing),
        cmocka_unit_test(test_corrupt_files),
        cmocka_unit_test(test_replay_record_of_1024_bytes_plays),
        cmocka_unit_test(test_replay_speed_out_of_range_refused),
        cmocka_unit_test(test_replay_special_files_refused),
        cmocka_unit_test(test_replay_recording_survives_sigkill),
        cmocka_unit_test(test_replay_writer_full_disk_keeps_records),
        cmocka_unit_test(test_recorder_refuses_time_going_back),
        cmocka_unit_test(test_recorder_refuses_a_bad_device_info),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
