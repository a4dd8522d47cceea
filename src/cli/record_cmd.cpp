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

struct JigArgs {
    bool jig = false;
    int n = 0;
    double pitch = 0;
    std::string heights;
    int samples = 0;
    std::string plan; // PLAN.csv of `cdm calib plan`: only its positions, in its order
    LiveOptions live; // --live: diagnosed as it is recorded, stops by itself (live_jig.h)
    std::array<double, 3> live_frame{}; // --device's frame, read before anything opens
};

struct RecordCtx {
    std::mutex mu;
    // replay
    cdm_recorder *rec = nullptr;
    // Samples that arrive before the recorder is open (it needs the
    // device-info report, read after cdm_open_ex returns).
    struct Pending {
        std::vector<uint8_t> report;
        cdm_raw raw;
        cdm_pose pose;
        uint64_t source_ns;
        uint32_t rejected_kind; // 0: a sample; else a cdm_rejected_kind
        std::string reason;
    };
    std::vector<Pending> pending;
    bool write_failed = false;
    std::string write_err;
    // jig
    bool jig = false;
    cdm_jig_plan *plan = nullptr;
    size_t plan_n = 0;
    cdm_dataset_writer *csv = nullptr;
    size_t next_point = 0;
    bool in_dwell = false;
    std::vector<std::array<double, 4>> dwell;
    std::vector<double> dwell_t;     // each sample's device time since the first sample (s): the t_s column
    bool have_t0 = false;
    uint64_t t0_us = 0;
    uint64_t short_dwells = 0;
    uint64_t kept_samples = 0; // rows handed to the dataset writer
    // Samples the dataset writer refused (a reading the reader would
    // refuse: a glitch to a non-positive length): left out, the session
    // goes on; the first reason is told at the end.
    uint64_t refused_samples = 0;
    std::string first_refusal;
    std::atomic<bool> done{false};
    std::unique_ptr<LiveJig> live; // with --live
    bool live_stopped = false;     // the live analysis ended the session: the model is determined
    // both
    uint64_t reports = 0;
    uint64_t rejected = 0; // reports the reader discarded, kept in the recording
    bool csv_file = false; // a pose CSV: no rejected report is kept
};

// A write's outcome. A sample the writer refused (CDM_ERR_INVALID_ARG:
// nothing of it was written) is counted and the session goes on; any other
// failure (I/O) ends it. The texts are this thread's: the reader's.
void after_write(RecordCtx &c, int rc) {
    if (rc == CDM_OK) return;
    if (rc == CDM_ERR_INVALID_ARG) {
        if (c.refused_samples++ == 0) c.first_refusal = cdm_thread_error();
        return;
    }
    c.write_failed = true;
    c.write_err = cdm_thread_error();
    c.done = true;
}

void close_dwell(RecordCtx &c) {
    c.in_dwell = false;
    if (c.next_point >= c.plan_n) return;
    if (c.dwell.size() < size_t(cdm_jig_plan_samples_at(c.plan, c.next_point))) {
        // Released too early: the same position is asked for again.
        ++c.short_dwells;
        c.dwell.clear();
        c.dwell_t.clear();
        return;
    }
    int point = 0;
    double ref[3] = {0, 0, 0};
    cdm_jig_plan_get(c.plan, c.next_point, &point, ref);
    size_t kept = 0; // the rows the writer took, moved to the front for the live analysis
    for (size_t k = 0; k < c.dwell.size() && !c.write_failed; ++k) {
        const int rc = cdm_dataset_writer_add_at(c.csv, point, ref, c.dwell[k].data(), c.dwell_t[k]);
        if (rc == CDM_OK) {
            ++c.kept_samples;
            c.dwell[kept] = c.dwell[k], c.dwell_t[kept] = c.dwell_t[k], ++kept;
        }
        after_write(c, rc);
    }
    c.dwell.resize(kept), c.dwell_t.resize(kept);
    if (c.live && !c.write_failed && kept && c.live->add(c.next_point, point, ref, c.dwell, c.dwell_t))
        c.live_stopped = c.done = true;
    c.dwell.clear();
    c.dwell_t.clear();
    if (++c.next_point == c.plan_n) c.done = true;
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
    if (c->done) return;
    if (s->raw->buttons & CDM_BUTTON_MARK) {
        if (!c->in_dwell) {
            c->in_dwell = true;
            c->dwell.clear();
            c->dwell_t.clear();
        }
        if (!c->have_t0) {
            c->have_t0 = true;
            c->t0_us = s->raw->device_time_us;
        }
        if (c->dwell.size() < size_t(cdm_jig_plan_samples_at(c->plan, c->next_point))) {
            c->dwell.push_back({s->raw->lengths_mm[0], s->raw->lengths_mm[1], s->raw->lengths_mm[2],
                                s->raw->lengths_mm[3]});
            // The device's own clock: acquisition time however fast the
            // recording is replayed (realtime=0).
            c->dwell_t.push_back(double(int64_t(s->raw->device_time_us - c->t0_us)) * 1e-6);
        }
    } else if (c->in_dwell) {
        close_dwell(*c);
    }
}

cdm_jig_plan *jig_plan_for(const std::string &uri, const JigArgs &a) {
    std::vector<double> heights;
    if (!a.heights.empty()) heights = parse_number_list(a.heights, "--jig-heights");
    cdm_jig_plan *plan = nullptr;
    if (cdm_jig_plan_create(uri.c_str(), a.n, a.pitch, heights.data(), heights.size(), a.samples, &plan) != CDM_OK)
        throw UsageError(std::string("record --jig: ") + cdm_thread_error());
    if (!a.plan.empty() && cdm_jig_plan_use_file(plan, a.plan.c_str()) != CDM_OK) {
        const std::string why = cdm_thread_error();
        cdm_jig_plan_free(plan);
        throw UsageError("record --jig --plan: " + why);
    }
    return plan;
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

// The live analysis's lines, each on its own (the progress line, on a
// terminal, is rewritten in place: a line goes below it).
void print_live(const std::vector<std::string> &lines, bool tty) {
    for (const auto &l : lines) std::fprintf(stderr, "%s%s\n", tty ? "\n" : "", l.c_str());
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

// A jig dataset completed: committed (fsync, rename) only whole, so after a
// write error the old FILE, if any, is left as it was; then the summary,
// with the live analysis's when there was one. A session that ended before
// its plan fails, unless the live analysis ended it (the model determined).
int finish_jig(RecordCtx &ctx, const std::string &file, const cdm_stats &st, bool json) {
    // The stream ended, or the session was stopped, with MARK still held:
    // a whole dwell is kept, a partial one dropped (it is not asked for
    // again: not a short dwell).
    if (ctx.in_dwell && ctx.next_point < ctx.plan_n &&
        ctx.dwell.size() >= size_t(cdm_jig_plan_samples_at(ctx.plan, ctx.next_point)))
        close_dwell(ctx);
    nlohmann::json live = ctx.live ? ctx.live->finish() : nlohmann::json(nullptr);
    if (ctx.live) {
        print_live(ctx.live->take_messages(), false);
        ctx.live_stopped = live.value("stopped", false); // what the summary says, and the exit status
    }
    std::string err = ctx.write_err;
    const bool ok = err.empty() && cdm_dataset_writer_commit(ctx.csv) == CDM_OK;
    if (!ok && err.empty()) err = cdm_thread_error();
    cdm_dataset_writer_free(ctx.csv);
    ctx.csv = nullptr;
    if (!ok) {
        std::fprintf(stderr, "cdm: record: %s; %s not written\n", err.c_str(), file.c_str());
        return kExitFailure;
    }
    if (ctx.refused_samples)
        std::fprintf(stderr, "cdm: record: %llu samples left out: the file could not hold them (first: %s)\n",
                     (unsigned long long)ctx.refused_samples, ctx.first_refusal.c_str());
    if (json) {
        const nlohmann::json j = {{"file", file},           {"positions", ctx.next_point}, {"of", ctx.plan_n},
                                  {"samples", ctx.kept_samples}, {"reports", ctx.reports},
                                  {"short_dwells", ctx.short_dwells}, {"stats", stats_json(st)},
                                  {"live", live}};
        std::printf("%s\n", j.dump().c_str());
    } else {
        std::printf("wrote %s: %zu of %zu jig positions (%llu samples; %llu reports, %llu dwells too short and "
                    "repeated, %llu dropped)\n",
                    file.c_str(), ctx.next_point, ctx.plan_n, (unsigned long long)ctx.kept_samples,
                    (unsigned long long)ctx.reports, (unsigned long long)ctx.short_dwells,
                    (unsigned long long)st.dropped);
    }
    if (ctx.live_stopped) {
        std::fprintf(stderr, "cdm: record: the live analysis ended the session after %zu of %zu positions: the "
                             "model is determined\n", ctx.next_point, ctx.plan_n);
    } else if (ctx.next_point < ctx.plan_n) {
        std::fprintf(stderr, "cdm: record: the session stopped before the jig plan was complete\n");
        return kExitFailure;
    }
    return kExitOk;
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

// The jig plan and the dataset writer, and with --live the analysis (its
// thread waits for start_live).
int open_jig(const std::string &uri, const std::string &file, const JigArgs &ja, RecordCtx &ctx) {
    ctx.plan = jig_plan_for(uri, ja);
    ctx.plan_n = cdm_jig_plan_count(ctx.plan);
    auto inputs = uri_inputs(uri);
    if (!ja.plan.empty()) inputs.push_back(ja.plan);
    if (ja.live.on && !ja.live.device.empty()) inputs.push_back(ja.live.device);
    std::vector<const char *> protect;
    for (const auto &p : inputs) protect.push_back(p.c_str());
    if (cdm_dataset_writer_open(file.c_str(), protect.data(), protect.size(), &ctx.csv) != CDM_OK) {
        std::fprintf(stderr, "cdm: record: %s\n", cdm_thread_error());
        cdm_jig_plan_free(ctx.plan);
        return kExitFailure;
    }
    if (!ja.live.on) return kExitOk;
    LiveSession s;
    for (size_t i = 0; i < ctx.plan_n; ++i) {
        int point = 0;
        std::array<double, 3> ref{};
        cdm_jig_plan_get(ctx.plan, i, &point, ref.data());
        s.positions.push_back(ref);
    }
    s.samples = cdm_jig_plan_samples(ctx.plan);
    size_t nh = 0;
    if (cdm_jig_plan_plate(ctx.plan, &s.holes, &s.pitch_mm, nullptr, 0, &nh) == CDM_OK) {
        s.heights_mm.resize(nh);
        cdm_jig_plan_plate(ctx.plan, nullptr, nullptr, s.heights_mm.data(), nh, &nh);
    }
    ctx.live = std::make_unique<LiveJig>(ja.live, std::move(s), unpaced(uri));
    return kExitOk;
}

// The live analysis started with the device's nominal geometry, or the
// --device file's when it is the device's frame (false, said, when it is
// another: a usage error, before anything is recorded). When it cannot
// start otherwise, the session is recorded without it (nothing is lost).
bool start_live(cdm_device *dev, const JigArgs &ja, RecordCtx &ctx) {
    cdm_device_info info{};
    info.struct_size = sizeof info;
    std::string err;
    if (cdm_get_info(dev, &info) != CDM_OK) {
        err = std::string("the device's information: ") + cdm_thread_error();
    } else if (!ja.live.device.empty() &&
               !(err = live_frame_mismatch(ja.live.device, ja.live_frame, {info.a_mm, info.b_mm, info.m_mm}))
                    .empty()) {
        std::fprintf(stderr, "cdm: record: %s\n", err.c_str());
        return false;
    } else if (ctx.live->start(info.a_mm, info.b_mm, info.m_mm, err)) {
        return true;
    }
    std::fprintf(stderr, "cdm: record: --live: %s; recording without the live analysis\n", err.c_str());
    ctx.live->finish(); // first: a reader waiting for an update (holding ctx.mu) is let go
    std::lock_guard<std::mutex> lock(ctx.mu);
    ctx.live.reset();
    return true;
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
                     "--jig: file, positions, of, samples, reports, short_dwells, stats and live (the live "
                     "analysis's updates, or null)");
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
