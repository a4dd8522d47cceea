// Replay: a sim session recorded through the sample callback (as `cdm
// record` does) plays back to the very same poses; pacing; corrupt files.
#include <unistd.h>

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
#include "device/replay_format.h"
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
    // Cut anywhere but on a record boundary: refused, with the byte offset.
    for (size_t cut = 1; cut < bytes.size(); ++cut) {
        const bool boundary = cut >= 140 && (cut - 140) % 74 == 0;
        write(std::vector<uint8_t>(bytes.begin(), bytes.begin() + cut));
        cdm_device *dev = nullptr;
        const std::string uri = "replay:" + bad;
        const int rc = cdm_open(uri.c_str(), &dev);
        if (boundary) {
            assert_int_equal(rc, CDM_OK);
            cdm_close(dev);
        } else {
            if (rc != CDM_ERR_PARSE) fail_msg("cut at %zu: %d", cut, rc);
            assert_non_null(std::strstr(cdm_thread_error(), "byte"));
        }
    }
    auto b = bytes;
    b[0] = 'X';
    write(b);
    expect_parse_error(bad, "magic");
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

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_pacing),
        cmocka_unit_test(test_corrupt_files),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
