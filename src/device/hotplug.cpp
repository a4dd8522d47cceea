#include "device/hotplug.h"

#include <libudev.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <set>

#include "device/device.h"
#include "device/hid/transport_hidapi.h"
#include "io/log.h"

namespace cdm {

namespace {
std::atomic<bool> g_hotplug_events{true};
}

void set_hotplug_events(bool on) { g_hotplug_events.store(on); }
bool hotplug_events() { return g_hotplug_events.load(); }

UdevMonitor::UdevMonitor() {
    udev_ = udev_new();
    if (!udev_) {
        err_ = std::string("udev_new failed: ") + std::strerror(errno);
        return;
    }
    // "udev", not "kernel": the event comes after udev's rules ran, so the
    // node exists with the permissions udev/70-cdm.rules gives it.
    udev_monitor *m = udev_monitor_new_from_netlink(udev_, "udev");
    if (!m) {
        err_ = std::string("udev_monitor_new_from_netlink(\"udev\") failed: ") + std::strerror(errno);
        return;
    }
    if (udev_monitor_filter_add_match_subsystem_devtype(m, "hidraw", nullptr) < 0 ||
        udev_monitor_filter_add_match_subsystem_devtype(m, "usb", "usb_device") < 0 ||
        udev_monitor_enable_receiving(m) < 0) {
        err_ = std::string("udev monitor: cannot filter or subscribe: ") + std::strerror(errno);
        udev_monitor_unref(m);
        return;
    }
    mon_ = m;
}

UdevMonitor::~UdevMonitor() {
    if (mon_) udev_monitor_unref(mon_);
    if (udev_) udev_unref(udev_);
}

int UdevMonitor::fd() const { return mon_ ? udev_monitor_get_fd(mon_) : -1; }

int UdevMonitor::wait(int timeout_ms, std::vector<UdevEvent> *out) {
    if (!mon_) return 0;
    int taken = 0;
    // The first poll waits; the following ones only drain what is queued.
    for (int t = timeout_ms;; t = 0) {
        pollfd p{udev_monitor_get_fd(mon_), POLLIN, 0};
        const int r = ::poll(&p, 1, t);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0 || !(p.revents & POLLIN)) break;
        udev_device *d = udev_monitor_receive_device(mon_);
        if (!d) break; // readable but nothing for us (filtered, or a short read)
        ++taken;
        if (out) {
            const char *a = udev_device_get_action(d), *s = udev_device_get_subsystem(d),
                       *n = udev_device_get_devnode(d);
            out->push_back({a ? a : "", s ? s : "", n ? n : ""});
        }
        udev_device_unref(d);
    }
    return taken;
}

int MasterWatcher::start(bool enumerate, Callback cb, std::unique_ptr<MasterWatcher> &out, std::string &err) {
    std::unique_ptr<MasterWatcher> w(new MasterWatcher());
    w->cb_ = std::move(cb);
    // Subscribed before the first enumeration, so that nothing between the
    // two is missed (an arrival seen by both is reported once: by path).
    w->mon_ = std::make_unique<UdevMonitor>();
    if (!w->mon_->ok()) {
        err = "no hot-plug events on this system: " + w->mon_->error();
        return CDM_ERR_UNSUPPORTED;
    }
    w->stop_fd_ = eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (w->stop_fd_ < 0) {
        err = std::string("eventfd: ") + std::strerror(errno);
        return CDM_ERR_IO;
    }
    // Without CDM_WATCH_ENUMERATE the masters present now are learnt here,
    // before cdm_watch returns: a master plugged in right after the call is
    // then a change, never taken for one that was already there (which a
    // first silent scan on the thread, racing the caller, could do).
    if (!enumerate) w->rescan(false);
    MasterWatcher *self = w.get();
    self->thread_ = std::thread([self, enumerate] { self->run(enumerate); });
    out = std::move(w);
    return CDM_OK;
}

MasterWatcher::~MasterWatcher() {
    if (thread_.joinable()) {
        const uint64_t one = 1;
        // An eventfd write of 8 bytes cannot be short; it fails only if the
        // counter would overflow, which one write never makes it.
        if (::write(stop_fd_, &one, sizeof one) != ssize_t(sizeof one))
            log::message(log::kError, "watcher: cannot signal its thread to stop");
        thread_.join();
    }
    if (stop_fd_ >= 0) ::close(stop_fd_);
}

void MasterWatcher::run(bool enumerate) {
    try {
        loop(enumerate);
    } catch (const std::exception &e) {
        // No exception leaves a thread of libcdm's; the watcher then stops
        // telling, and says so.
        log::message(log::kError, std::string("watcher stopped: internal error: ") + e.what());
    }
}

void MasterWatcher::loop(bool enumerate) {
    if (enumerate) rescan(true); // the masters already there, told on this thread
    for (;;) {
        pollfd p[2] = {{stop_fd_, POLLIN, 0}, {mon_->fd(), POLLIN, 0}};
        const int r = ::poll(p, 2, -1);
        if (r < 0) {
            if (errno == EINTR) continue;
            log::message(log::kError, std::string("watcher: poll failed: ") + std::strerror(errno));
            return;
        }
        if (p[0].revents) return;
        std::vector<UdevEvent> events;
        if (mon_->wait(0, &events) == 0) continue;
        // A node's removal is reported from its event, not only from the
        // enumeration after the batch: an unplug and a replug under the
        // same node within one batch are a departure and an arrival. And a
        // node whose last event was "remove" is gone until its "add", even
        // if sysfs still shows it: udev sends "remove" once the kernel has
        // torn the device down, but an emulator (umockdev) sends it before
        // it removes the tree, and the enumeration would bring the dead
        // node straight back.
        for (const UdevEvent &e : events) {
            if (e.subsystem != "hidraw" || e.devnode.empty()) continue;
            if (e.action == "add") {
                removed_.erase(e.devnode);
                continue;
            }
            if (e.action != "remove") continue;
            removed_.insert(e.devnode);
            auto it = known_.find(e.devnode);
            if (it == known_.end()) continue;
            const cdm_device_info info = it->second;
            known_.erase(it);
            cb_(CDM_WATCH_LEFT, info);
        }
        rescan(true);
    }
}

// Compares the enumeration (device/hid/hidraw_enum.h) with known_: new nodes are arrivals (their
// full info read from the device), vanished ones departures.
void MasterWatcher::rescan(bool report) {
    std::vector<MasterNode> nodes;
    std::string err;
    hid_list_master_nodes(nodes, err);
    // An incomplete enumeration (a device changed during the scan) tells
    // arrivals but no departures: a master it missed is not gone.
    const bool complete = err.empty();
    if (!complete) log::message(log::kWarning, "watcher: " + err);
    std::set<std::string> now;
    nodes.erase(std::remove_if(nodes.begin(), nodes.end(),
                               [&](const MasterNode &n) { return removed_.count(n.path) != 0; }),
                nodes.end());
    for (const MasterNode &n : nodes) now.insert(n.path);
    for (auto it = known_.begin(); it != known_.end();) {
        if (now.count(it->first) || !complete) {
            ++it;
            continue;
        }
        const cdm_device_info info = it->second;
        it = known_.erase(it);
        if (report) cb_(CDM_WATCH_LEFT, info);
    }
    for (const MasterNode &n : nodes) {
        if (known_.count(n.path)) continue;
        cdm_device_info info;
        // A node just added may not answer yet: udev applies its rule's
        // permissions after the node appears, and a device can take a moment
        // after enumeration (the emulated one, on a loaded machine, can
        // tell "1.0" for "1.0.0"). An arrival is told with the full info
        // when the device gives it within kSettleMs (tries kSettleStepMs
        // apart, on this thread, leaving off at once when the watcher is
        // stopped), else with what enumeration knows.
        // (The deadline is on the clock: a try that itself blocks, a
        // control request timing out, counts too.)
        constexpr int kSettleMs = 250, kSettleStepMs = 25;
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(kSettleMs);
        bool full = hid_master_info(n, info);
        while (report && !full && std::chrono::steady_clock::now() < deadline) {
            pollfd p{stop_fd_, POLLIN, 0};
            if (::poll(&p, 1, kSettleStepMs) != 0) break; // stopping (or poll failed): no more tries
            full = hid_master_info(n, info);
        }
        known_[n.path] = info;
        if (report) cb_(CDM_WATCH_ARRIVED, info);
    }
}

} // namespace cdm
