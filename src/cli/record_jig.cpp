#include "record_jig.h"

#include <cstdio>
#include <cstring>

#include "commands.h"
#include "record_files.h"

namespace cdm::cli {

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

namespace {

void close_dwell(RecordCtx &c) {
    c.in_dwell = false;
    if (c.next_point >= c.plan_n) return;
    if (c.dwell.size() < size_t(cdm_jig_plan_samples_at(c.plan, c.next_point))) {
        // Released too early: the same position is asked for again.
        ++c.short_dwells;
        c.dwell.clear();
        c.dwell_t.clear();
        c.dwell_rail.clear();
        return;
    }
    int point = 0;
    double ref[3] = {0, 0, 0};
    cdm_jig_plan_get(c.plan, c.next_point, &point, ref);
    size_t kept = 0, rail = 0; // the rows the writer took, moved to the front for the live analysis
    for (size_t k = 0; k < c.dwell.size() && !c.write_failed; ++k) {
        if (c.dwell_rail[k]) {
            ++rail;
            continue;
        }
        const int rc = cdm_dataset_writer_add_at(c.csv, point, ref, c.dwell[k].data(), c.dwell_t[k]);
        if (rc == CDM_OK) {
            ++c.kept_samples;
            c.dwell[kept] = c.dwell[k], c.dwell_t[kept] = c.dwell_t[k], ++kept;
        }
        after_write(c, rc);
    }
    c.rail_samples += rail;
    if (rail && rail == c.dwell.size()) c.rail_positions.push_back(c.next_point);
    if (kept) ++c.positions_in_file;
    c.dwell.resize(kept), c.dwell_t.resize(kept);
    if (c.live && !c.write_failed && kept && c.live->add(c.next_point, point, ref, c.dwell, c.dwell_t))
        c.live_stopped = c.done = true;
    c.dwell.clear();
    c.dwell_t.clear();
    c.dwell_rail.clear();
    if (++c.next_point == c.plan_n) c.done = true;
}

} // namespace

void jig_start(RecordCtx &c, uint32_t adc_bits) {
    c.adc_full_scale = adc_bits >= 1 && adc_bits <= 16 ? (1u << adc_bits) - 1u : 0xFFFFu;
    c.jig_ready = true;
    for (const cdm_raw &r : c.jig_pending) jig_sample(c, r);
    c.jig_pending.clear();
    c.jig_pending.shrink_to_fit();
}

void jig_sample(RecordCtx &c, const cdm_raw &r) {
    if (!c.jig_ready) {
        c.jig_pending.push_back(r);
        return;
    }
    const cdm_raw *raw = &r;
    if (c.done) return;
    if (raw->buttons & CDM_BUTTON_MARK) {
        if (!c.in_dwell) {
            c.in_dwell = true;
            c.dwell.clear();
            c.dwell_t.clear();
            c.dwell_rail.clear();
        }
        if (!c.have_t0) {
            c.have_t0 = true;
            c.t0_us = raw->device_time_us;
        }
        if (c.dwell.size() < size_t(cdm_jig_plan_samples_at(c.plan, c.next_point))) {
            c.dwell.push_back({raw->lengths_mm[0], raw->lengths_mm[1], raw->lengths_mm[2],
                                raw->lengths_mm[3]});
            bool rail = false;
            for (uint16_t a : raw->pot_adc) rail = rail || a >= c.adc_full_scale;
            c.dwell_rail.push_back(rail);
            // The device's own clock: acquisition time however fast the
            // recording is replayed (realtime=0).
            c.dwell_t.push_back(double(int64_t(raw->device_time_us - c.t0_us)) * 1e-6);
        }
    } else if (c.in_dwell) {
        close_dwell(c);
    }
}

namespace {
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

} // namespace

// The live analysis's lines, each on its own (the progress line, on a
// terminal, is rewritten in place: a line goes below it).
void print_live(const std::vector<std::string> &lines, bool tty) {
    for (const auto &l : lines) std::fprintf(stderr, "%s%s\n", tty ? "\n" : "", l.c_str());
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
    if (ctx.rail_samples) // first: it may be why nothing can be committed
        std::fprintf(stderr,
                     "cdm: record: warning: %llu samples left out: a pot at its ADC's full scale (%u counts) reads "
                     "a clipped count, not a length; %zu position%s had every sample so and %s not in the file%s\n",
                     (unsigned long long)ctx.rail_samples, unsigned(ctx.adc_full_scale), ctx.rail_positions.size(),
                     ctx.rail_positions.size() == 1 ? "" : "s", ctx.rail_positions.size() == 1 ? "is" : "are",
                     ctx.rail_positions.empty() ? "" : " (beyond the pots' range: `cdm record --json` lists them)");
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
    const size_t in_file = ctx.positions_in_file;
    if (json) {
        nlohmann::json rail = nlohmann::json::array();
        for (size_t i : ctx.rail_positions) {
            int point = 0;
            double ref[3];
            cdm_jig_plan_get(ctx.plan, i, &point, ref);
            rail.push_back({ref[0], ref[1], ref[2]});
        }
        const nlohmann::json j = {{"file", file},           {"positions", in_file}, {"of", ctx.plan_n},
                                  {"samples", ctx.kept_samples}, {"reports", ctx.reports},
                                  {"short_dwells", ctx.short_dwells}, {"stats", stats_json(st)},
                                  {"rail_samples", ctx.rail_samples}, {"rail_positions", rail},
                                  {"live", live}};
        std::printf("%s\n", j.dump().c_str());
    } else {
        std::printf("wrote %s: %zu of %zu jig positions (%llu samples; %llu reports, %llu dwells too short and "
                    "repeated, %llu dropped)\n",
                    file.c_str(), in_file, ctx.plan_n, (unsigned long long)ctx.kept_samples,
                    (unsigned long long)ctx.reports, (unsigned long long)ctx.short_dwells,
                    (unsigned long long)st.dropped);
    }
    if (ctx.live_stopped) {
        std::fprintf(stderr, "cdm: record: the live analysis ended the session after %zu of %zu positions walked: "
                             "the model is determined\n", ctx.next_point, ctx.plan_n);
    } else if (ctx.next_point < ctx.plan_n) {
        std::fprintf(stderr, "cdm: record: the session stopped before the jig plan was complete\n");
        return kExitFailure;
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

} // namespace cdm::cli
