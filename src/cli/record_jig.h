// `cdm record --jig`: a calibration dataset recorded from a device's MARK
// dwells (record_jig.cpp), beside the recording of reports in
// record_cmd.cpp; the state both share (RecordCtx) and the jig's steps:
// each sample, each completed dwell, the plan, the live analysis, the end.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <cdm/cdm.h>
#include "live_jig.h"

namespace cdm::cli {

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
    // A pot at its ADC's full scale reads a clipped count, not a length
    // (libcdm's rule: no position from it): such samples are counted and
    // left out; a position with every sample so is skipped (beyond the
    // pots' range), never written as data. The full scale is the device's:
    // samples wait in jig_pending until jig_start() has read it.
    std::vector<uint8_t> dwell_rail;
    bool jig_ready = false;
    std::vector<cdm_raw> jig_pending;
    uint32_t adc_full_scale = 0;
    uint64_t rail_samples = 0;
    std::vector<size_t> rail_positions; // skipped: every sample at full scale
    size_t positions_in_file = 0;
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

// A write's outcome: a refused sample is counted, a failure ends the session.
void after_write(RecordCtx &c, int rc);
// A sample of a jig session: kept while MARK is held, the dwell closed when
// it is released (the reader's thread, under c.mu); held in jig_pending
// until jig_start().
void jig_sample(RecordCtx &c, const cdm_raw &r);
// The device's ADC full scale known (from its info, after the open and
// after start_live): the samples held so far are taken, in order. Under
// c.mu; on an unpaced source it may wait for the live analysis's updates,
// which never take c.mu.
void jig_start(RecordCtx &c, uint32_t adc_bits);
// The live analysis's lines, each on its own line.
void print_live(const std::vector<std::string> &lines, bool tty);
// The plan and the dataset writer (and the analysis with --live).
int open_jig(const std::string &uri, const std::string &file, const JigArgs &ja, RecordCtx &ctx);
// The analysis started on the open device; false (said) for a --device of another frame.
bool start_live(cdm_device *dev, const JigArgs &ja, RecordCtx &ctx);
// The dataset committed and the summary printed; the exit status.
int finish_jig(RecordCtx &ctx, const std::string &file, const cdm_stats &st, bool json);

} // namespace cdm::cli
