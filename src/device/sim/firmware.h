// The firmware side of the protocol, emulated: what the master's
// microcontroller answers to GET/SET_REPORT(Feature) (device info, the
// calibration store) and how it packs a sensor sample into an input report.
// The simulated master uses it, and so does the hidapi mock in the tests, so
// both exercise the host code against one definition of device behaviour.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "device/protocol.h"

namespace cdm::sim {

class Firmware {
public:
    explicit Firmware(const proto::DeviceInfoReport &info);

    const proto::DeviceInfoReport &info() const { return info_; }

    // GET_REPORT(Feature): buf[0] = report ID on entry. Returns the report
    // length, or -1 where a real device would STALL (unknown ID, short buffer).
    int get_feature(uint8_t *buf, size_t len);
    // SET_REPORT(Feature). Returns 0, or -1 for a request the firmware
    // refuses (STALL): bad op, write outside the declared length, commit
    // without begin.
    int send_feature(const uint8_t *buf, size_t len);

    bool calibration_stored() const;
    // Test hook: flips one stored byte, as a worn flash cell would, so the
    // host's CRC check can be seen to fire.
    void corrupt_store(size_t offset);

private:
    proto::DeviceInfoReport info_;
    mutable std::mutex mu_; // feature requests may come from any host thread
    proto::CalState state_ = proto::CalState::Empty;
    std::vector<uint8_t> store_;
    uint32_t crc_ = 0;
    uint32_t written_ = 0;
    uint32_t read_ptr_ = 0;
};

} // namespace cdm::sim
