// `cdm list | info | stream | record`: the device side of the command. Every
// report goes through the public C API (cdm_open_ex and its sample
// callback), the same path an application takes.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "jig/plan.h"
#include "cdm/cdm.h"
#include "cli/commands.h"
#include "device/device.h"
#include "device/replay_format.h"
#include "device/sim/sim_truth.h"
#include "device/transport.h"

namespace cdm::cli {

namespace {

volatile std::sig_atomic_t g_interrupted = 0;
void on_sigint(int) { g_interrupted = 1; }

int report_error(const char *what, int rc) {
    std::fprintf(stderr, "cdm: %s: %s", what, cdm_strerror(rc));
    const char *detail = cdm_thread_error();
    if (detail && *detail) std::fprintf(stderr, ": %s", detail);
    std::fprintf(stderr, "\n");
    return 1;
}

std::string flags_text(uint32_t f) {
    std::string s;
    s += (f & CDM_POSE_STALE) ? 'S' : '-';
    s += (f & CDM_POSE_DISCONNECTED) ? 'D' : '-';
    s += (f & CDM_POSE_COMPENSATED) ? 'C' : '-';
    s += (f & CDM_POSE_OUT_OF_WORKSPACE) ? 'W' : '-';
    s += (f & CDM_POSE_END_OF_STREAM) ? 'E' : '-';
    return s;
}

std::string buttons_text(uint32_t b) {
    std::string s;
    s += (b & CDM_BUTTON_CLUTCH) ? 'C' : '-';
    s += (b & CDM_BUTTON_AUX) ? 'A' : '-';
    s += (b & CDM_BUTTON_MARK) ? 'M' : '-';
    return s;
}

double now_s() { return double(cdm::monotonic_ns()) * 1e-9; }

int cmd_list() {
    cdm_device_list *list = nullptr;
    const int rc = cdm_enumerate(&list);
    if (rc != CDM_OK) return report_error("enumerate", rc);
    const size_t n = cdm_device_list_count(list);
    if (n == 0) {
        std::printf("no master connected (USB 1209:cd01)");
        const char *why = cdm_thread_error();
        if (why && *why) std::printf(": %s", why);
        std::printf("\nthe simulated master is always there: cdm stream sim:\n");
    }
    for (size_t i = 0; i < n; ++i) {
        cdm_device_info info{};
        info.struct_size = sizeof info;
        if (cdm_device_list_get(list, i, &info) != CDM_OK) continue;
        std::printf("%s  serial %s  firmware %s  %04x:%04x\n", info.uri, info.serial, info.firmware,
                    info.vendor_id, info.product_id);
    }
    cdm_device_list_free(list);
    return 0;
}

int cmd_info(const std::string &uri) {
    cdm_device *dev = nullptr;
    int rc = cdm_open(uri.c_str(), &dev);
    if (rc != CDM_OK) return report_error(("open " + uri).c_str(), rc);
    cdm_device_info i{};
    i.struct_size = sizeof i;
    rc = cdm_get_info(dev, &i);
    if (rc != CDM_OK) {
        cdm_close(dev);
        return report_error("get info", rc);
    }
    std::printf("uri:              %s\n", i.uri);
    std::printf("transport:        %s\n", i.transport);
    std::printf("usb id:           %04x:%04x\n", i.vendor_id, i.product_id);
    std::printf("serial:           %s\n", i.serial);
    std::printf("firmware:         %s\n", i.firmware);
    std::printf("protocol version: %u\n", i.protocol_version);
    std::printf("report rate:      %.1f Hz\n", i.report_rate_hz);
    std::printf("pot ADC:          %u bits\n", i.adc_bits);
    for (int k = 0; k < 4; ++k)
        std::printf("pot %d:            %.6f mm/count, offset %.4f mm\n", k + 1, i.pot_scale_mm[k],
                    i.pot_offset_mm[k]);
    std::printf("geometry:         a %.3f mm, b %.3f mm, m %.3f mm\n", i.a_mm, i.b_mm, i.m_mm);
    std::printf("grip (Hall):      closed %.0f counts, open %.0f counts = %.4f rad\n", i.hall_closed, i.hall_open,
                i.grip_open_rad);
    size_t len = 0;
    rc = cdm_device_calibration_read(dev, nullptr, 0, &len);
    if (rc == CDM_OK || rc == CDM_ERR_NO_MEM)
        std::printf("stored calib:     %zu bytes\n", len);
    else
        std::printf("stored calib:     none (%s)\n", cdm_thread_error());
    cdm_close(dev);
    return 0;
}

// ----------------------------------------------------------------- stream

struct Accum {
    double sum = 0, sum2 = 0;
    void add(double v) {
        sum += v;
        sum2 += v * v;
    }
};

struct StreamCtx {
    std::atomic<cdm_device *> dev{nullptr};
    bool truth = false;
    std::mutex mu;
    uint64_t reports = 0;
    // Host delay: host receipt time minus the device clock. Their offset is
    // unknown, so we show the delay in excess of the smallest one seen: the
    // latency the transport added on top of its best case (jitter, queueing).
    bool have_min = false;
    int64_t min_delay_ns = 0;
    double excess_sum_ms = 0, excess_max_ms = 0;
    uint64_t excess_n = 0;
    // --truth
    uint64_t truth_n = 0;
    Accum err[3];
    double last_err[3] = {0, 0, 0};
};

void stream_sample(void *user, const cdm_sample *s) {
    auto *c = static_cast<StreamCtx *>(user);
    const int64_t delay = int64_t(s->pose->host_time_ns) - int64_t(s->pose->device_time_us) * 1000;
    double e[3];
    bool have_truth = false;
    if (c->truth) {
        if (cdm_device *d = c->dev.load()) {
            double p[3];
            if (sim_truth(d, s->pose->sequence, p)) {
                for (int k = 0; k < 3; ++k) e[k] = s->pose->position[k] - p[k];
                have_truth = true;
            }
        }
    }
    std::lock_guard<std::mutex> lock(c->mu);
    ++c->reports;
    if (!c->have_min || delay < c->min_delay_ns) {
        c->min_delay_ns = delay;
        c->have_min = true;
    }
    const double ex = double(delay - c->min_delay_ns) * 1e-6;
    c->excess_sum_ms += ex;
    c->excess_max_ms = std::max(c->excess_max_ms, ex);
    ++c->excess_n;
    if (have_truth) {
        ++c->truth_n;
        for (int k = 0; k < 3; ++k) {
            c->err[k].add(e[k]);
            c->last_err[k] = e[k];
        }
    }
}

int cmd_stream(const std::string &uri, double seconds, double rate, const std::string &calib, bool truth) {
    StreamCtx ctx;
    ctx.truth = truth;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = stream_sample;
    o.user = &ctx;
    cdm_device *dev = nullptr;
    int rc = cdm_open_ex(uri.c_str(), &o, &dev);
    if (rc != CDM_OK) return report_error(("open " + uri).c_str(), rc);
    ctx.dev.store(dev);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    cdm_get_info(dev, &info);
    if (truth && std::strcmp(info.transport, "sim") != 0) {
        cdm_close(dev);
        std::fprintf(stderr, "cdm: --truth needs a sim: device (%s is %s)\n", uri.c_str(), info.transport);
        return 1;
    }
    if (!calib.empty()) {
        cdm_calibration *cal = nullptr;
        if (cdm_calibration_load(calib.c_str(), &cal) != CDM_OK) {
            cdm_close(dev);
            std::fprintf(stderr, "cdm: --calibration: %s\n", cdm_thread_error());
            return 1;
        }
        cdm_set_calibration(dev, cal); // the device keeps its own reference
        cdm_calibration_free(cal);
    }
    std::printf("streaming %s (%s, serial %s, %.0f Hz nominal); Ctrl-C stops\n", info.uri, info.transport,
                info.serial, info.report_rate_hz);
    std::printf("flags: S stale, D disconnected, C compensated, W out of workspace, E end of stream; "
                "buttons: C clutch, A aux, M mark\n");
    std::printf("age: newest pose's age when printed; delay+: host receipt minus device clock, over the best "
                "seen (mean/max)\n");
    std::signal(SIGINT, on_sigint);
    const bool tty = isatty(fileno(stdout));
    const double t0 = now_s();
    double last_t = t0;
    uint64_t last_reports = 0;
    const double period = 1.0 / std::max(0.5, rate);
    int final_rc = CDM_OK;
    while (!g_interrupted && (seconds <= 0 || now_s() - t0 < seconds)) {
        std::this_thread::sleep_for(std::chrono::duration<double>(period));
        cdm_pose p{};
        p.struct_size = sizeof p;
        rc = cdm_get_pose(dev, &p);
        const double t = now_s();
        uint64_t reports;
        double ex_mean, ex_max, le[3];
        uint64_t tn;
        {
            std::lock_guard<std::mutex> lock(ctx.mu);
            reports = ctx.reports;
            ex_mean = ctx.excess_n ? ctx.excess_sum_ms / double(ctx.excess_n) : 0.0;
            ex_max = ctx.excess_max_ms;
            ctx.excess_sum_ms = ctx.excess_max_ms = 0;
            ctx.excess_n = 0;
            std::copy(ctx.last_err, ctx.last_err + 3, le);
            tn = ctx.truth_n;
        }
        const double measured = double(reports - last_reports) / (t - last_t);
        last_reports = reports;
        last_t = t;
        if (rc == CDM_ERR_NO_DATA) {
            std::printf("%swaiting for the first report...%s", tty ? "\r" : "", tty ? "" : "\n");
            std::fflush(stdout);
            continue;
        }
        const double age_ms = double(cdm::monotonic_ns() - p.host_time_ns) * 1e-6;
        std::printf("%s#%-8u pos %8.3f %8.3f %8.3f mm  q %6.3f %6.3f %6.3f %6.3f  grip %5.3f  btn %s  %s  "
                    "%6.1f Hz  age %6.2f ms  delay+ %5.2f/%5.2f ms  drops %u",
                    tty ? "\r" : "", p.sequence, p.position[0], p.position[1], p.position[2], p.orientation[0],
                    p.orientation[1], p.orientation[2], p.orientation[3], p.grip, buttons_text(p.buttons).c_str(),
                    flags_text(p.flags).c_str(), measured, age_ms, ex_mean, ex_max, p.dropped);
        if (truth && tn) std::printf("  err %+7.4f %+7.4f %+7.4f mm", le[0], le[1], le[2]);
        std::printf("%s", tty ? "  " : "\n");
        std::fflush(stdout);
        if (rc == CDM_ERR_END_OF_STREAM) {
            final_rc = rc;
            break;
        }
    }
    const double elapsed = now_s() - t0;
    cdm_stats st{};
    st.struct_size = sizeof st;
    cdm_get_stats(dev, &st);
    char err[256] = "";
    cdm_device_error(dev, err, sizeof err);
    cdm_close(dev); // joins the reader thread: ctx is ours alone from here
    std::printf("%s%llu reports in %.2f s (%.1f Hz), dropped %llu, malformed %llu, out of workspace %llu, "
                "reconnects %llu%s\n",
                tty ? "\n" : "", (unsigned long long)st.reports, elapsed, double(st.reports) / elapsed,
                (unsigned long long)st.dropped, (unsigned long long)st.malformed,
                (unsigned long long)st.out_of_workspace, (unsigned long long)st.reconnects,
                final_rc == CDM_ERR_END_OF_STREAM ? " (end of stream)" : "");
    if (*err) std::printf("last device message: %s\n", err);
    if (truth) {
        if (ctx.truth_n == 0) {
            std::printf("no report could be matched with the simulator's truth\n");
        } else {
            const double n = double(ctx.truth_n);
            std::printf("error vs simulator truth over %llu reports (mm):\n", (unsigned long long)ctx.truth_n);
            const char *ax = "xyz";
            for (int k = 0; k < 3; ++k)
                std::printf("  %c: mean %+8.4f  rms %7.4f\n", ax[k], ctx.err[k].sum / n,
                            std::sqrt(ctx.err[k].sum2 / n));
        }
    }
    return 0;
}

// ----------------------------------------------------------------- record

struct RecordCtx {
    std::mutex mu;
    // replay
    replay::Writer *writer = nullptr;
    std::vector<std::pair<uint64_t, std::vector<uint8_t>>> pending; // before the writer is open
    std::string write_err;
    // jig
    bool jig = false;
    std::vector<JigPosition> plan;
    int samples = 100;
    std::FILE *csv = nullptr;
    size_t next_point = 0;
    bool in_dwell = false;
    std::vector<std::array<double, 4>> dwell;
    uint64_t short_dwells = 0;
    std::atomic<bool> done{false};
    // both
    uint64_t reports = 0;
};

void close_dwell(RecordCtx &c) {
    c.in_dwell = false;
    if (c.next_point >= c.plan.size()) return;
    if (c.dwell.size() < size_t(c.samples)) {
        // Released too early: the same position is asked for again.
        ++c.short_dwells;
        c.dwell.clear();
        return;
    }
    const JigPosition &jp = c.plan[c.next_point];
    for (const auto &l : c.dwell)
        std::fprintf(c.csv, "%d,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", jp.point, jp.ref[0], jp.ref[1], jp.ref[2], l[0],
                     l[1], l[2], l[3]);
    c.dwell.clear();
    if (++c.next_point == c.plan.size()) c.done = true;
}

void record_sample(void *user, const cdm_sample *s) {
    auto *c = static_cast<RecordCtx *>(user);
    std::lock_guard<std::mutex> lock(c->mu);
    ++c->reports;
    if (!c->jig) {
        if (!c->writer) {
            c->pending.emplace_back(s->raw->host_time_ns, std::vector<uint8_t>(s->report, s->report + s->report_len));
        } else if (c->write_err.empty()) {
            c->writer->write(s->raw->host_time_ns, s->report, s->report_len, c->write_err);
        }
        return;
    }
    if (c->done) return;
    const bool mark = s->raw->buttons & CDM_BUTTON_MARK;
    if (mark) {
        if (!c->in_dwell) {
            c->in_dwell = true;
            c->dwell.clear();
        }
        if (c->dwell.size() < size_t(c->samples))
            c->dwell.push_back({s->raw->lengths_mm[0], s->raw->lengths_mm[1], s->raw->lengths_mm[2],
                                s->raw->lengths_mm[3]});
    } else if (c->in_dwell) {
        close_dwell(*c);
    }
}

struct JigArgs {
    bool jig = false;
    int n = 0;
    double pitch = 0;
    std::string heights;
    int samples = 0;
};

// The plan `cdm record --jig` labels with. A sim: URI's jig_* options are the
// defaults (so that `record "sim:?motion=jig&jig_n=5" --jig` labels what the
// simulator does); an explicit flag that contradicts them is an error.
bool jig_plan_for(const std::string &uri, const JigArgs &a, JigPlanOptions &o, std::string &err) {
    Uri u;
    if (parse_uri(uri, u, err) == CDM_OK && u.scheme == "sim") {
        for (const auto &kv : u.options) {
            if (kv.first == "jig_n") o.n = std::atoi(kv.second.c_str());
            else if (kv.first == "jig_pitch") o.pitch_mm = std::atof(kv.second.c_str());
            else if (kv.first == "jig_samples") o.samples = std::atoi(kv.second.c_str());
            else if (kv.first == "jig_heights" && !parse_heights(kv.second, o.heights_mm, err)) return false;
        }
    }
    err.clear();
    JigPlanOptions from_uri = o;
    if (a.n) o.n = a.n;
    if (a.pitch > 0) o.pitch_mm = a.pitch;
    if (a.samples) o.samples = a.samples;
    if (!a.heights.empty() && !parse_heights(a.heights, o.heights_mm, err)) return false;
    if (u.scheme == "sim" && (o.n != from_uri.n || o.pitch_mm != from_uri.pitch_mm ||
                              o.samples != from_uri.samples || o.heights_mm != from_uri.heights_mm)) {
        err = "the --jig-* flags disagree with the simulator's jig_* options in the URI: the labels would not "
              "match the positions";
        return false;
    }
    return check_jig_options(o, err);
}

int cmd_record(const std::string &uri, const std::string &file, double seconds, const JigArgs &ja) {
    RecordCtx ctx;
    ctx.jig = ja.jig;
    const std::string tmp = file + ".tmp";
    if (ja.jig) {
        JigPlanOptions po;
        std::string err;
        if (!jig_plan_for(uri, ja, po, err)) {
            std::fprintf(stderr, "cdm: record --jig: %s\n", err.c_str());
            return 1;
        }
        ctx.plan = make_jig_plan(po);
        ctx.samples = po.samples;
        ctx.csv = std::fopen(tmp.c_str(), "w");
        if (!ctx.csv) {
            std::fprintf(stderr, "cdm: cannot create %s: %s\n", tmp.c_str(), std::strerror(errno));
            return 1;
        }
        std::fprintf(ctx.csv, "point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n");
    }
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = record_sample;
    o.user = &ctx;
    cdm_device *dev = nullptr;
    int rc = cdm_open_ex(uri.c_str(), &o, &dev);
    if (rc != CDM_OK) {
        if (ctx.csv) std::fclose(ctx.csv);
        std::remove(tmp.c_str());
        return report_error(("open " + uri).c_str(), rc);
    }
    replay::Writer writer;
    if (!ja.jig) {
        // The recording starts with the device's own info report, byte for
        // byte, so a replay converts exactly as this device did.
        uint8_t info[256] = {0x02};
        std::string err;
        const int n = dev->transport().get_feature(info, sizeof info, err);
        if (n <= 0 || writer.open(tmp, info, size_t(n), err) != CDM_OK) {
            cdm_close(dev);
            std::remove(tmp.c_str());
            std::fprintf(stderr, "cdm: record: %s\n", err.c_str());
            return 1;
        }
        std::lock_guard<std::mutex> lock(ctx.mu);
        for (const auto &r : ctx.pending)
            if (ctx.write_err.empty()) writer.write(r.first, r.second.data(), r.second.size(), ctx.write_err);
        ctx.pending.clear();
        ctx.writer = &writer;
    }
    std::signal(SIGINT, on_sigint);
    const bool tty = isatty(fileno(stderr));
    const double t0 = now_s();
    double last_print = 0;
    bool ended = false;
    while (!g_interrupted && !ctx.done && (seconds <= 0 || now_s() - t0 < seconds)) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        cdm_pose p{};
        p.struct_size = sizeof p;
        ended = cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM;
        const double t = now_s() - t0;
        if (t - last_print >= 0.5 || ended) {
            last_print = t;
            std::lock_guard<std::mutex> lock(ctx.mu);
            if (ja.jig)
                std::fprintf(stderr, "%sjig position %zu/%zu (%s), %llu reports, %.1f s, drops %u%s",
                             tty ? "\r" : "", ctx.next_point, ctx.plan.size(), ctx.in_dwell ? "MARK held" : "moving",
                             (unsigned long long)ctx.reports, t, p.dropped, tty ? "   " : "\n");
            else
                std::fprintf(stderr, "%srecorded %llu reports, %.1f s, drops %u%s", tty ? "\r" : "",
                             (unsigned long long)ctx.reports, t, p.dropped, tty ? "   " : "\n");
        }
        if (ended) break;
    }
    cdm_stats st{};
    st.struct_size = sizeof st;
    cdm_get_stats(dev, &st);
    cdm_close(dev); // no callback runs after this
    if (tty) std::fprintf(stderr, "\n");
    std::string err;
    bool ok = true;
    if (ja.jig) {
        if (ctx.in_dwell) close_dwell(ctx); // the stream ended with MARK still held
        ok = std::fflush(ctx.csv) == 0 && std::ferror(ctx.csv) == 0;
        ok = std::fclose(ctx.csv) == 0 && ok;
        if (!ok) err = tmp + ": write error";
    } else {
        if (!ctx.write_err.empty()) {
            err = ctx.write_err;
            ok = false;
        }
        if (writer.close(err) != CDM_OK) ok = false;
    }
    if (!ok || std::rename(tmp.c_str(), file.c_str()) != 0) {
        std::remove(tmp.c_str());
        std::fprintf(stderr, "cdm: record: %s\n", err.empty() ? std::strerror(errno) : err.c_str());
        return 1;
    }
    if (ja.jig) {
        std::printf("wrote %s: %zu of %zu jig positions x %d samples (%llu reports, %llu dwells too short and "
                    "repeated, %llu dropped)\n",
                    file.c_str(), ctx.next_point, ctx.plan.size(), ctx.samples, (unsigned long long)ctx.reports,
                    (unsigned long long)ctx.short_dwells, (unsigned long long)st.dropped);
        if (ctx.next_point < ctx.plan.size()) {
            std::fprintf(stderr, "cdm: record: the session stopped before the jig plan was complete\n");
            return 2;
        }
    } else {
        std::printf("wrote %s: %llu reports (%llu dropped, %llu malformed)\n", file.c_str(),
                    (unsigned long long)ctx.reports, (unsigned long long)st.dropped,
                    (unsigned long long)st.malformed);
    }
    return 0;
}

} // namespace

void add_device_commands(CLI::App &app) {
    auto *list = app.add_subcommand("list", "List the connected masters (USB 1209:cd01)");
    list->callback([] { std::exit(cmd_list()); });

    auto *info = app.add_subcommand("info", "Show what a device says about itself (feature report 0x02)");
    static std::string info_uri;
    info->add_option("URI", info_uri, "device URI: hid:/dev/hidrawN, serial:SN, sim:?..., replay:FILE")->required();
    info->callback([] { std::exit(cmd_info(info_uri)); });

    auto *stream = app.add_subcommand("stream", "Print the live pose, report rate, latency and drops");
    static std::string s_uri, s_calib;
    static double s_seconds = 0, s_rate = 10;
    static bool s_truth = false;
    stream->add_option("URI", s_uri, "device URI (sim:, replay:FILE, hid:/dev/hidrawN, serial:SN)")->required();
    stream->add_option("--seconds", s_seconds, "stop after this many seconds (default: until Ctrl-C or the end)");
    stream->add_option("--rate", s_rate, "display refresh rate in Hz (default 10)")->check(CLI::Range(0.5, 1000.0));
    stream->add_option("--calibration", s_calib, "apply this calibration (CALIB.json from `cdm calib fit`)");
    stream->add_flag("--truth", s_truth,
                     "sim: only: also show the error against the simulator's true position, and a summary");
    stream->callback([] { std::exit(cmd_stream(s_uri, s_seconds, s_rate, s_calib, s_truth)); });

    auto *record = app.add_subcommand(
        "record", "Record a device's reports to a replay file, or with --jig a calibration dataset CSV");
    static std::string r_uri, r_file;
    static double r_seconds = 0;
    static JigArgs ja;
    record->add_option("URI", r_uri, "device URI")->required();
    record->add_option("FILE", r_file, "output file (written to FILE.tmp, renamed when complete)")->required();
    record->add_option("--seconds", r_seconds, "stop after this many seconds (default: until Ctrl-C or the end)");
    record->add_flag("--jig", ja.jig,
                     "write the dataset CSV point,x_ref,y_ref,z_ref,l1..l4: each MARK-held dwell is labelled with "
                     "the next jig-plan position");
    record->add_option("--jig-n", ja.n, "holes per side of the plate (default 25)")->check(CLI::Range(1, 1000));
    record->add_option("--jig-pitch", ja.pitch, "hole pitch in mm (default 5)")->check(CLI::PositiveNumber);
    record->add_option("--jig-heights", ja.heights, "fixture heights in mm (default 30,40,50,60,70)");
    record->add_option("--jig-samples", ja.samples, "samples kept per position (default 100)")
        ->check(CLI::Range(1, 1000000));
    record->callback([] { std::exit(cmd_record(r_uri, r_file, r_seconds, ja)); });
}

} // namespace cdm::cli
