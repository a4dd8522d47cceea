// The recordings `cdm record` and `cdm export` write (docs/recording.md):
// the replay format (replay_format.h), MCAP with the raw reports and the
// decoded poses as channels (recording_mcap.h), or a CSV of the poses. One
// interface, so the command records the same way whatever the format.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "cdm/cdm.h"

namespace cdm::recording {

enum class Format { Replay, Mcap, Csv };

// By the file name's extension: ".mcap" MCAP, ".csv" the pose CSV,
// anything else the replay format (".cdmrec" by convention).
Format format_for_path(const std::string &path);
// "cdmrec", "mcap", "csv" (what cdm_recorder_open_ex takes), and MCAP
// with its chunks' compression named: "mcap:zstd" (what "mcap" means),
// "mcap:lz4", "mcap:none"; false if none. `compression` gets the name after
// "mcap:" ("" without one).
bool parse_format(const std::string &name, Format &out, std::string *compression = nullptr);

// Not thread-safe: the caller serialises (the C API's recorder says so).
class Writer {
public:
    virtual ~Writer() = default;
    // One input report as received, its host time (ns, CLOCK_MONOTONIC of
    // the recording machine; MCAP logs it shifted to wall-clock time) and, when known, the pose libcdm decoded from
    // it (MCAP and CSV keep it; the replay format keeps only the bytes).
    // Returns CDM_OK or a cdm_error with err set. A host time before the
    // previous report's is refused (CDM_ERR_INVALID_ARG, nothing written,
    // the writer goes on): replay: refuses a file where time goes back.
    virtual int write(uint64_t host_ns, const uint8_t *report, size_t len, const cdm_pose *pose,
                      std::string &err) = 0;
    // A report the reader discarded (kind "malformed" or "out_of_order",
    // the reason in words): its bytes as write()'s without a pose, so a
    // replay discards it again. MCAP also logs the reason; a CSV, which
    // holds poses, skips it.
    virtual int write_rejected(uint64_t host_ns, const uint8_t *report, size_t len, const char *kind,
                               const char *reason, std::string &err) {
        (void)kind, (void)reason;
        return write(host_ns, report, len, nullptr, err);
    }
    // Completes the file (MCAP: summary and footer) and fsyncs it. What was
    // written before an error stays.
    virtual int close(std::string &err) = 0;
    virtual uint64_t reports() const = 0;
};

// Creates `path` (a new file: never over an existing one) in `format`,
// starting with the device-info feature report (report ID first; checked
// by the protocol parser before the file is created, whatever the format,
// since every replay needs it: CDM_ERR_INVALID_ARG naming what is wrong).
// `compression`: MCAP's chunks ("zstd" or "" the default, "lz4", "none").
int open_writer(const std::string &path, Format format, const uint8_t *info, size_t info_len,
                std::unique_ptr<Writer> &out, std::string &err, const std::string &compression = "");

// The CSV's header line (docs/recording.md lists the columns and units).
extern const char *const kCsvHeader;

} // namespace cdm::recording
