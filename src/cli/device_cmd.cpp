// `cdm list | info | stream`: the device side of the command, through the
// public C API (cdm_open_ex and its sample callback), the path an
// application takes.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include <cdm/cdm.h>
#include "commands.h"

namespace cdm::cli {

namespace {

volatile std::sig_atomic_t g_interrupted = 0;
void on_signal(int) { g_interrupted = 1; }

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

std::string usb_id(const cdm_device_info &i) {
    char b[16];
    std::snprintf(b, sizeof b, "%04x:%04x", i.vendor_id, i.product_id);
    return b;
}

int cmd_list(bool json) {
    cdm_device_list *list = nullptr;
    const int rc = cdm_enumerate(&list);
    if (rc != CDM_OK) return report_error("enumerate", rc);
    const size_t n = cdm_device_list_count(list);
    nlohmann::json out = nlohmann::json::array();
    if (n == 0 && !json) {
        std::printf("no master connected (USB 1209:cd01)");
        const char *why = cdm_thread_error();
        if (why && *why) std::printf(": %s", why);
        std::printf("\nthe simulated master is always there: cdm stream sim:\n");
    }
    for (size_t i = 0; i < n; ++i) {
        cdm_device_info info{};
        info.struct_size = sizeof info;
        if (cdm_device_list_get(list, i, &info) != CDM_OK) continue;
        if (json)
            out.push_back({{"uri", info.uri}, {"serial", info.serial}, {"firmware", info.firmware},
                           {"usb_id", usb_id(info)}});
        else
            std::printf("%s  serial %s  firmware %s  %s\n", info.uri, info.serial, info.firmware, usb_id(info).c_str());
    }
    cdm_device_list_free(list);
    if (json) std::printf("%s\n", out.dump(1).c_str());
    return kExitOk;
}

// `cdm list --watch`: one line per arrival or departure, from cdm_watch's
// callback (the watcher's thread; stdout is written under a lock, and
// flushed, so that a pipe sees each line as it happens).
struct WatchOut {
    std::mutex mu;
    bool json = false;
    uint64_t t0_ns = 0;
    unsigned arrived = 0, left = 0;
};

void on_watch(void *user, const cdm_watch_event *e) {
    auto *o = static_cast<WatchOut *>(user);
    const cdm_device_info &i = *e->info;
    const bool arrived = e->kind == CDM_WATCH_ARRIVED;
    const double t = double(e->host_time_ns - std::min(e->host_time_ns, o->t0_ns)) * 1e-9;
    std::lock_guard<std::mutex> lock(o->mu);
    (arrived ? o->arrived : o->left)++;
    if (o->json)
        std::printf("%s\n", nlohmann::json{{"event", arrived ? "arrived" : "left"},
                                           {"t_s", t},
                                           {"uri", i.uri},
                                           {"serial", i.serial},
                                           {"firmware", i.firmware},
                                           {"usb_id", usb_id(i)}}
                                .dump()
                                .c_str());
    else
        std::printf("%8.3f s  %-7s  %s  serial %s  firmware %s\n", t, arrived ? "arrived" : "left", i.uri, i.serial,
                    i.firmware);
    std::fflush(stdout);
}

int cmd_list_watch(bool json, double seconds) {
    WatchOut out;
    out.json = json;
    out.t0_ns = now_ns();
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    cdm_watcher *w = nullptr;
    const int rc = cdm_watch(CDM_WATCH_ENUMERATE, on_watch, &out, &w);
    if (rc != CDM_OK) return report_error("watch", rc);
    if (!json)
        std::fprintf(stderr, "watching for masters (USB 1209:cd01): the connected ones first, then arrivals and "
                             "departures; %s\n",
                     seconds > 0 ? "stops after --seconds" : "Ctrl-C stops");
    const double t0 = now_s();
    while (!g_interrupted && (seconds <= 0 || now_s() - t0 < seconds))
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    cdm_watch_free(w); // joins the watcher's thread: out is ours alone from here
    if (!json) std::fprintf(stderr, "%u arrived, %u left\n", out.arrived, out.left);
    return kExitOk;
}

nlohmann::json info_json(const cdm_device_info &i, long calib_bytes) {
    return {{"uri", i.uri},
            {"transport", i.transport},
            {"usb_id", usb_id(i)},
            {"serial", i.serial},
            {"firmware", i.firmware},
            {"protocol_version", i.protocol_version},
            {"report_rate_hz", i.report_rate_hz},
            {"adc_bits", i.adc_bits},
            {"pot_scale_mm_per_count", i.pot_scale_mm},
            {"pot_offset_mm", i.pot_offset_mm},
            {"a_mm", i.a_mm},
            {"b_mm", i.b_mm},
            {"m_mm", i.m_mm},
            {"hall_closed", i.hall_closed},
            {"hall_open", i.hall_open},
            {"grip_open_rad", i.grip_open_rad},
            {"stored_calibration_bytes", calib_bytes < 0 ? nlohmann::json() : nlohmann::json(calib_bytes)}};
}

void print_info(const cdm_device_info &i, long calib_bytes, const std::string &calib_why) {
    std::printf("uri:              %s\n", i.uri);
    std::printf("transport:        %s\n", i.transport);
    std::printf("usb id:           %s\n", usb_id(i).c_str());
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
    if (calib_bytes >= 0)
        std::printf("stored calib:     %ld bytes\n", calib_bytes);
    else
        std::printf("stored calib:     none (%s)\n", calib_why.c_str());
}

int cmd_info(const std::string &uri, bool json) {
    cdm_device *dev = nullptr;
    int rc = cdm_open(uri.c_str(), &dev);
    if (rc != CDM_OK) return report_error("open " + uri, rc);
    cdm_device_info i{};
    i.struct_size = sizeof i;
    rc = cdm_get_info(dev, &i);
    if (rc != CDM_OK) {
        cdm_close(dev);
        return report_error("get info", rc);
    }
    size_t len = 0;
    rc = cdm_device_calibration_read(dev, nullptr, 0, &len);
    const long calib_bytes = (rc == CDM_OK || rc == CDM_ERR_NO_MEM) ? long(len) : -1;
    const std::string why = calib_bytes < 0 ? cdm_thread_error() : "";
    cdm_close(dev);
    if (json)
        std::printf("%s\n", info_json(i, calib_bytes).dump(1).c_str());
    else
        print_info(i, calib_bytes, why);
    return kExitOk;
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
    // --calibration: the truth error counts only the poses computed with it
    // (CDM_POSE_COMPENSATED), not the few the reader published between the
    // open and cdm_set_calibration with the nominal model.
    bool compensated_only = false;
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
    if (c->truth && (!c->compensated_only || (s->pose->flags & CDM_POSE_COMPENSATED))) {
        if (cdm_device *d = c->dev.load()) {
            double p[3];
            if (cdm_sim_truth(d, s->pose->sequence, p) == CDM_OK) {
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

struct StreamArgs {
    std::string uri, calib;
    double seconds = 0, rate = 10;
    bool truth = false, json = false;
};

// One display line: the live numbers since the previous one.
struct Tick {
    cdm_pose p;
    double hz, age_ms, ex_mean, ex_max, err[3];
    uint64_t truth_n;
};

void print_tick(const Tick &t, bool tty, bool truth, bool json) {
    const cdm_pose &p = t.p;
    if (json) {
        nlohmann::json j = {{"sequence", p.sequence},  {"position_mm", p.position}, {"orientation", p.orientation},
                            {"grip_rad", p.grip},     {"buttons", p.buttons},     {"flags", p.flags},
                            {"rate_hz", t.hz},        {"age_ms", t.age_ms},       {"delay_excess_mean_ms", t.ex_mean},
                            {"delay_excess_max_ms", t.ex_max}, {"dropped", p.dropped}};
        if (truth && t.truth_n) j["error_mm"] = t.err;
        std::printf("%s\n", j.dump().c_str());
        std::fflush(stdout);
        return;
    }
    std::printf("%s#%-8u pos %8.3f %8.3f %8.3f mm  q %6.3f %6.3f %6.3f %6.3f  grip %5.3f  btn %s  %s  "
                "%6.1f Hz  age %6.2f ms  delay+ %5.2f/%5.2f ms  drops %u",
                tty ? "\r" : "", p.sequence, p.position[0], p.position[1], p.position[2], p.orientation[0],
                p.orientation[1], p.orientation[2], p.orientation[3], p.grip, buttons_text(p.buttons).c_str(),
                flags_text(p.flags).c_str(), t.hz, t.age_ms, t.ex_mean, t.ex_max, p.dropped);
    if (truth && t.truth_n) std::printf("  err %+7.4f %+7.4f %+7.4f mm", t.err[0], t.err[1], t.err[2]);
    std::printf("%s", tty ? "  " : "\n");
    std::fflush(stdout);
}

void print_stream_summary(const StreamArgs &a, const StreamCtx &ctx, const cdm_stats &st, double elapsed,
                          bool ended, const char *err, bool tty) {
    const double n = double(ctx.truth_n);
    if (a.json) {
        nlohmann::json j = stats_json(st);
        j["summary"] = true;
        j["seconds"] = elapsed;
        j["rate_hz"] = double(st.reports) / elapsed;
        j["end_of_stream"] = ended;
        j["last_device_message"] = err;
        if (a.truth && ctx.truth_n) {
            for (int k = 0; k < 3; ++k) {
                j["truth_error_mean_mm"].push_back(ctx.err[k].sum / n);
                j["truth_error_rms_mm"].push_back(std::sqrt(ctx.err[k].sum2 / n));
            }
        }
        std::printf("%s\n", j.dump().c_str());
        return;
    }
    std::printf("%s%llu reports in %.2f s (%.1f Hz), %s, out of workspace %llu, reconnects %llu%s\n",
                tty ? "\n" : "", (unsigned long long)st.reports, elapsed, double(st.reports) / elapsed,
                losses_text(st).c_str(), (unsigned long long)st.out_of_workspace,
                (unsigned long long)st.reconnects, ended ? " (end of stream)" : "");
    if (*err) std::printf("last device message: %s\n", err);
    if (!a.truth) return;
    if (ctx.truth_n == 0) {
        std::printf("no report could be matched with the simulator's truth\n");
        return;
    }
    std::printf("error vs simulator truth over %llu reports (mm):\n", (unsigned long long)ctx.truth_n);
    const char *ax = "xyz";
    for (int k = 0; k < 3; ++k)
        std::printf("  %c: mean %+8.4f  rms %7.4f\n", ax[k], ctx.err[k].sum / n, std::sqrt(ctx.err[k].sum2 / n));
}

// Opens the device with our sample callback and the calibration, if any.
int open_stream(const StreamArgs &a, StreamCtx &ctx, cdm_device *&dev, cdm_device_info &info) {
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = stream_sample;
    o.user = &ctx;
    int rc = cdm_open_ex(a.uri.c_str(), &o, &dev);
    if (rc != CDM_OK) return report_error("open " + a.uri, rc);
    ctx.dev.store(dev);
    info.struct_size = sizeof info;
    cdm_get_info(dev, &info);
    if (a.truth && std::strcmp(info.transport, "sim") != 0) {
        cdm_close(dev);
        throw UsageError("--truth needs a sim: device (" + a.uri + " is " + info.transport + ")");
    }
    if (!a.calib.empty()) {
        cdm_calibration *cal = nullptr;
        if ((rc = cdm_calibration_load(a.calib.c_str(), &cal)) != CDM_OK) {
            cdm_close(dev);
            return report_error("--calibration " + a.calib, rc);
        }
        cdm_set_calibration(dev, cal); // the device keeps its own reference
        cdm_calibration_free(cal);
    }
    return kExitOk;
}

int cmd_stream(const StreamArgs &a) {
    StreamCtx ctx;
    ctx.truth = a.truth;
    ctx.compensated_only = !a.calib.empty();
    cdm_device *dev = nullptr;
    cdm_device_info info{};
    if (int rc = open_stream(a, ctx, dev, info); rc != kExitOk) return rc;
    const bool tty = !a.json && isatty(fileno(stdout));
    if (!a.json) {
        std::printf("streaming %s (%s, serial %s, %.0f Hz nominal); Ctrl-C stops\n", info.uri, info.transport,
                    info.serial, info.report_rate_hz);
        std::printf("flags: S stale, D disconnected, C compensated, W out of workspace, E end of stream; "
                    "buttons: C clutch, A aux, M mark\n");
        std::printf("age: newest pose's age when printed; delay+: host receipt minus device clock, over the best "
                    "seen (mean/max)\n");
    }
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    const double t0 = now_s();
    double last_t = t0;
    uint64_t last_reports = 0;
    const double period = 1.0 / a.rate;
    bool ended = false;
    while (!g_interrupted && (a.seconds <= 0 || now_s() - t0 < a.seconds)) {
        std::this_thread::sleep_for(std::chrono::duration<double>(period));
        Tick t{};
        t.p.struct_size = sizeof t.p;
        const int rc = cdm_get_pose(dev, &t.p);
        const double now = now_s();
        uint64_t reports;
        {
            std::lock_guard<std::mutex> lock(ctx.mu);
            reports = ctx.reports;
            t.ex_mean = ctx.excess_n ? ctx.excess_sum_ms / double(ctx.excess_n) : 0.0;
            t.ex_max = ctx.excess_max_ms;
            ctx.excess_sum_ms = ctx.excess_max_ms = 0;
            ctx.excess_n = 0;
            std::copy(ctx.last_err, ctx.last_err + 3, t.err);
            t.truth_n = ctx.truth_n;
        }
        t.hz = double(reports - last_reports) / (now - last_t);
        last_reports = reports;
        last_t = now;
        if (rc == CDM_ERR_NO_DATA) {
            if (!a.json) std::printf("%swaiting for the first report...%s", tty ? "\r" : "", tty ? "" : "\n");
            std::fflush(stdout);
            continue;
        }
        t.age_ms = double(int64_t(now_ns() - t.p.host_time_ns)) * 1e-6;
        print_tick(t, tty, a.truth, a.json);
        if (rc == CDM_ERR_END_OF_STREAM) {
            ended = true;
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
    print_stream_summary(a, ctx, st, elapsed, ended, err, tty);
    return kExitOk;
}

const char *const kUriHelp = "device URI: sim:[?options], replay:FILE, hid:/dev/hidrawN, serial:SN";

} // namespace

void add_device_commands(CLI::App &app) {
    auto *list = app.add_subcommand("list", "List the connected masters (USB 1209:cd01)");
    static bool l_json = false;
    static bool l_watch = false;
    static double l_seconds = 0;
    list->add_flag("--json", l_json,
                   "print a JSON array of {uri, serial, firmware, usb_id}; with --watch one JSON object per event "
                   "and line, {event, t_s, uri, serial, firmware, usb_id}");
    list->add_flag("--watch", l_watch,
                   "print the connected masters, then every arrival and departure as it happens (udev's hot-plug "
                   "events), until Ctrl-C");
    list->add_option("--seconds", l_seconds, "with --watch: stop after this many seconds (0: until Ctrl-C)")
        ->check(range(0, 1e9));
    list->callback([] {
        select_command([] {
            if (l_seconds > 0 && !l_watch) throw UsageError("list: --seconds needs --watch");
            return l_watch ? cmd_list_watch(l_json, l_seconds) : cmd_list(l_json);
        });
    });

    auto *info = app.add_subcommand("info", "Show what a device says about itself (feature report 0x02)");
    static std::string info_uri;
    static bool i_json = false;
    static std::vector<std::string> i_plugins;
    info->add_option("URI", info_uri, kUriHelp)->required();
    info->add_flag("--json", i_json, "print one JSON object");
    add_plugin_option(info, i_plugins);
    info->callback([] {
        select_command([] {
            if (int rc = load_plugins(i_plugins); rc != kExitOk) return rc;
            return cmd_info(info_uri, i_json);
        });
    });

    auto *stream = app.add_subcommand("stream", "Print the live pose, report rate, latency and drops");
    static StreamArgs s;
    stream->add_option("URI", s.uri, kUriHelp)->required();
    stream->add_option("--seconds", s.seconds, "stop after this many seconds (0: until Ctrl-C or the end)")
        ->check(range(0, 1e9));
    stream->add_option("--rate", s.rate, "display refresh rate in Hz")->check(range(0.5, 1000));
    stream->add_option("--calibration", s.calib, "apply this calibration (CALIB.json from `cdm calib fit`)");
    stream->add_flag("--truth", s.truth,
                     "sim: only: also show the error against the simulator's true position, and a summary (with "
                     "--calibration: over the poses computed with it)");
    stream->add_flag("--json", s.json, "one JSON object per line per refresh, then a summary object");
    static std::vector<std::string> s_plugins;
    add_plugin_option(stream, s_plugins);
    stream->callback([] {
        select_command([] {
            if (int rc = load_plugins(s_plugins); rc != kExitOk) return rc;
            return cmd_stream(s);
        });
    });
}

} // namespace cdm::cli
