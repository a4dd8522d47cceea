#include "device/hid/hidraw_enum.h"

#include <libudev.h>
#include <linux/input.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "cdm/cdm.h"
#include "device/protocol.h"

namespace {
// "0003:0000ABCD:00001234" (bus:vendor:product, hex) as the kernel writes
// HID_ID; false for anything else.
bool parse_hid_id(const char *id, unsigned &bus, unsigned &vid, unsigned &pid) {
    char tail = 0;
    return id && std::sscanf(id, "%x:%x:%x%c", &bus, &vid, &pid, &tail) == 3;
}

// bcdDevice is four hex digits ("0100"); anything else is unknown (0).
unsigned parse_bcd(const char *s) {
    if (!s) return 0;
    char *end = nullptr;
    errno = 0;
    const unsigned long v = std::strtoul(s, &end, 16);
    if (errno || end == s || v > 0xFFFF) return 0;
    while (*end == '\n' || *end == ' ') ++end;
    return *end ? 0 : unsigned(v);
}
} // namespace

extern "C" int cdm_hidraw_list_masters(cdm_hidraw_master_fn fn, void *ctx, char *why, size_t cap) {
    auto fail = [&](const char *what) {
        if (cap) std::snprintf(why, cap, "hidraw enumeration: %s", what);
        return int(CDM_ERR_IO);
    };
    udev *u = udev_new();
    if (!u) return fail("udev_new failed (no udev on this system?)");
    udev_enumerate *en = udev_enumerate_new(u);
    if (!en || udev_enumerate_add_match_subsystem(en, "hidraw") < 0) {
        if (en) udev_enumerate_unref(en);
        udev_unref(u);
        return fail("cannot list the hidraw devices through udev");
    }
    // A device that changes during the scan makes it return an error, but
    // the scan goes on and the list holds every other device (systemd 252):
    // what was listed is told, and the error returned beside it, so that a
    // caller does not take one changing device for every master gone.
    const int scan = udev_enumerate_scan_devices(en);
    for (udev_list_entry *e = udev_enumerate_get_list_entry(en); e; e = udev_list_entry_get_next(e)) {
        const char *syspath = udev_list_entry_get_name(e);
        udev_device *raw = syspath ? udev_device_new_from_syspath(u, syspath) : nullptr;
        if (!raw) continue; // gone since the scan
        const char *node = udev_device_get_devnode(raw);
        // The parents belong to `raw` (freed with it). They are found by
        // the syspath's directories, not the class device's `device` link,
        // which some sysfs trees (containers, emulators) lack.
        udev_device *hid = udev_device_get_parent_with_subsystem_devtype(raw, "hid", nullptr);
        const char *id = hid ? udev_device_get_property_value(hid, "HID_ID") : nullptr;
        // The master is a USB device: the same IDs on another bus (a
        // Bluetooth or uhid device claiming them) are not listed. The udev
        // rule grants access only to a USB master's node, so such a device
        // would be listed but could not be opened by the seat's user.
        unsigned bus = 0, vid = 0, pid = 0;
        if (node && *node && parse_hid_id(id, bus, vid, pid) && bus == BUS_USB && vid == cdm::proto::kVendorId &&
            pid == cdm::proto::kProductId) {
            const char *uniq = udev_device_get_property_value(hid, "HID_UNIQ");
            udev_device *usb = udev_device_get_parent_with_subsystem_devtype(raw, "usb", "usb_device");
            const char *bcd = usb ? udev_device_get_sysattr_value(usb, "bcdDevice") : nullptr;
            fn(ctx, node, uniq ? uniq : "", parse_bcd(bcd));
        }
        udev_device_unref(raw);
    }
    udev_enumerate_unref(en);
    udev_unref(u);
    if (scan < 0) {
        if (cap) std::snprintf(why, cap, "hidraw enumeration: the udev scan was incomplete (%s)", std::strerror(-scan));
        return int(CDM_ERR_IO);
    }
    return 0;
}
