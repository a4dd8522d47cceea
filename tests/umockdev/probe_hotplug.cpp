// What hot-plug notification reaches a process when the master is unplugged
// and plugged back on the emulated kernel device: libudev's monitor (hidraw
// and usb subsystems) and libusb's hotplug callback (1209:cd01). It prints
// what it saw (docs/testing.md quotes it) and fails only if the udev monitor,
// which the next step builds on, misses an event; libusb's answer is
// reported, not asserted, as it is the thing being found out.
#include <libudev.h>
#include <libusb-1.0/libusb.h>
#include <poll.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "master_testbed.h"

namespace {

std::atomic<int> g_usb_arrived{0}, g_usb_left{0};

int LIBUSB_CALL on_usb(libusb_context *, libusb_device *, libusb_hotplug_event ev, void *) {
    if (ev == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED) ++g_usb_arrived;
    else ++g_usb_left;
    return 0;
}

// Drains the monitor for `ms`, appending "action subsystem" lines.
void drain(udev_monitor *mon, int ms, std::vector<std::string> &seen) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < end) {
        pollfd p{udev_monitor_get_fd(mon), POLLIN, 0};
        if (poll(&p, 1, 20) <= 0) continue;
        udev_device *d = udev_monitor_receive_device(mon);
        if (!d) continue;
        const char *a = udev_device_get_action(d), *s = udev_device_get_subsystem(d);
        seen.push_back(std::string(a ? a : "?") + " " + (s ? s : "?"));
        udev_device_unref(d);
    }
}

} // namespace

int main() {
    if (!cdm_umock::in_mock_environment()) {
        std::fprintf(stderr, "run me through umockdev-wrapper\n");
        return 1;
    }
    cdm_umock::MasterTestbed tb;

    udev *u = udev_new();
    udev_monitor *mon = udev_monitor_new_from_netlink(u, "udev");
    udev_monitor_filter_add_match_subsystem_devtype(mon, "hidraw", nullptr);
    udev_monitor_filter_add_match_subsystem_devtype(mon, "usb", "usb_device");
    udev_monitor_enable_receiving(mon);

    libusb_context *ctx = nullptr;
    const int init_rc = libusb_init(&ctx);
    const int has_hotplug = init_rc == 0 ? libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) : 0;
    libusb_hotplug_callback_handle h = 0;
    int reg_rc = -99;
    if (has_hotplug)
        reg_rc = libusb_hotplug_register_callback(
            ctx, LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT, LIBUSB_HOTPLUG_ENUMERATE,
            0x1209, 0xCD01, LIBUSB_HOTPLUG_MATCH_ANY, on_usb, nullptr, &h);
    std::atomic<bool> stop{false};
    std::thread events([&] {
        timeval tv{0, 50000};
        while (!stop && init_rc == 0) libusb_handle_events_timeout_completed(ctx, &tv, nullptr);
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const int usb_at_start = g_usb_arrived;
    libusb_device **list = nullptr;
    const ssize_t n_usb = init_rc == 0 ? libusb_get_device_list(ctx, &list) : -1;
    int master_listed = 0;
    for (ssize_t i = 0; i < n_usb; ++i) {
        libusb_device_descriptor dd{};
        if (libusb_get_device_descriptor(list[i], &dd) == 0 && dd.idVendor == 0x1209 && dd.idProduct == 0xCD01)
            ++master_listed;
    }
    if (list) libusb_free_device_list(list, 1);

    std::vector<std::string> seen;
    tb.unplug();
    drain(mon, 500, seen);
    const int usb_left_after_unplug = g_usb_left;
    tb.plug();
    drain(mon, 500, seen);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    stop = true;
    events.join();

    std::printf("libudev monitor (netlink \"udev\", hidraw + usb_device):");
    for (const auto &s : seen) std::printf(" [%s]", s.c_str());
    std::printf("\nlibusb: init %d, HAS_HOTPLUG %d, register %d, master in get_device_list %d (of %zd), "
                "ARRIVED at registration (ENUMERATE) %d, LEFT after unplug %d, ARRIVED after replug %d\n",
                init_rc, has_hotplug, reg_rc, master_listed, n_usb, usb_at_start, usb_left_after_unplug,
                int(g_usb_arrived) - usb_at_start);
    if (init_rc == 0) libusb_exit(ctx);
    udev_monitor_unref(mon);
    udev_unref(u);

    int remove_hidraw = 0, add_hidraw = 0;
    for (const auto &s : seen) {
        if (s == "remove hidraw") ++remove_hidraw;
        if (s == "add hidraw") ++add_hidraw;
    }
    const bool ok = remove_hidraw == 1 && add_hidraw == 1;
    std::printf("%d passed, %d failed\n", ok ? 1 : 0, ok ? 0 : 1);
    return ok ? 0 : 1;
}
