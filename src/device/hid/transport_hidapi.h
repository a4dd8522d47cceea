// Enumeration of real masters (VID/PID of protocol.h): the nodes through
// libudev (hidraw_enum.h), their info from the device through hidapi.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cdm/cdm.h"

namespace cdm {
// Every connected master, with its full device info when it answers the
// device-info feature report (else what enumeration alone knows). An empty
// list is not an error; err says why the list may be incomplete, or empty, if so.
void hid_list_masters(std::vector<cdm_device_info> &out, std::string &err);

// A master's node as enumeration alone knows it (nothing opened).
struct MasterNode {
    std::string path;   // "/dev/hidrawN"
    std::string serial; // from the USB string descriptor, "" if none
    uint16_t release = 0; // bcdDevice: the firmware's major.minor
};
// Every connected master's node, each once (cheap: no open). err as above.
void hid_list_master_nodes(std::vector<MasterNode> &out, std::string &err);
// Its full info when it answers the device-info feature report (returns
// true), else what enumeration knows (uri, serial, firmware major.minor,
// USB ids; returns false).
bool hid_master_info(const MasterNode &node, cdm_device_info &out);
} // namespace cdm
