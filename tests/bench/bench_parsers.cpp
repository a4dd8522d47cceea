// Is every parser that takes outside input linear in its input, up to the
// size its cap allows? Each parser is fed the input shapes most likely to
// find a super-linear path (an object of millions of keys, a dataset whose
// every row is a new position, a URI of thousands of options, an MCAP file
// of millions of messages...) at a quarter, a half and the whole of its
// cap, and the time of each size is printed with the ratio
//
//   r = t(cap) / t(cap / 2)
//
// which is 2 for a linear parser (n log n gives a little more) and 4 for a
// quadratic one. A ratio above 3 is printed as "super-linear" and makes the
// exit status 1. Timings on a shared machine wobble, so each size is timed
// --repeat times and the fastest kept. Not run by ctest (docs/reliability.md,
// "Parsers", gives the table); `--scale F` shrinks every cap by F (the smoke
// run in ctest uses it with --check-only, which checks each parser's
// outcome on each shape and times nothing).
//
//   ./build/tests/bench/bench_parsers [--scale F] [--repeat N] [--only NAME] [--dir DIR] [--check-only]
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "calib/dataset/dataset.h"
#include "device/protocol.h"
#include "device/recording/recording.h"
#include "device/recording/replay_format.h"
#include "device/sim/faults.h"
#include "device/transport.h"
#include "io/device_json.h"
#include "io/file.h"
#include "io/json.h"
#include "io/mcap.h"

namespace {

using cdm::proto::DeviceInfoReport;

double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

// One parser on one input shape. make(n) builds an input of about n bytes
// (in memory, or a file under dir); parse() returns whether it was accepted.
struct Case {
    const char *name;
    const char *what;
    size_t cap;
    bool accepted; // the parser's expected outcome on this shape
    bool file;     // make() returns a file's path (removed after the timing)
    std::function<std::string(size_t)> make;
    std::function<bool(const std::string &, std::string &)> parse;
};

std::string g_dir = "/tmp";

std::string repeat_until(const std::string &head, const std::function<std::string(size_t)> &item,
                         const std::string &sep, const std::string &tail, size_t n) {
    std::string s = head;
    s.reserve(n + 64);
    for (size_t k = 0;; ++k) {
        const std::string next = (k ? sep : std::string()) + item(k);
        if (s.size() + next.size() + tail.size() > n) break; // never past the cap
        s += next;
    }
    return s + tail;
}

DeviceInfoReport bench_info() {
    DeviceInfoReport r;
    r.fw_major = 1;
    std::strcpy(r.serial, "BENCH0001");
    r.report_rate_hz = 1000.0f;
    r.pot_scale_mm = {0.01f, 0.01f, 0.01f, 0.01f};
    r.a_mm = r.b_mm = 150.0f;
    r.m_mm = 30.0f;
    r.hall_closed = 2600;
    r.hall_open = 1400;
    r.grip_open_rad = 0.6f;
    return r;
}

std::vector<uint8_t> info_bytes() {
    std::vector<uint8_t> b(cdm::proto::kDeviceInfoReportSize);
    cdm::proto::serialize_device_info(bench_info(), b.data());
    return b;
}

std::vector<uint8_t> input_report(uint32_t k) {
    cdm::proto::InputReport r;
    r.sequence = k;
    r.device_time_us = uint64_t(k) * 1000;
    r.pot_adc = {10000, 10000, 10000, 10000};
    r.quat_q14 = {16384, 0, 0, 0};
    std::vector<uint8_t> b(cdm::proto::kInputReportSize);
    cdm::proto::serialize_input(r, b.data());
    return b;
}

void put_le(std::string &s, uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) s.push_back(char((v >> (8 * i)) & 0xFF));
}

// The replay format (docs/protocol.md, "Replay files") built in memory.
std::string replay_bytes(size_t n) {
    const auto info = info_bytes();
    const auto rep = input_report(0);
    std::string s(cdm::replay::kMagic, 8);
    put_le(s, cdm::replay::kVersion, 2);
    put_le(s, info.size(), 2);
    s.append(info.begin(), info.end());
    s.reserve(n + 128);
    for (uint32_t k = 0; s.size() + 10 + rep.size() <= n; ++k) {
        put_le(s, uint64_t(k) * 1000000, 8);
        put_le(s, rep.size(), 2);
        const auto r = input_report(k);
        s.append(r.begin(), r.end());
    }
    return s;
}

constexpr size_t kMcapBytesPerMessage = cdm::proto::kInputReportSize + 31 + 16;

// An MCAP recording of about n bytes of messages (uncompressed), written
// by the recorder in `compression`; returns its path.
std::string mcap_file(size_t n, const char *compression) {
    const std::string path = g_dir + "/bench_parsers_" + compression + "_" + std::to_string(n) + ".mcap";
    ::unlink(path.c_str());
    const auto info = info_bytes();
    std::unique_ptr<cdm::recording::Writer> w;
    std::string err;
    std::string fmt = std::string("mcap:") + compression, comp;
    cdm::recording::Format f;
    cdm::recording::parse_format(fmt, f, &comp);
    if (cdm::recording::open_writer(path, f, info.data(), info.size(), w, err, comp) != 0) {
        std::fprintf(stderr, "bench_parsers: %s\n", err.c_str());
        std::exit(2);
    }
    // A message is its record (the report and 31 bytes) and its index entry
    // (16 bytes); chunk and summary records add about 1 %: 97 % of n keeps
    // the file, and the uncompressed chunks, within the cap.
    const size_t per = kMcapBytesPerMessage;
    for (uint32_t k = 0; double(k) * double(per) < 0.97 * double(n); ++k) {
        const auto r = input_report(k);
        if (w->write(uint64_t(k) * 1000000 + 1, r.data(), r.size(), nullptr, err) != 0) {
            std::fprintf(stderr, "bench_parsers: %s\n", err.c_str());
            std::exit(2);
        }
    }
    if (w->close(err) != 0) std::exit(2);
    return path;
}

// A dataset CSV written to a file of about n bytes: `rows_per_point`
// samples at each position (1: every row a new position).
std::string dataset_file(size_t n, int rows_per_point, const char *tag) {
    const std::string path = g_dir + "/bench_parsers_" + tag + "_" + std::to_string(n) + ".csv";
    std::FILE *f = std::fopen(path.c_str(), "w");
    if (!f) std::exit(2);
    size_t written = std::fprintf(f, "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n");
    char line[160];
    for (size_t row = 0;; ++row) {
        const size_t p = row / size_t(rows_per_point);
        const double y = double(p % 1000) * 0.05 - 25, z = double((p / 1000) % 1000) * 0.05 - 25;
        const double x = 30 + double(p / 1000000) * 10;
        const int len = std::snprintf(line, sizeof line, "%zu,%.2f,%.2f,%.2f,%.3f,%.3f,%.3f,%.3f\n", p, x, y, z,
                                      150.0 + double(row % 7) * 0.001, 151.0, 152.0, 153.0);
        if (written + size_t(len) > n) break; // never past the cap
        std::fwrite(line, 1, size_t(len), f);
        written += size_t(len);
    }
    std::fclose(f);
    return path;
}

std::vector<Case> cases() {
    const size_t kJson = cdm::io::kJsonMaxBytes, kData = cdm::io::kDatasetMaxBytes;
    const size_t kRec = size_t(cdm::replay::kMaxFileBytes), kUri = cdm::kMaxUriBytes;
    // An MCAP recording is capped by its bytes and by its messages' count,
    // whichever comes first.
    const size_t kMcap = std::min(kRec, size_t(double(cdm::mcap::kMaxMessages) * kMcapBytesPerMessage / 0.97) - 1);
    auto json = [](const std::string &text, std::string &err) {
        cdm::io::JsonValue v;
        return cdm::io::parse_json(text, "bench.json", v, err);
    };
    std::vector<Case> c;
    c.push_back({"json_object_keys", "one object of distinct keys (the duplicate check)", kJson, true, false,
                 [](size_t n) {
                     return repeat_until("{", [](size_t k) { return "\"k" + std::to_string(k) + "\":0"; }, ",", "}",
                                         n);
                 },
                 json});
    c.push_back({"json_array_numbers", "one array of decimals", kJson, true, false,
                 [](size_t n) { return repeat_until("[", [](size_t) { return std::string("0.125"); }, ",", "]", n); },
                 json});
    c.push_back({"json_string_escapes", "one string of \\u escapes", kJson, true, false,
                 [](size_t n) {
                     return repeat_until("[\"", [](size_t) { return std::string("\\u00e9\\n"); }, "", "\"]", n);
                 },
                 json});
    c.push_back({"json_nested", "arrays nested to the depth limit, repeated", kJson, true, false,
                 [](size_t n) {
                     return repeat_until("[", [](size_t) { return std::string(60, '[') + std::string(60, ']'); },
                                         ",", "]", n);
                 },
                 json});
    c.push_back({"device_json_keys", "a device file of distinct unknown keys (refused, after the parse)", kJson, false, false,
                 [](size_t n) {
                     return repeat_until("{", [](size_t k) { return "\"k" + std::to_string(k) + "\":1"; }, ",", "}",
                                         n);
                 },
                 [](const std::string &text, std::string &err) {
                     cdm::DeviceGeometry g;
                     return cdm::io::parse_device_json(text, "bench.json", g, err);
                 }});
    c.push_back({"dataset_rows", "a jig dataset, 100 samples per position", kData, true, true,
                 [](size_t n) { return dataset_file(n, 100, "rows"); },
                 [](const std::string &path, std::string &err) {
                     cdm::Dataset d;
                     return cdm::load_dataset(path, d, err);
                 }});
    c.push_back({"dataset_distinct_points", "a dataset whose every row is a new position", kData, true, true,
                 [](size_t n) { return dataset_file(n, 1, "distinct"); },
                 [](const std::string &path, std::string &err) {
                     cdm::Dataset d;
                     return cdm::load_dataset(path, d, err);
                 }});
    c.push_back({"replay_records", "a replay file of 64-byte reports", kRec, true, false, replay_bytes,
                 [](const std::string &bytes, std::string &err) {
                     cdm::replay::File f;
                     return cdm::replay::parse(std::vector<uint8_t>(bytes.begin(), bytes.end()), "bench.cdmrec", f,
                                               err) == 0;
                 }});
    for (const char *comp : {"none", "zstd"})
        c.push_back({comp[0] == 'n' ? "mcap_messages" : "mcap_messages_zstd",
                     comp[0] == 'n' ? "an MCAP file of report messages, chunks uncompressed"
                                    : "the same, zstd chunks (the cap is on the uncompressed bytes)",
                     kMcap, true, true, [comp](size_t n) { return mcap_file(n, comp); },
                     [](const std::string &path, std::string &err) {
                         cdm::replay::File f;
                         return cdm::replay::load(path, f, err) == 0;
                     }});
    c.push_back({"uri_options", "a sim: URI of distinct options (the repeat check)", kUri, true, false,
                 [](size_t n) {
                     return repeat_until("sim:?", [](size_t k) { return "o" + std::to_string(k) + "=1"; }, "&", "", n);
                 },
                 [](const std::string &text, std::string &err) {
                     cdm::Uri u;
                     return cdm::parse_uri(text, u, err) == 0;
                 }});
    c.push_back({"sim_fault_list", "one sim: fault list of distinct report indices", kUri, true, false,
                 [](size_t n) {
                     return repeat_until("", [](size_t k) { return std::to_string(1000 + k * 7); }, ",", "", n - 16);
                 },
                 [](const std::string &list, std::string &err) {
                     cdm::Uri u;
                     cdm::parse_uri("sim:", u, err);
                     cdm::sim::FaultPlan plan;
                     bool known = false;
                     return cdm::sim::parse_fault_option(u, "drop", list, plan, known, err) && known;
                 }});
    return c;
}

struct Args {
    double scale = 1.0;
    int repeat = 3;
    std::string only;
    bool check_only = false;
};

Args parse_args(int argc, char **argv) {
    Args a;
    for (int i = 1; i < argc; ++i) {
        const std::string k = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : nullptr;
        if (k == "--check-only") {
            a.check_only = true;
            continue;
        }
        if (!v) {
            std::fprintf(stderr, "usage: bench_parsers [--scale F] [--repeat N] [--only NAME] [--dir DIR] [--check-only]\n");
            std::exit(2);
        }
        ++i;
        if (k == "--scale") a.scale = std::atof(v);
        else if (k == "--repeat") a.repeat = std::max(1, std::atoi(v));
        else if (k == "--only") a.only = v;
        else if (k == "--dir") g_dir = v;
        else {
            std::fprintf(stderr, "bench_parsers: unknown option %s\n", k.c_str());
            std::exit(2);
        }
    }
    if (!(a.scale > 0 && a.scale <= 1)) {
        std::fprintf(stderr, "bench_parsers: --scale must be in (0, 1]\n");
        std::exit(2);
    }
    return a;
}

// The time of one parse of an input of at most n bytes: the fastest of
// `repeat` runs, each parsing as many times as fill 50 ms (a URI parses in
// microseconds) and giving the mean. A file input is removed afterwards.
double time_parse(const Case &c, size_t n, int repeat, bool &ok, std::string &err) {
    const std::string in = c.make(n);
    double best = 1e300;
    for (int r = 0; r < repeat; ++r) {
        int iters = 0;
        const double t0 = now();
        double t = t0;
        do {
            ok = c.parse(in, err);
            ++iters;
            t = now();
        } while (t - t0 < 0.05);
        best = std::min(best, (t - t0) / iters);
    }
    if (c.file) ::unlink(in.c_str());
    return best;
}

} // namespace

int main(int argc, char **argv) {
    const Args a = parse_args(argc, argv);
    int bad = 0;
    std::printf("%-24s %10s %10s %10s %9s %7s  %s\n", "parser/shape", "cap MiB", "t(cap/4)", "t(cap/2)", "t(cap)", "ratio",
                "verdict (ratio t(cap)/t(cap/2): 2 linear, 4 quadratic; > 3 super-linear)");
    for (const Case &c : cases()) {
        if (!a.only.empty() && a.only != c.name) continue;
        const size_t cap = size_t(double(c.cap) * a.scale);
        bool ok = false;
        std::string err;
        if (a.check_only) {
            const std::string in = c.make(cap / 4);
            ok = c.parse(in, err);
            if (c.file) ::unlink(in.c_str());
            const bool pass = ok == c.accepted;
            std::printf("%-24s %s (%s)%s%s\n", c.name, pass ? "ok" : "WRONG OUTCOME", ok ? "accepted" : "refused",
                        err.empty() ? "" : ": ", err.substr(0, 160).c_str());
            bad += !pass;
            continue;
        }
        double t[3];
        bool wrong = false;
        for (int k = 0; k < 3 && !wrong; ++k) {
            t[k] = time_parse(c, cap >> (2 - k), a.repeat, ok, err);
            if (ok != c.accepted) {
                std::printf("%-24s wrong outcome at %zu bytes: %s\n", c.name, cap >> (2 - k), err.c_str());
                ++bad;
                wrong = true;
            }
        }
        if (wrong) continue;
        const double ratio = t[2] / t[1];
        const bool super = ratio > 3.0;
        bad += super;
        std::printf("%-24s %10.1f %9.3fs %9.3fs %8.3fs %7.2f  %s: %s\n", c.name, double(cap) / (1 << 20), t[0], t[1],
                    t[2], ratio, super ? "super-linear" : "linear", c.what);
        std::fflush(stdout);
    }
    return bad ? 1 : 0;
}
