// `cdm record`: a device's reports to a recording (the replay format, MCAP
// or a pose CSV, by the file's extension: docs/recording.md), or with --jig
// a calibration dataset CSV; `cdm export`: a recording converted, by
// recording its replay. Kill-safe: SIGINT, SIGTERM and SIGHUP all finish
// the file cleanly; a write error (a full disk) keeps what was written and
// names the real cause; the output never replaces one of its inputs or a
// file that is not a regular file.
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <cdm/cdm.h>
#include "commands.h"
#include "live_jig.h"
#include "record_files.h"
#include "record_jig.h"

namespace cdm::cli {

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_stop(int) { g_stop = 1; }

void install_stop_handlers() {
    struct sigaction sa {};
    sa.sa_handler = on_stop;
    sigemptyset(&sa.sa_mask);
    for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaction(s, &sa, nullptr);
}

// A rejected report written: counted when the file keeps it (a CSV, which
// holds poses, does not).
void kept_rejected(RecordCtx &c, int rc) {
    if (rc == CDM_OK && !c.csv_file) ++c.rejected;
    after_write(c, rc);
}

// A report the reader discarded is kept too (not in a jig dataset, which
// holds positions): a replay discards it again and counts it as the live
// reader did.
void record_rejected(void *user, const cdm_rejected *r) {
    auto *c = static_cast<RecordCtx *>(user);
    std::lock_guard<std::mutex> lock(c->mu);
    if (c->jig) return;
    if (!c->rec) {
        c->pending.push_back({std::vector<uint8_t>(r->report, r->report + r->report_len), cdm_raw{}, cdm_pose{},
                              r->source_time_ns, r->kind, r->reason});
        return;
    }
    if (!c->write_failed) kept_rejected(*c, cdm_recorder_write_rejected(c->rec, r));
}

void record_sample(void *user, const cdm_sample *s) {
    auto *c = static_cast<RecordCtx *>(user);
    std::lock_guard<std::mutex> lock(c->mu);
    ++c->reports;
    if (!c->jig) {
        if (!c->rec) {
            c->pending.push_back({std::vector<uint8_t>(s->report, s->report + s->report_len), *s->raw, *s->pose,
                                  s->source_time_ns, 0, std::string()});
            return;
        }
        if (!c->write_failed) after_write(*c, cdm_recorder_write_sample(c->rec, s));
        return;
    }
    jig_sample(*c, *s->raw);
}

// The replay header: the device's own info report, byte for byte, so a
// replay converts exactly as this device did.
int open_recorder(cdm_device *dev, const std::string &tmp, const char *format, RecordCtx &ctx) {
    uint8_t info[1024];
    size_t len = 0;
    int rc = cdm_device_info_report(dev, info, sizeof info, &len);
    if (rc != CDM_OK) return report_error("record: device-info report", rc);
    cdm_recorder *rec = nullptr;
    if ((rc = cdm_recorder_open_ex(tmp.c_str(), format, info, len, &rec)) != CDM_OK)
        return report_error("record", rc);
    std::lock_guard<std::mutex> lock(ctx.mu);
    ctx.rec = rec;
    for (const auto &r : ctx.pending) {
        if (r.rejected_kind) {
            cdm_rejected j{};
            j.struct_size = sizeof j;
            j.kind = r.rejected_kind;
            j.report = r.report.data();
            j.report_len = uint32_t(r.report.size());
            j.source_time_ns = r.source_ns;
            j.reason = r.reason.c_str();
            if (!ctx.write_failed) kept_rejected(ctx, cdm_recorder_write_rejected(rec, &j));
            continue;
        }
        cdm_sample s{};
        s.struct_size = sizeof s;
        s.report_len = uint32_t(r.report.size());
        s.report = r.report.data();
        s.raw = &r.raw;
        s.pose = &r.pose;
        s.source_time_ns = r.source_ns;
        if (!ctx.write_failed) after_write(ctx, cdm_recorder_write_sample(rec, &s));
    }
    ctx.pending.clear();
    return kExitOk;
}

void progress(RecordCtx &ctx, bool jig, double t, uint32_t dropped, bool tty) {
    std::lock_guard<std::mutex> lock(ctx.mu);
    if (jig && ctx.next_point < ctx.plan_n) {
        // Where the holder goes next, as the person at the bench reads it:
        // the fixture height, the hole, the samples kept so far.
        int point = 0;
        double ref[3] = {0, 0, 0};
        cdm_jig_plan_get(ctx.plan, ctx.next_point, &point, ref);
        std::fprintf(stderr,
                     "%sjig position %zu/%zu: height %s mm, hole y %s z %s mm: %zu/%d samples (%s), %.1f s, drops "
                     "%u%s",
                     tty ? "\r" : "", ctx.next_point + 1, ctx.plan_n, num(ref[0]).c_str(), num(ref[1]).c_str(),
                     num(ref[2]).c_str(), ctx.in_dwell ? ctx.dwell.size() : size_t(0),
                     cdm_jig_plan_samples_at(ctx.plan, ctx.next_point), ctx.in_dwell ? "MARK held" : "moving", t,
                     dropped, tty ? "   " : "\n");
    } else if (jig) {
        std::fprintf(stderr, "%sjig plan complete (%zu positions), %.1f s%s", tty ? "\r" : "", ctx.plan_n, t,
                     tty ? "   " : "\n");
    } else
        std::fprintf(stderr, "%srecorded %llu reports, %.1f s, drops %u%s", tty ? "\r" : "",
                     (unsigned long long)ctx.reports, t, dropped, tty ? "   " : "\n");
}

// Runs until the time is up, the stream ends, the plan is complete, a write
// fails or a stop signal arrives.
void record_loop(cdm_device *dev, RecordCtx &ctx, double seconds, bool jig) {
    const bool tty = isatty(fileno(stderr));
    const double t0 = now_s();
    double last_print = -1;
    while (!g_stop && !ctx.done && (seconds <= 0 || now_s() - t0 < seconds)) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        cdm_pose p{};
        p.struct_size = sizeof p;
        const bool ended = cdm_get_pose(dev, &p) == CDM_ERR_END_OF_STREAM;
        const double t = now_s() - t0;
        if (ctx.live) {
            print_live(ctx.live->take_messages(), tty);
            if (ctx.live->stop_requested()) {
                std::lock_guard<std::mutex> lock(ctx.mu);
                ctx.live_stopped = ctx.done = true;
            }
        }
        if (t - last_print >= 0.5 || ended) {
            last_print = t;
            progress(ctx, jig, t, p.dropped, tty);
        }
        if (ended) break;
    }
    if (tty) std::fprintf(stderr, "\n");
}

// Completes the file: flush, close, rename into place. After a write error
// (a full disk, an I/O error) the target is never replaced: an existing FILE
// stays as it was, and what was written stays in the temporary, named.
int finish(RecordCtx &ctx, const std::string &tmp, const std::string &file, const cdm_stats &st, bool json) {
    if (ctx.jig) return finish_jig(ctx, file, st, json);
    std::string err = ctx.write_err;
    if (cdm_recorder_close(ctx.rec) != CDM_OK && err.empty()) err = cdm_thread_error();
    if (err.empty()) err = sync_file(tmp);
    if (!err.empty()) {
        std::fprintf(stderr,
                     "cdm: record: %s; %s not replaced (left as it was, if it existed); what was written "
                     "before the error is kept in %s\n",
                     err.c_str(), file.c_str(), tmp.c_str());
        return kExitFailure;
    }
    if (std::rename(tmp.c_str(), file.c_str()) != 0) {
        std::fprintf(stderr, "cdm: record: cannot rename %s to %s: %s\n", tmp.c_str(), file.c_str(),
                     std::strerror(errno));
        return kExitFailure;
    }
    if (ctx.refused_samples)
        std::fprintf(stderr, "cdm: record: %llu samples left out: the file could not hold them (first: %s)\n",
                     (unsigned long long)ctx.refused_samples, ctx.first_refusal.c_str());
    if (json) {
        nlohmann::json j = {{"file", file}, {"format", format_of(file)}, {"samples", ctx.reports},
                            {"rejected", ctx.rejected}, {"stats", stats_json(st)}};
        std::printf("%s\n", j.dump().c_str());
    } else {
        std::printf("wrote %s (%s): %llu reports and %llu rejected ones (%s)\n", file.c_str(), format_of(file),
                    (unsigned long long)ctx.reports, (unsigned long long)ctx.rejected, losses_text(st).c_str());
    }
    return kExitOk;
}

int cmd_record(const std::string &uri, const std::string &file, double seconds, JigArgs ja,
               const std::string &compression, bool exporting = false, bool json = false) {
    const bool live_device = ja.jig && ja.live.on && !ja.live.device.empty();
    check_output(uri, file, {ja.plan, live_device ? ja.live.device : std::string()});
    if (live_device) ja.live_frame = live_device_frame(ja.live.device);
    if (!ja.plan.empty() && !ja.jig) throw UsageError("--plan " + ja.plan + ": a planned session is recorded with --jig");
    std::string format = format_of(file);
    if (!compression.empty()) {
        if (format != "mcap" || ja.jig)
            throw UsageError("--compression " + compression + ": only an MCAP recording (FILE.mcap) has chunks to "
                                                              "compress");
        format += ":" + compression;
    }
    RecordCtx ctx;
    ctx.jig = ja.jig;
    ctx.csv_file = format == "csv";
    const std::string tmp = file + ".tmp";
    install_stop_handlers(); // before the first report: a stop at any moment finishes the file
    if (ja.jig && open_jig(uri, file, ja, ctx) != kExitOk) return kExitFailure;
    cdm_open_options o{};
    o.struct_size = sizeof o;
    o.on_sample = record_sample;
    o.on_rejected = record_rejected;
    o.user = &ctx;
    cdm_device *dev = nullptr;
    int rc = cdm_open_ex(uri.c_str(), &o, &dev);
    if (rc == CDM_OK && exporting) {
        // A recording cut short plays what it holds: say what was lost.
        char warn[512] = "";
        cdm_device_error(dev, warn, sizeof warn);
        if (std::strncmp(warn, "warning:", 8) == 0) std::fprintf(stderr, "cdm: export: %s\n", warn);
    }
    if (rc == CDM_OK && !ja.jig && (rc = open_recorder(dev, tmp, format.c_str(), ctx)) != kExitOk) {
        cdm_close(dev);
        return rc;
    }
    if (rc != CDM_OK) {
        cdm_dataset_writer_free(ctx.csv); // removes its temporary
        cdm_jig_plan_free(ctx.plan);
        return report_error("open " + uri, rc);
    }
    if (ctx.live && !start_live(dev, ja, ctx)) {
        ctx.live->finish();
        cdm_close(dev);
        cdm_dataset_writer_free(ctx.csv); // removes its temporary
        cdm_jig_plan_free(ctx.plan);
        return kExitUsage;
    }
    if (ja.jig) { // the device's ADC full scale, then the samples held for it (after start_live: see jig_start)
        cdm_device_info info{};
        info.struct_size = sizeof info;
        const uint32_t bits = cdm_get_info(dev, &info) == CDM_OK ? info.adc_bits : 16;
        std::lock_guard<std::mutex> lock(ctx.mu);
        jig_start(ctx, bits);
    }
    record_loop(dev, ctx, seconds, ja.jig);
    cdm_stats st{};
    st.struct_size = sizeof st;
    cdm_get_stats(dev, &st);
    cdm_close(dev); // no callback runs after this
    rc = finish(ctx, tmp, file, st, json);
    cdm_jig_plan_free(ctx.plan);
    return rc;
}

} // namespace

void add_record_command(CLI::App &app) {
    auto *record = app.add_subcommand(
        "record", "Record a device's reports to a recording: FILE.mcap MCAP (raw reports and poses, for "
                  "Foxglove), FILE.csv the poses, anything else the replay format; or with --jig a calibration "
                  "dataset CSV. Ctrl-C, SIGTERM and SIGHUP stop it and finish the file.");
    static std::string r_uri, r_file;
    static double r_seconds = 0;
    static JigArgs ja;
    record->add_option("URI", r_uri, "device URI: sim:[?options], replay:FILE, hid:/dev/hidrawN, serial:SN")
        ->required();
    record->add_option("FILE", r_file, "output file (a replay is written to FILE.tmp, which must not exist, and renamed when complete; a jig "
                   "CSV goes through an exclusive temporary and replaces FILE only when whole)")->required();
    record->add_option("--seconds", r_seconds, "stop after this many seconds (0: until Ctrl-C or the end)")
        ->check(range(0, 1e9));
    record->add_flag("--jig", ja.jig,
                     "write the dataset CSV point,x_ref,y_ref,z_ref,l1..l4: each MARK-held dwell is labelled with "
                     "the next jig-plan position");
    record->add_option("--jig-n", ja.n, "holes per side of the plate (0: 25, or the sim: URI's jig_n)")
        ->check(range(0, 1000));
    record->add_option("--jig-pitch", ja.pitch, "hole pitch in mm (0: 5, or the sim: URI's jig_pitch)")
        ->check(range(0, 1000));
    record->add_option("--jig-heights", ja.heights,
                       "comma-separated fixture heights in mm (default 30,40,50,60,70, or the sim: URI's)");
    record->add_option("--jig-samples", ja.samples, "samples kept per position (0: 100, or the sim: URI's)")
        ->check(range(0, 1000000));
    record->add_option("--plan", ja.plan,
                       "with --jig: a planned session, PLAN.csv of `cdm calib plan` (the plate and heights as "
                       "given here): only its positions, in its order, each with its own samples; the progress line "
                       "says which hole at which height comes next");
    add_live_options(record, ja.live);
    static std::string r_compression;
    const char *compression_help = "MCAP's chunk compression: zstd (the default), lz4 (faster, larger) or none";
    record->add_option("--compression", r_compression, compression_help)
        ->check(CLI::IsMember({"zstd", "lz4", "none"}));
    static std::vector<std::string> r_plugins;
    add_plugin_option(record, r_plugins);
    static bool r_json = false;
    record->add_flag("--json", r_json,
                     "print the summary as one JSON object: file, format, samples, rejected (the reports the "
                     "reader discarded that the file keeps: none in a CSV) and the device's counters (stats); with "
                     "--jig: file, positions (in the file), of, samples, reports, short_dwells, stats, "
                     "rail_samples and rail_positions (samples with a pot at full scale, left out; positions with "
                     "every sample so) and live (the live analysis's updates, or null)");
    record->callback([] {
        select_command([] {
            if (int rc = load_plugins(r_plugins); rc != kExitOk) return rc;
            if (ja.live.on && !ja.jig) throw UsageError("--live: a live analysis is of a jig session (--jig)");
            return cmd_record(r_uri, r_file, r_seconds, ja, r_compression, false, r_json);
        });
    });

    auto *exp = app.add_subcommand(
        "export", "Convert a recording (replay format or MCAP) to MCAP, CSV or the replay format, by OUT's "
                  "extension (.mcap, .csv, anything else: replay format): its reports replayed as fast as read, "
                  "with their recorded times, and recorded again with the poses libcdm decodes (docs/recording.md)");
    static std::string e_in, e_out;
    exp->add_option("REC", e_in, "a recording made by cdm record (.cdmrec or .mcap)")->required();
    exp->add_option("OUT", e_out, "output file (written to OUT.tmp, which must not exist, then renamed)")->required();
    static std::string e_compression;
    exp->add_option("--compression", e_compression, compression_help)->check(CLI::IsMember({"zstd", "lz4", "none"}));
    exp->callback([] {
        select_command([] {
            if (e_in.find('?') != std::string::npos)
                throw UsageError("export: REC \"" + e_in + "\" contains '?', which a replay: URI cannot hold");
            return cmd_record("replay:" + e_in + "?speed=0", e_out, 0, JigArgs{}, e_compression, true);
        });
    });
}

} // namespace cdm::cli
