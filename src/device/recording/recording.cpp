#include "device/recording/recording.h"

#include <fcntl.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstddef>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "device/protocol.h"
#include "device/recording/recording_mcap.h"
#include "device/recording/replay_format.h"
#include "io/file.h"

namespace cdm::recording {

const char *const kCsvHeader = "host_time_ns,sequence,device_time_us,x_mm,y_mm,z_mm,qw,qx,qy,qz,grip_rad,buttons,"
                               "flags,vx_mm_s,vy_mm_s,vz_mm_s,dropped";

namespace {

bool ends_with(const std::string &s, const char *suffix) {
    const size_t n = std::strlen(suffix);
    if (s.size() < n) return false;
    for (size_t i = 0; i < n; ++i)
        if (std::tolower(static_cast<unsigned char>(s[s.size() - n + i])) != suffix[i]) return false;
    return true;
}

class ReplayWriter final : public Writer {
public:
    int open(const std::string &path, const uint8_t *info, size_t len, std::string &err) {
        return w_.open(path, info, len, err);
    }
    int write(uint64_t host_ns, const uint8_t *report, size_t len, const cdm_pose *, std::string &err) override {
        return w_.write(host_ns, report, len, err); // the replay format keeps the bytes; poses come from them
    }
    int close(std::string &err) override { return w_.close(err); }
    uint64_t reports() const override { return w_.records(); }

private:
    replay::Writer w_;
};

// Rows are buffered and handed to the kernel 64 KiB at a time: a CSV is an
// export, whose atomicity comes from the temporary it is written to.
class CsvWriter final : public Writer {
public:
    ~CsvWriter() override {
        if (fd_ >= 0) ::close(fd_);
    }
    int open(const std::string &path, std::string &err) {
        fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC | O_NOCTTY, 0644);
        if (fd_ < 0) {
            err = path + ": cannot create: " + std::strerror(errno) +
                  (errno == EEXIST ? " (not writing over an existing file)" : "");
            return CDM_ERR_IO;
        }
        path_ = path;
        buf_ = std::string(kCsvHeader) + "\n";
        return CDM_OK;
    }
    int write(uint64_t host_ns, const uint8_t *, size_t, const cdm_pose *p, std::string &err) override {
        if (!p) {
            err = path_ + ": a CSV recording holds poses: every row needs one";
            return CDM_ERR_INVALID_ARG;
        }
        // After a failed write the file is ended: a row is not buffered to
        // grow the memory of a caller that keeps writing.
        if (!fail_.empty()) {
            err = fail_;
            return CDM_ERR_IO;
        }
        // Not replayed, but a recording all the same: its host_time_ns
        // column keeps the order the replayable formats must keep.
        if (!replay::host_time_in_order(host_ns, last_ns_, rows_, err)) return CDM_ERR_INVALID_ARG;
        last_ns_ = host_ns;
        const double *v = p->struct_size >= offsetof(cdm_pose, velocity) + sizeof p->velocity ? p->velocity : zero_;
        buf_ += std::to_string(host_ns) + "," + std::to_string(p->sequence) + "," + std::to_string(p->device_time_us);
        for (double x : {p->position[0], p->position[1], p->position[2], p->orientation[0], p->orientation[1],
                         p->orientation[2], p->orientation[3], p->grip}) {
            buf_ += ',';
            append_number(buf_, x);
        }
        buf_ += "," + std::to_string(p->buttons) + "," + std::to_string(p->flags);
        for (int k = 0; k < 3; ++k) {
            buf_ += ',';
            append_number(buf_, v[k]);
        }
        buf_ += "," + std::to_string(p->dropped) + "\n";
        ++rows_;
        return buf_.size() < (64u << 10) ? CDM_OK : flush(err);
    }
    int write_rejected(uint64_t, const uint8_t *, size_t, const char *, const char *, std::string &) override {
        return CDM_OK; // no pose, no row: a CSV is not replayed
    }
    int close(std::string &err) override {
        if (fd_ < 0) return CDM_OK;
        int rc = flush(err);
        std::string close_err;
        if (!io::sync_close(fd_, path_, close_err) && rc == CDM_OK) {
            err = close_err;
            rc = CDM_ERR_IO;
        }
        return rc;
    }
    uint64_t reports() const override { return rows_; }

private:
    int flush(std::string &err) {
        if (!fail_.empty()) {
            err = fail_;
            return CDM_ERR_IO;
        }
        if (const int e = io::write_fully(fd_, buf_.data(), buf_.size())) {
            fail_ = path_ + ": write error after " + std::to_string(rows_) + " rows: " + std::strerror(e);
            err = fail_;
            return CDM_ERR_IO;
        }
        buf_.clear();
        return CDM_OK;
    }
    static constexpr double zero_[3] = {0, 0, 0};
    int fd_ = -1;
    std::string path_, buf_, fail_;
    uint64_t rows_ = 0;
    uint64_t last_ns_ = 0; // the last row's host time
};

} // namespace

Format format_for_path(const std::string &path) {
    if (ends_with(path, ".mcap")) return Format::Mcap;
    if (ends_with(path, ".csv")) return Format::Csv;
    return Format::Replay;
}

bool parse_format(const std::string &name, Format &out, std::string *compression) {
    if (compression) compression->clear();
    if (name == "cdmrec") out = Format::Replay;
    else if (name == "mcap") out = Format::Mcap;
    else if (name == "mcap:zstd" || name == "mcap:lz4" || name == "mcap:none") {
        out = Format::Mcap;
        if (compression) *compression = name.substr(5);
    }
    else if (name == "csv") out = Format::Csv;
    else return false;
    return true;
}

int open_writer(const std::string &path, Format format, const uint8_t *info, size_t info_len,
                std::unique_ptr<Writer> &out, std::string &err, const std::string &compression) {
    if (!info || info_len == 0 || info_len > replay::kMaxReport) {
        err = "device-info report of " + std::to_string(info_len) + " bytes (1..1024)";
        return CDM_ERR_INVALID_ARG;
    }
    // What replay: checks when it opens the file (transport_replay.cpp),
    // checked before the file is created: a recording it would refuse is
    // never started. The CSV keeps no report, but is asked for the same one.
    proto::DeviceInfoReport di;
    std::string detail;
    if (const proto::Reject rej = proto::parse_device_info(info, info_len, di, &detail); rej != proto::Reject::None) {
        err = "device-info report (" + std::to_string(info_len) + " bytes) rejected: " + proto::reject_text(rej) +
              (detail.empty() ? "" : ": " + detail);
        return CDM_ERR_INVALID_ARG;
    }
    if (format == Format::Mcap) return open_mcap_writer(path, info, info_len, di, compression, out, err);
    if (format == Format::Csv) {
        auto w = std::make_unique<CsvWriter>();
        if (int rc = w->open(path, err); rc != CDM_OK) return rc;
        out = std::move(w);
        return CDM_OK;
    }
    auto w = std::make_unique<ReplayWriter>();
    if (int rc = w->open(path, info, info_len, err); rc != CDM_OK) return rc;
    out = std::move(w);
    return CDM_OK;
}

} // namespace cdm::recording
