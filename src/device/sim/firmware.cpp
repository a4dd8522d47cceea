#include "device/sim/firmware.h"

#include <algorithm>
#include <cstring>

namespace cdm::sim {

using namespace cdm::proto;

Firmware::Firmware(const DeviceInfoReport &info) : info_(info) {}

int Firmware::get_feature(uint8_t *buf, size_t len) {
    std::lock_guard<std::mutex> lock(mu_);
    switch (buf[0]) {
    case kDeviceInfoReportId:
        if (len < kDeviceInfoReportSize) return -1;
        serialize_device_info(info_, buf);
        return int(kDeviceInfoReportSize);
    case kCalHeaderReportId: {
        if (len < kCalHeaderReportSize) return -1;
        CalHeader h;
        h.state = state_;
        h.length = uint32_t(store_.size());
        h.crc32 = crc_;
        h.capacity = kCalMaxLength;
        h.written = written_;
        serialize_cal_header(h, buf);
        return int(kCalHeaderReportSize);
    }
    case kCalChunkReportId: {
        if (len < kCalChunkReportSize) return -1;
        CalChunk c;
        c.op = CalChunkOp::Data;
        c.offset = uint16_t(read_ptr_);
        if (state_ == CalState::Valid && read_ptr_ < store_.size()) {
            c.length = uint8_t(std::min<size_t>(kCalChunkMaxData, store_.size() - read_ptr_));
            std::memcpy(c.data.data(), store_.data() + read_ptr_, c.length);
            read_ptr_ += c.length;
        }
        serialize_cal_chunk(c, buf);
        return int(kCalChunkReportSize);
    }
    default: return -1;
    }
}

int Firmware::send_feature(const uint8_t *buf, size_t len) {
    std::lock_guard<std::mutex> lock(mu_);
    if (len == 0) return -1;
    if (buf[0] == kCalHeaderReportId) {
        CalHeader h;
        if (parse_cal_header(buf, len, h) != Reject::None) return -1;
        switch (h.op) {
        case CalHeaderOp::BeginWrite:
            if (h.length > kCalMaxLength) return -1;
            state_ = CalState::Writing;
            store_.assign(h.length, 0);
            crc_ = h.crc32;
            written_ = 0;
            read_ptr_ = 0;
            return 0;
        case CalHeaderOp::Commit:
            if (state_ != CalState::Writing) return -1;
            // The firmware checks the CRC before it marks the blob valid, so
            // a transfer that lost a chunk never becomes "the calibration".
            state_ = (written_ == store_.size() && crc32(store_.data(), store_.size()) == crc_)
                         ? CalState::Valid
                         : CalState::CommitFailed;
            return 0;
        case CalHeaderOp::Erase:
            state_ = CalState::Empty;
            store_.clear();
            crc_ = written_ = read_ptr_ = 0;
            return 0;
        case CalHeaderOp::None: return -1;
        }
        return -1;
    }
    if (buf[0] == kCalChunkReportId) {
        CalChunk c;
        if (parse_cal_chunk(buf, len, c) != Reject::None) return -1;
        switch (c.op) {
        case CalChunkOp::SeekRead:
            if (c.offset > store_.size()) return -1;
            read_ptr_ = c.offset;
            return 0;
        case CalChunkOp::WriteData:
            if (state_ != CalState::Writing || size_t(c.offset) + c.length > store_.size()) return -1;
            std::memcpy(store_.data() + c.offset, c.data.data(), c.length);
            written_ = std::max<uint32_t>(written_, uint32_t(c.offset) + c.length);
            return 0;
        case CalChunkOp::Data: return -1;
        }
    }
    return -1;
}

bool Firmware::calibration_stored() const {
    std::lock_guard<std::mutex> lock(mu_);
    return state_ == CalState::Valid;
}

void Firmware::corrupt_store(size_t offset) {
    std::lock_guard<std::mutex> lock(mu_);
    if (offset < store_.size()) store_[offset] ^= 0x01;
}

} // namespace cdm::sim
