// The recording format of `cdm record` and `replay:FILE` (docs/protocol.md,
// "Replay files"): a header carrying the device-info feature report, then
// every input report as it arrived with its host receipt time. Reports are
// stored as raw wire bytes, so a replay goes through the same parser as the
// device did.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cdm::replay {

constexpr char kMagic[8] = {'C', 'D', 'M', 'R', 'P', 'L', 'A', 'Y'};
constexpr uint16_t kVersion = 1;
constexpr size_t kHeaderSize = 12;       // magic, version u16, info length u16
constexpr size_t kRecordHeaderSize = 10; // host time u64, length u16
constexpr size_t kMaxReport = 1024;      // longer than any report of any protocol version

struct Record {
    uint64_t host_ns;
    size_t offset; // of the report bytes in File::bytes
    uint16_t length;
};

// Largest recording load() reads into memory: 2 GiB is about 8 hours of
// 1 kHz reports at 74 bytes each.
constexpr uint64_t kMaxFileBytes = uint64_t(2) << 30;

struct File {
    std::vector<uint8_t> bytes;
    std::vector<uint8_t> info; // device-info feature report, report ID first
    std::vector<Record> records;
    // A recording cut by a kill or a full disk ends inside its last record:
    // those bytes are dropped, and `warning` says where and how many.
    uint64_t truncated_bytes = 0;
    std::string warning;
};

// Reads either format: a file starting with MCAP's magic is read as the
// MCAP layout of docs/recording.md (recording_mcap.h), with the same error
// and truncation rules. Checks the whole framing up front, so that a corrupt file is refused when
// opened (CDM_ERR_PARSE, err = "NAME: byte OFFSET: what") rather than
// failing half-way through a replay. The one damage accepted is a truncated
// tail (an incomplete last record): every complete record before it plays.
// A file cut inside the header or the device-info report is refused. The
// reports' contents are left to the protocol parser at play time.
int parse(std::vector<uint8_t> bytes, const std::string &name, File &out, std::string &err);
// Regular files only (a directory, FIFO or device is refused without
// blocking), at most kMaxFileBytes; errors carry strerror.
int load(const std::string &path, File &out, std::string &err);

// Host times never decrease in a recording: parse() refuses a file where
// one does, whatever its format, so every recording writer refuses such a
// record before writing anything of it. False when `host_ns` (the n-th
// record's, 0-based) is before `previous_ns` (the record before it's),
// with err naming both.
bool host_time_in_order(uint64_t host_ns, uint64_t previous_ns, uint64_t n, std::string &err);

// Writes a recording, append-only: every write() hands its record to the
// kernel at once (one write(2), no user-space buffer), so a process killed
// by any signal leaves every record it wrote, and at worst one incomplete
// record that parse() drops. A failed write (ENOSPC, EIO) truncates the file
// back to the last complete record, reports the errno, and leaves the writer
// failed: later writes return the same error; close() keeps the file.
// A record whose host time is before the previous one's is refused
// (CDM_ERR_INVALID_ARG, host_time_in_order) and nothing of it is written;
// the writer goes on. Not thread-safe; the caller serialises.
class Writer {
public:
    Writer() = default;
    ~Writer(); // closes (what was written stays)
    Writer(const Writer &) = delete;
    Writer &operator=(const Writer &) = delete;
    // Creates or truncates `path` (mode 0644) and writes the header. The
    // caller (cdm record) chooses the name; rename it after close() if it
    // records to a temporary.
    int open(const std::string &path, const uint8_t *info, size_t info_len, std::string &err);
    int write(uint64_t host_ns, const uint8_t *report, size_t len, std::string &err);
    // fsyncs and closes. An error here names the errno; the records already
    // written stay in the file.
    int close(std::string &err);
    uint64_t records() const { return records_; }
    uint64_t bytes() const { return bytes_; } // complete bytes in the file
private:
    int write_all(const uint8_t *p, size_t n, std::string &err);
    int fd_ = -1;
    bool failed_ = false;
    std::string path_, fail_text_;
    uint64_t records_ = 0, bytes_ = 0;
    uint64_t last_ns_ = 0; // the last record's host time
};

} // namespace cdm::replay
