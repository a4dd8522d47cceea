#include "device/replay_format.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>

#include "cdm/cdm.h"
#include "device/protocol.h"

namespace cdm::replay {

namespace {
int parse_error(const std::string &name, size_t offset, const std::string &what, std::string &err) {
    err = name + ": byte " + std::to_string(offset) + ": " + what;
    return CDM_ERR_PARSE;
}
} // namespace

int parse(std::vector<uint8_t> bytes, const std::string &name, File &out, std::string &err) {
    const size_t n = bytes.size();
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
        if (n - off < kRecordHeaderSize)
            return parse_error(name, off, "truncated record header (" + std::to_string(n - off) + " of " +
                                              std::to_string(kRecordHeaderSize) + " bytes)", err);
        const uint64_t t = proto::get_u64(bytes.data() + off);
        const uint16_t len = proto::get_u16(bytes.data() + off + 8);
        if (len == 0 || len > kMaxReport)
            return parse_error(name, off + 8, "record length " + std::to_string(len) + " out of 1..1024", err);
        if (t < last_ns)
            return parse_error(name, off, "host time goes backwards (record " + std::to_string(f.records.size()) + ")",
                               err);
        if (n - off - kRecordHeaderSize < len)
            return parse_error(name, off, "truncated record: " + std::to_string(len) + " report bytes announced, " +
                                              std::to_string(n - off - kRecordHeaderSize) + " left", err);
        f.records.push_back(Record{t, off + kRecordHeaderSize, len});
        last_ns = t;
        off += kRecordHeaderSize + len;
    }
    f.bytes = std::move(bytes);
    out = std::move(f);
    return CDM_OK;
}

int load(const std::string &path, File &out, std::string &err) {
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        err = path + ": cannot open: " + std::strerror(errno);
        return CDM_ERR_NO_DEVICE;
    }
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) {
        err = path + ": read error";
        return CDM_ERR_IO;
    }
    return parse(std::move(bytes), path, out, err);
}

Writer::~Writer() {
    if (f_) std::fclose(f_);
}

int Writer::open(const std::string &path, const uint8_t *info, size_t info_len, std::string &err) {
    if (info_len == 0 || info_len > kMaxReport) {
        err = "device-info report of " + std::to_string(info_len) + " bytes";
        return CDM_ERR_INVALID_ARG;
    }
    f_ = std::fopen(path.c_str(), "wb");
    if (!f_) {
        err = path + ": cannot create: " + std::strerror(errno);
        return CDM_ERR_IO;
    }
    path_ = path;
    uint8_t h[kHeaderSize];
    std::memcpy(h, kMagic, sizeof kMagic);
    proto::put_u16(h + 8, kVersion);
    proto::put_u16(h + 10, uint16_t(info_len));
    if (std::fwrite(h, 1, sizeof h, f_) != sizeof h || std::fwrite(info, 1, info_len, f_) != info_len) {
        err = path + ": write error: " + std::strerror(errno);
        return CDM_ERR_IO;
    }
    return CDM_OK;
}

int Writer::write(uint64_t host_ns, const uint8_t *report, size_t len, std::string &err) {
    if (!f_ || len == 0 || len > kMaxReport) {
        err = "record of " + std::to_string(len) + " bytes";
        return CDM_ERR_INVALID_ARG;
    }
    uint8_t h[kRecordHeaderSize];
    proto::put_u64(h, host_ns);
    proto::put_u16(h + 8, uint16_t(len));
    if (std::fwrite(h, 1, sizeof h, f_) != sizeof h || std::fwrite(report, 1, len, f_) != len) {
        err = path_ + ": write error: " + std::strerror(errno);
        return CDM_ERR_IO;
    }
    return CDM_OK;
}

int Writer::close(std::string &err) {
    if (!f_) return CDM_OK;
    const bool ok = std::fflush(f_) == 0 && std::ferror(f_) == 0;
    const bool closed = std::fclose(f_) == 0;
    f_ = nullptr;
    if (!ok || !closed) {
        err = path_ + ": write error: " + std::strerror(errno);
        return CDM_ERR_IO;
    }
    return CDM_OK;
}

} // namespace cdm::replay
