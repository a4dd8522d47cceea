#include "device/recording/replay_format.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

#include "cdm/cdm.h"
#include "device/protocol.h"
#include "io/file.h"
#include "device/recording/recording_mcap.h"

namespace cdm::replay {

namespace {
int parse_error(const std::string &name, size_t offset, const std::string &what, std::string &err) {
    err = name + ": byte " + std::to_string(offset) + ": " + what;
    return CDM_ERR_PARSE;
}
// The writer appends record by record, so a kill or a full disk can only
// cut the last record: keep everything before it, and say so.
void truncated_tail(const std::string &name, size_t off, size_t n, const std::string &where, File &f) {
    f.truncated_bytes = n - off;
    f.warning = name + ": byte " + std::to_string(off) + ": recording ends inside a " + where + "; " +
                std::to_string(n - off) + " trailing bytes dropped, " + std::to_string(f.records.size()) +
                " complete records kept (was the recorder killed, or the disk full?)";
}
} // namespace

int parse(std::vector<uint8_t> bytes, const std::string &name, File &out, std::string &err) {
    const size_t n = bytes.size();
    // An MCAP recording (docs/recording.md) plays the same way: its report
    // channel becomes the records.
    if (n >= 5 && bytes[0] == 0x89 && std::memcmp(bytes.data() + 1, "MCAP", 4) == 0)
        return recording::parse_mcap(std::move(bytes), name, out, err);
    // A text file (a jig CSV given to replay: by mistake) is said to be one,
    // with where it belongs, rather than only "magic missing".
    const size_t head = std::min<size_t>(n, 256);
    const bool text = n > 0 && std::all_of(bytes.begin(), bytes.begin() + long(head), [](uint8_t c) {
        return c == '\n' || c == '\r' || c == '\t' || (c >= 0x20 && c != 0x7F);
    });
    if (text && (n < sizeof kMagic || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0))
        return parse_error(name, 0,
                           "a text file, not a cdm recording (magic \"CDMRPLAY\" missing): replay: plays the replay "
                           "format or MCAP (`cdm record FILE`, `cdm record FILE.mcap`), not a CSV; a jig dataset "
                           "CSV is read by `cdm calib diagnose` or `cdm calib fit`",
                           err);
    if (n < kHeaderSize)
        return parse_error(name, n, "file ends inside the " + std::to_string(kHeaderSize) + "-byte header", err);
    if (std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
        return parse_error(name, 0, "not a cdm recording (magic \"CDMRPLAY\" missing)", err);
    const uint16_t version = proto::get_u16(bytes.data() + 8);
    if (version != kVersion)
        return parse_error(name, 8, "recording format version " + std::to_string(version) + ", this library reads " +
                                        std::to_string(kVersion), err);
    const uint16_t info_len = proto::get_u16(bytes.data() + 10);
    if (info_len == 0 || info_len > kMaxReport)
        return parse_error(name, 10, "device-info length " + std::to_string(info_len) + " out of 1..1024", err);
    if (n < kHeaderSize + info_len)
        return parse_error(name, n, "file ends inside the device-info report (" + std::to_string(info_len) +
                                        " bytes from byte 12)", err);
    File f;
    f.info.assign(bytes.begin() + kHeaderSize, bytes.begin() + kHeaderSize + info_len);
    size_t off = kHeaderSize + info_len;
    uint64_t last_ns = 0;
    while (off < n) {
        if (n - off < kRecordHeaderSize) {
            truncated_tail(name, off, n, "record header", f);
            break;
        }
        const uint64_t t = proto::get_u64(bytes.data() + off);
        const uint16_t len = proto::get_u16(bytes.data() + off + 8);
        if (len == 0 || len > kMaxReport)
            return parse_error(name, off + 8, "record length " + std::to_string(len) + " out of 1..1024", err);
        if (t < last_ns)
            return parse_error(name, off, "host time goes backwards (record " + std::to_string(f.records.size()) + ")",
                               err);
        if (n - off - kRecordHeaderSize < len) {
            truncated_tail(name, off, n, "report (" + std::to_string(len) + " bytes announced)", f);
            break;
        }
        f.records.push_back(Record{t, off + kRecordHeaderSize, len});
        last_ns = t;
        off += kRecordHeaderSize + len;
    }
    f.bytes = std::move(bytes);
    out = std::move(f);
    return CDM_OK;
}

int load(const std::string &path, File &out, std::string &err) {
    // O_NONBLOCK: a FIFO without a writer must not hang the open; it is
    // refused below anyway, like every file that is not regular.
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) {
        err = path + ": cannot open: " + std::strerror(errno);
        return errno == ENOENT ? CDM_ERR_NO_DEVICE : CDM_ERR_IO;
    }
    struct stat st;
    std::vector<uint8_t> bytes;
    int rc = CDM_OK;
    if (::fstat(fd, &st) != 0) {
        err = path + ": cannot stat: " + std::strerror(errno);
        rc = CDM_ERR_IO;
    } else if (!S_ISREG(st.st_mode)) {
        err = path + ": not a regular file (" +
              (S_ISDIR(st.st_mode) ? "a directory" : S_ISFIFO(st.st_mode) ? "a FIFO" : "a device or socket") +
              "): a recording is a file written by cdm record";
        rc = CDM_ERR_INVALID_ARG;
    } else if (uint64_t(st.st_size) > kMaxFileBytes) {
        err = path + ": " + std::to_string(st.st_size) + " bytes, more than the " +
              std::to_string(kMaxFileBytes) + "-byte limit of a recording";
        rc = CDM_ERR_INVALID_ARG;
    } else {
        bytes.resize(size_t(st.st_size));
        size_t got = 0;
        while (got < bytes.size()) {
            const ssize_t r = ::read(fd, bytes.data() + got, bytes.size() - got);
            if (r < 0 && errno == EINTR) continue;
            if (r < 0) {
                err = path + ": read error at byte " + std::to_string(got) + ": " + std::strerror(errno);
                rc = CDM_ERR_IO;
                break;
            }
            if (r == 0) break; // shrank while reading: parse what is there
            got += size_t(r);
        }
        bytes.resize(got);
    }
    ::close(fd);
    if (rc != CDM_OK) return rc;
    return parse(std::move(bytes), path, out, err);
}

bool host_time_in_order(uint64_t host_ns, uint64_t previous_ns, uint64_t n, std::string &err) {
    if (n == 0 || host_ns >= previous_ns) return true;
    err = "host time " + std::to_string(host_ns) + " ns of record " + std::to_string(n) +
          " is before the previous record's " + std::to_string(previous_ns) +
          " ns: host times never decrease in a recording (replay: refuses a file where one does); not written";
    return false;
}

Writer::~Writer() {
    if (fd_ >= 0) ::close(fd_);
}

int Writer::write_all(const uint8_t *p, size_t n, std::string &err) {
    if (failed_) {
        err = fail_text_;
        return CDM_ERR_IO;
    }
    if (const int e = io::write_fully(fd_, p, n)) {
        // Keep the file a valid recording: drop the partial record.
        const bool cut = ::ftruncate(fd_, off_t(bytes_)) == 0 && ::lseek(fd_, off_t(bytes_), SEEK_SET) >= 0;
        failed_ = true;
        fail_text_ = path_ + ": write error after " + std::to_string(records_) + " records (" +
                     std::to_string(bytes_) + " bytes kept" + (cut ? "" : ", last record may be partial") +
                     "): " + std::strerror(e);
        err = fail_text_;
        return CDM_ERR_IO;
    }
    bytes_ += n;
    return CDM_OK;
}

int Writer::open(const std::string &path, const uint8_t *info, size_t info_len, std::string &err) {
    if (fd_ >= 0) {
        err = path_ + ": writer already open";
        return CDM_ERR_INVALID_ARG;
    }
    if (!info || info_len == 0 || info_len > kMaxReport) {
        err = "device-info report of " + std::to_string(info_len) + " bytes (1..1024)";
        return CDM_ERR_INVALID_ARG;
    }
    // A new file only: never truncates an existing one (an earlier
    // recording, or whatever a planted symlink points at).
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC | O_NOCTTY, 0644);
    if (fd_ < 0) {
        err = path + ": cannot create: " + std::strerror(errno) +
              (errno == EEXIST ? " (not writing over an existing file; an interrupted recording plays as replay:)" : "");
        return CDM_ERR_IO;
    }
    path_ = path;
    failed_ = false;
    records_ = bytes_ = last_ns_ = 0;
    std::vector<uint8_t> h(kHeaderSize + info_len);
    std::memcpy(h.data(), kMagic, sizeof kMagic);
    proto::put_u16(h.data() + 8, kVersion);
    proto::put_u16(h.data() + 10, uint16_t(info_len));
    std::memcpy(h.data() + kHeaderSize, info, info_len);
    return write_all(h.data(), h.size(), err);
}

int Writer::write(uint64_t host_ns, const uint8_t *report, size_t len, std::string &err) {
    if (fd_ < 0 || !report || len == 0 || len > kMaxReport) {
        err = fd_ < 0 ? std::string("recording not open") : "record of " + std::to_string(len) + " bytes (1..1024)";
        return CDM_ERR_INVALID_ARG;
    }
    if (failed_) { // a failed writer says why, whatever it is given
        err = fail_text_;
        return CDM_ERR_IO;
    }
    if (!host_time_in_order(host_ns, last_ns_, records_, err)) return CDM_ERR_INVALID_ARG;
    uint8_t rec[kRecordHeaderSize + kMaxReport];
    proto::put_u64(rec, host_ns);
    proto::put_u16(rec + 8, uint16_t(len));
    std::memcpy(rec + kRecordHeaderSize, report, len);
    const int rc = write_all(rec, kRecordHeaderSize + len, err);
    if (rc == CDM_OK) {
        ++records_;
        last_ns_ = host_ns;
    }
    return rc;
}

int Writer::close(std::string &err) {
    if (fd_ < 0) return CDM_OK;
    int rc = failed_ ? CDM_ERR_IO : CDM_OK;
    if (failed_) err = fail_text_;
    std::string close_err;
    if (!io::sync_close(fd_, path_, close_err) && rc == CDM_OK) {
        err = close_err;
        rc = CDM_ERR_IO;
    }
    return rc;
}

} // namespace cdm::replay
