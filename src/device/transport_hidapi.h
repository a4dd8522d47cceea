// Enumeration of real masters through hidapi (VID/PID of protocol.h).
#pragma once

#include <string>
#include <vector>

#include "cdm/cdm.h"

namespace cdm {
// Every connected master, with its full device info when it answers the
// device-info feature report (else what enumeration alone knows). An empty
// list is not an error; err says why hidapi could not enumerate, if so.
void hid_list_masters(std::vector<cdm_device_info> &out, std::string &err);
} // namespace cdm
