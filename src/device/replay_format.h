// The recording format of `cdm record` and `replay:FILE` (docs/protocol.md,
// "Replay files"): a header carrying the device-info feature report, then
// every input report as it arrived with its host receipt time. Reports are
// stored as raw wire bytes, so a replay goes through the same parser as the
// device did.
#pragma once

#include <cstdint>
#include <cstdio>
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

struct File {
    std::vector<uint8_t> bytes;
    std::vector<uint8_t> info; // device-info feature report, report ID first
    std::vector<Record> records;
};

// Checks the whole framing up front, so that a truncated or corrupt file is
// refused when opened (CDM_ERR_PARSE, err = "NAME: byte OFFSET: what")
// rather than failing half-way through a replay. The reports' contents are
// left to the protocol parser at play time.
int parse(std::vector<uint8_t> bytes, const std::string &name, File &out, std::string &err);
int load(const std::string &path, File &out, std::string &err);

// Writes a recording. Not thread-safe; the caller serialises.
class Writer {
public:
    Writer() = default;
    ~Writer();
    Writer(const Writer &) = delete;
    Writer &operator=(const Writer &) = delete;
    int open(const std::string &path, const uint8_t *info, size_t info_len, std::string &err);
    int write(uint64_t host_ns, const uint8_t *report, size_t len, std::string &err);
    int close(std::string &err); // flushes; an error here means the file is incomplete
private:
    std::FILE *f_ = nullptr;
    std::string path_;
};

} // namespace cdm::replay
