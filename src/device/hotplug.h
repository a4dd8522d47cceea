// Hot-plug as an event: udev's monitor (the "udev" netlink group, i.e. after
// udev's rules ran and the node has its permissions), filtered on the two
// subsystems a master's arrival and departure show in: hidraw (the node the
// driver opens) and usb/usb_device (the device itself). Why udev and not
// libusb's hotplug callback: docs/reliability.md, "Hot-plug".
//
// Two users: a disconnected hid: handle waits on it between reconnection
// attempts (HidTransport::wait_arrival), and MasterWatcher turns it into
// cdm_watch's arrivals and departures.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "cdm/cdm.h"

struct udev;
struct udev_monitor;

namespace cdm {

// Whether a disconnected hid: handle wakes on udev's events (default true).
// False leaves only the retry poll (kReconnectIntervalMs): the baseline the
// replug benchmark (tests/umockdev/bench_replug.cpp) measures against.
void set_hotplug_events(bool on);
bool hotplug_events();

// One udev event as the monitor gave it.
struct UdevEvent {
    std::string action;    // "add", "remove", "change", "bind", ...
    std::string subsystem; // "hidraw" or "usb"
    std::string devnode;   // "/dev/hidraw0", "" if none
};

class UdevMonitor {
public:
    // Subscribes at once (events from here on are queued in the socket).
    // ok() is false, with error() saying why, where netlink or libudev is
    // refused (a sandbox); a system without udevd gives a monitor that never
    // receives anything, which is why the reader keeps its retry poll.
    UdevMonitor();
    ~UdevMonitor();
    UdevMonitor(const UdevMonitor &) = delete;
    UdevMonitor &operator=(const UdevMonitor &) = delete;

    bool ok() const { return mon_ != nullptr; }
    const std::string &error() const { return err_; }
    int fd() const; // -1 if !ok()

    // Waits up to timeout_ms (0: no wait) for the socket to be readable,
    // then takes every queued event (appended to `out` if given). Returns
    // how many it took.
    int wait(int timeout_ms, std::vector<UdevEvent> *out = nullptr);

private:
    udev *udev_ = nullptr;
    udev_monitor *mon_ = nullptr;
    std::string err_;
};

// The masters connected, and cdm_watch's callback told of every change:
// a thread of its own waits on a UdevMonitor (and a stop eventfd), and on
// each batch of events compares hidapi's enumeration with what it knew.
class MasterWatcher {
public:
    using Callback = std::function<void(uint32_t kind, const cdm_device_info &info)>;
    // Returns CDM_OK or a cdm_error with err set (no monitor: UNSUPPORTED).
    // With `enumerate`, the masters present at the start are reported as
    // arrivals first, on the watcher's thread.
    static int start(bool enumerate, Callback cb, std::unique_ptr<MasterWatcher> &out, std::string &err);
    ~MasterWatcher(); // stops and joins the thread: no callback runs after it
    // True on the watcher's own thread (in its callback), where the
    // destructor must not run: it would join itself.
    bool on_own_thread() const { return std::this_thread::get_id() == thread_.get_id(); }
    MasterWatcher(const MasterWatcher &) = delete;
    MasterWatcher &operator=(const MasterWatcher &) = delete;

private:
    MasterWatcher() = default;
    void run(bool enumerate);
    void loop(bool enumerate);
    void rescan(bool report);

    std::unique_ptr<UdevMonitor> mon_;
    int stop_fd_ = -1;
    Callback cb_;
    std::map<std::string, cdm_device_info> known_; // by node path
    std::set<std::string> removed_;                // nodes whose last udev event was "remove"
    std::thread thread_;
};

} // namespace cdm
