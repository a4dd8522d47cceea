// An emulated master in the kernel's shape, on umockdev: the sysfs tree the
// kernel builds for a USB HID device 1209:cd01 (USB device, interface, HID
// device with its report descriptor, hidraw class device) with the uevent
// properties the kernel gives, and an ioctl/read handler on /dev/hidraw0 that
// plays the project's simulated firmware (src/device/sim). The real
// libhidapi-hidraw and libudev then run against it unchanged.
//
// Must run under umockdev's preload (umockdev-wrapper PROGRAM): umockdev
// redirects /sys and /dev by LD_PRELOAD.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>

#include "device/sim/sim_truth.h"

namespace cdm_umock {

// How the node behaves: a master, or something that only claims to be one.
enum class NodeMode {
    Master,    // answers every hidraw ioctl as the kernel would, streams input reports
    NoIoctl,   // answers every ioctl ENOTTY (not a hidraw node at all)
    Garbage,   // HIDIOCGRDESCSIZE says 4096 (over HID_MAX_DESCRIPTOR_SIZE), reports are random bytes
};

struct TestbedOptions {
    std::string serial = "UMOCK0001";
    double rate_hz = 250; // the device's report rate (kept low: 2 shared cores)
    NodeMode mode = NodeMode::Master;
    // hidraw0/device -> its HID parent, as the kernel makes it. False
    // reproduces a sysfs without it (umockdev's default, and some containers'):
    // hidapi's filtered enumeration then misses the master.
    bool device_link = true;
    // The HID device's bus in HID_ID and its modalias (linux/input.h:
    // 0x03 USB, 0x05 Bluetooth, 0x06 virtual, as uhid devices say).
    unsigned hid_bus = 0x0003;
};

class MasterTestbed {
public:
    explicit MasterTestbed(const TestbedOptions &o = {});
    ~MasterTestbed();
    MasterTestbed(const MasterTestbed &) = delete;
    MasterTestbed &operator=(const MasterTestbed &) = delete;

    // The kernel's unplug: "remove" uevents (hidraw, hid, interface, USB
    // device, children first), the sysfs tree and the node gone; reads
    // pending on an open node fail with ENODEV, as hidraw's do.
    void unplug();
    // The kernel's plug: tree, node and "add" uevents back, parents first
    // (USB device ... hidraw last), as the kernel announces them.
    void plug();
    bool plugged() const;

    // The truth of report `seq` (position mm, device frame), if still kept.
    bool truth(uint32_t seq, cdm::SimTruth &out) const;
    uint64_t reports_sent() const;
    uint64_t ioctls_seen(unsigned nr) const; // by _IOC_NR, 'H' type only

    const std::string &hidraw_syspath() const;

    struct Impl;

private:
    std::unique_ptr<Impl> p_;
};

// True when the umockdev preload is active in this process.
bool in_mock_environment();

} // namespace cdm_umock
